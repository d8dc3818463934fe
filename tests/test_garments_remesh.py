"""Decimation keeps shape and borders; barycentric transfer moves full-res data to the low-res mesh."""

from __future__ import annotations

import numpy as np
import pytest

from garsim.bodies.anny import AnnyBody
from garsim.garments.garment import Garment
from garsim.garments.remesh import BarycentricMap, decimate, subdivide, transfer_barycentric
from garsim.garments.templates import TemplateBody, make_garment
from garsim.geometry.mesh import border_loops


@pytest.fixture(scope="module")
def body() -> TemplateBody:
    return TemplateBody.from_anny(AnnyBody())


@pytest.mark.parametrize("kind", ["skirt", "tshirt", "trousers", "dress"])
def test_decimate_4x_keeps_bbox_and_borders(body, kind):
    g = make_garment(kind, body, target_vertices=3000)
    low, mapping = decimate(g, 0.25)
    assert 0.15 * g.num_vertices < low.num_vertices < 0.45 * g.num_vertices
    assert np.abs(low.vertices.min(0) - g.vertices.min(0)).max() < 0.01
    assert np.abs(low.vertices.max(0) - g.vertices.max(0)).max() < 0.01
    loops_full, loops_low = border_loops(g.faces), border_loops(low.faces)
    assert len(loops_low) == len(loops_full)
    # every low-res border vertex lies on the original border (borders are preserved)
    full_border = g.vertices[np.concatenate(loops_full)]
    low_border = low.vertices[np.concatenate(loops_low)]
    d = np.linalg.norm(low_border[:, None] - full_border[None], axis=2).min(axis=1)
    assert d.max() < 1e-5
    # still edge-manifold, pinned band carried over
    e = np.sort(np.concatenate([low.faces[:, [0, 1]], low.faces[:, [1, 2]], low.faces[:, [2, 0]]]), axis=1)
    assert np.unique(e, axis=0, return_counts=True)[1].max() == 2
    assert low.pinned.any()
    assert abs(low.vertices[low.pinned, 2].mean() - g.vertices[g.pinned, 2].mean()) < 0.02
    # transferring the full-res positions reproduces the low-res positions
    moved = transfer_barycentric(g.vertices.astype(np.float64), mapping)
    np.testing.assert_allclose(moved, low.vertices, atol=1e-5)
    assert np.allclose(mapping.weights.sum(1), 1.0) and (mapping.weights >= 0).all()


def test_transfer_hand_computed():
    mapping = BarycentricMap(np.array([[0, 1, 2], [2, 3, 1]]), np.array([[0.5, 0.25, 0.25], [1.0, 0.0, 0.0]]))
    values = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 8.0], [1.0, 1.0]])
    np.testing.assert_allclose(transfer_barycentric(values, mapping), [[1.0, 2.0], [0.0, 8.0]])
    np.testing.assert_allclose(transfer_barycentric(np.array([1.0, 2.0, 3.0, 4.0]), mapping), [1.75, 3.0])
    with pytest.raises(ValueError, match="full-resolution"):
        transfer_barycentric(values[:2], mapping)


def test_decimate_bad_ratio():
    g = Garment(np.eye(3), np.array([[0, 1, 2]]), np.zeros(3, bool), "skirt")
    with pytest.raises(ValueError, match="ratio"):
        decimate(g, 0.0)


def test_subdivide_splits_every_triangle_at_its_edge_midpoints():
    """Two triangles sharing an edge: 4 + 5 vertices (one midpoint per edge), 8 faces that keep the orientation and
    tile the same surface (per-vertex data is carried linearly, so a plane stays the plane)."""
    v = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [2.0, 2.0, 0.0]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    fine, mapping = subdivide(faces, 4)
    fv = transfer_barycentric(v, mapping)
    assert fine.shape == (8, 3) and len(fv) == 9 and fine.max() == 8
    np.testing.assert_allclose(fv[:4], v)
    assert {tuple(p) for p in fv[4:, :2]} == {(1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (2.0, 1.0), (1.0, 2.0)}
    normals = np.cross(fv[fine[:, 1]] - fv[fine[:, 0]], fv[fine[:, 2]] - fv[fine[:, 0]])
    np.testing.assert_allclose(normals, [[0.0, 0.0, 1.0]] * 8)  # area 0.5 each (a quarter of 2), facing +Z
    e = np.sort(np.concatenate([fine[:, [0, 1]], fine[:, [1, 2]], fine[:, [2, 0]]]), axis=1)
    assert len(np.unique(e, axis=0)) == 16  # 2 x 5 halves of the coarse edges + 3 x 2 inner edges
    np.testing.assert_allclose(transfer_barycentric(v[:, 0] * 3.0 - v[:, 1], mapping), fv[:, 0] * 3.0 - fv[:, 1])


def test_decimating_a_subdivided_garment_leaves_no_zero_area_face():
    """Collapses between the collinear vertices of a subdivided mesh made zero-area faces that every mesh check
    refuses (the API's ``max_vertices`` path on a subdivided garment); they are dropped."""
    from pathlib import Path

    from garsim.data.store import DatasetStore
    from garsim.geometry.io import validate_mesh, zero_area_faces

    store = DatasetStore(Path(__file__).parent / "fixtures" / "dataset_v2")
    level = store.read_sequence(next(e for e in store.entries() if e["id"] == "test-00040")).levels["low"]
    faces, mapping = subdivide(level.faces, len(level.template))
    fine = Garment(transfer_barycentric(level.template, mapping), faces, np.zeros(len(mapping.weights), bool), "skirt")
    low, back = decimate(fine, len(level.template) / len(fine.vertices))
    assert not zero_area_faces(low.vertices, low.faces).any() and np.unique(low.faces).size == len(low.vertices)
    validate_mesh(low.vertices, low.faces)
    np.testing.assert_allclose(transfer_barycentric(fine.vertices.astype(np.float64), back), low.vertices, atol=1e-6)
