"""MeshPairBody: a canonical + target mesh pair without a rig, and its validation errors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from garsim.bodies.base import BodyModel, PosedBody
from garsim.bodies.mesh_pair import MeshPairBody

TETRA_V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_arrays_give_canonical_and_target_without_rig():
    target = TETRA_V * 2.0 + 0.5
    body = MeshPairBody(TETRA_V, target, TETRA_F)
    assert isinstance(body, BodyModel)
    assert body.num_vertices == 4
    assert body.skin_weights is None and body.skin_indices is None
    can, tgt = body.canonical(), body.pose()
    assert isinstance(can, PosedBody) and can.transforms is None and tgt.transforms is None
    assert can.vertices.dtype == np.float32 and can.vertices.shape == (4, 3)
    np.testing.assert_array_equal(can.vertices, TETRA_V.astype(np.float32))
    np.testing.assert_array_equal(tgt.vertices, target.astype(np.float32))
    np.testing.assert_array_equal(body.rest_vertices, can.vertices)
    np.testing.assert_array_equal(body.faces, TETRA_F)
    assert body.faces.dtype == np.int64
    # pose() ignores its argument: the pair has exactly one target.
    np.testing.assert_array_equal(body.pose({"anything": 1}).vertices, tgt.vertices)
    # Callers get copies: editing them does not change the body.
    can.vertices[:] = 0.0
    np.testing.assert_array_equal(body.canonical().vertices, TETRA_V.astype(np.float32))


def test_trimesh_objects_are_accepted(icosphere):
    v, f = icosphere
    can = trimesh.Trimesh(v, f, process=False)
    tgt = trimesh.Trimesh(v * np.array([1.0, 1.0, 1.5], dtype=np.float32), f, process=False)
    body = MeshPairBody(can, tgt)
    assert body.num_vertices == len(v)
    np.testing.assert_array_equal(body.faces, f)
    np.testing.assert_allclose(body.pose().vertices[:, 2], v[:, 2] * 1.5, rtol=1e-6)
    # Mixed: a trimesh canonical and an array target take the faces from the trimesh.
    mixed = MeshPairBody(can, v * 1.1)
    np.testing.assert_array_equal(mixed.faces, f)


@pytest.mark.parametrize(
    "canonical, target, faces, message",
    [
        (TETRA_V, TETRA_V[:3], TETRA_F, r"target mesh: 3 faces reference vertices outside \[0, 2\]"),
        (TETRA_V, np.vstack([TETRA_V, [[2.0, 2.0, 2.0]]]), TETRA_F, "canonical mesh has 4 vertices but target has 5"),
        (np.where(np.eye(4, 3) > 0, np.nan, TETRA_V), TETRA_V, TETRA_F, "canonical mesh: 3 vertices have NaN/inf"),
        (TETRA_V, np.where(np.eye(4, 3) > 0, np.inf, TETRA_V), TETRA_F, "target mesh: 3 vertices have NaN/inf"),
        (TETRA_V[:, :2], TETRA_V, TETRA_F, r"shape \(V, 3\)"),
        (TETRA_V, TETRA_V, TETRA_F + 1, r"reference vertices outside \[0, 3\]"),
        (TETRA_V, TETRA_V, -TETRA_F - 1, r"reference vertices outside \[0, 3\]"),
        (TETRA_V, TETRA_V, np.array([[0, 0, 1], [0, 1, 3]]), "repeat a vertex"),
        (TETRA_V, TETRA_V, TETRA_F[:, :2], "at least 3 corners"),
        (TETRA_V, TETRA_V, np.zeros((0, 3), dtype=int), "no faces"),
        (TETRA_V, TETRA_V, TETRA_F + 0.5, "face indices must be integers"),
        (TETRA_V, TETRA_V, None, "no faces"),
        (None, TETRA_V, TETRA_F, "canonical mesh is None"),
    ],
)
def test_validation_errors(canonical, target, faces, message):
    with pytest.raises(ValueError, match=message):
        MeshPairBody(canonical, target, faces)


def test_zero_area_faces_are_rejected_in_either_mesh():
    flat_target = TETRA_V.copy()
    flat_target[3] = [0.5, 0.5, 0.0]  # vertex 3 moves onto the edge 1-2: face (1, 2, 3) has zero area
    with pytest.raises(ValueError, match="target mesh: 1 degenerate faces have zero area"):
        MeshPairBody(TETRA_V, flat_target, TETRA_F)
    with pytest.raises(ValueError, match="canonical mesh: 1 degenerate faces have zero area"):
        MeshPairBody(flat_target, TETRA_V, TETRA_F)


def test_different_faces_are_rejected(icosphere):
    v, f = icosphere
    other = f.copy()
    other[0] = other[0, ::-1]
    with pytest.raises(ValueError, match="different faces"):
        MeshPairBody(trimesh.Trimesh(v, f, process=False), trimesh.Trimesh(v, other, process=False))
    with pytest.raises(ValueError, match="different faces"):
        MeshPairBody(trimesh.Trimesh(v, f, process=False), v, other)
