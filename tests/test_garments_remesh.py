"""Decimation keeps shape and borders; barycentric transfer moves full-res data to the low-res mesh."""

from __future__ import annotations

import numpy as np
import pytest

from garsim.bodies.anny import AnnyBody
from garsim.garments.garment import Garment
from garsim.garments.remesh import BarycentricMap, decimate, transfer_barycentric
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
