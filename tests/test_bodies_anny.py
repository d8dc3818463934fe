"""AnnyBody: T-pose, skinning transforms, batching, and refusals of bad input (never downloading)."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from scipy.spatial import cKDTree

from garsim.bodies.anny import AnnyBody
from garsim.bodies.base import BodyModel
from garsim.geometry.skinning import apply_transforms, blended_transforms, dense_weights


def _dominant_bone_names(body: AnnyBody) -> np.ndarray:
    w, idx = body.skin_weights, body.skin_indices
    return np.array(body.bone_labels)[idx[np.arange(len(w)), w.argmax(axis=1)]]


def _lbs(body: AnnyBody, transforms: np.ndarray) -> np.ndarray:
    weights = dense_weights(body.skin_indices, body.skin_weights, len(body.bone_labels))
    return apply_transforms(body.rest_vertices.astype(np.float64), blended_transforms(weights, transforms))


def test_is_a_body_model_with_consistent_arrays(anny_body):
    b = anny_body
    assert isinstance(b, BodyModel)
    v = b.num_vertices
    assert b.rest_vertices.shape == (v, 3) and b.faces.shape[1] == 3
    assert b.faces.min() == 0 and b.faces.max() == v - 1
    assert b.skin_weights.shape == b.skin_indices.shape == (v, 9)
    np.testing.assert_allclose(b.skin_weights.sum(axis=1), 1.0, atol=1e-5)
    assert len(b.bone_labels) == 104 and b.bone_index("upperleg01.L") == b.bone_labels.index("upperleg01.L")


def test_t_pose_is_mirror_symmetric_in_x(anny_body):
    v = anny_body.canonical().vertices
    mirrored = v * np.array([-1.0, 1.0, 1.0], dtype=np.float32)
    dist, _ = cKDTree(v).query(mirrored)
    assert dist.max() < 2e-3  # every vertex has a mirror twin (Anny is symmetric to ~0.4 mm)
    assert abs(float(v[:, 0].mean())) < 1e-3


def test_t_pose_raises_the_arms_relative_to_the_a_pose(anny_body):
    dom = _dominant_bone_names(anny_body)
    t_pose = anny_body.canonical().vertices
    a_pose = anny_body.pose(None).vertices
    for side in "LR":
        wrist = dom == f"wrist.{side}"
        shoulder = dom == f"upperarm01.{side}"
        lift = t_pose[wrist, 2].mean() - a_pose[wrist, 2].mean()
        assert lift > 0.2, f"wrist.{side} raised by only {lift:.3f} m"
        # In the T-pose the arm is near horizontal: wrist within 10 cm of the shoulder's height.
        assert abs(t_pose[wrist, 2].mean() - t_pose[shoulder, 2].mean()) < 0.1
        # ... and spread: wrists far apart in X, on the correct side (X points to the body's left).
        sign = 1.0 if side == "L" else -1.0
        assert sign * t_pose[wrist, 0].mean() > 0.55
    # Legs do not move between the A- and T-pose.
    legs = np.isin(dom, ["foot.L", "foot.R", "lowerleg01.L", "lowerleg01.R"])
    np.testing.assert_allclose(t_pose[legs], a_pose[legs], atol=1e-5)


def test_identity_pose_transforms_skin_the_rest_mesh_to_the_output(anny_body):
    vertices, transforms = anny_body.pose_batch(None)
    assert transforms.shape == (1, len(anny_body.bone_labels), 4, 4)
    np.testing.assert_allclose(_lbs(anny_body, transforms[0]), vertices[0], atol=1e-5)
    # Anny's own output is not its rest mesh: the root is moved to the origin (DESIGN.md's trap).
    assert np.abs(vertices[0] - anny_body.rest_vertices).max() > 1e-3
    # The same holds for a real pose (the canonical T-pose).
    can = anny_body.canonical()
    np.testing.assert_allclose(_lbs(anny_body, can.transforms), can.vertices, atol=1e-5)


def test_batched_posing_equals_one_by_one(anny_body):
    # A batch of 4 (a (3, 3) array would be read as one rotation matrix, see AnnyBody's rotation formats).
    rng = np.random.default_rng(3)
    batch = {
        "upperleg01.L": rng.normal(0, 0.3, (4, 3)),
        "lowerarm01.R": rng.normal(0, 0.3, (4, 3)),
        "spine02": rng.normal(0, 0.1, (4, 3)),
    }
    vertices, transforms = anny_body.pose_batch(batch)
    assert vertices.shape == (4, anny_body.num_vertices, 3)
    for i in range(4):
        single = anny_body.pose({k: v[i] for k, v in batch.items()})
        np.testing.assert_allclose(vertices[i], single.vertices, atol=1e-5)
        np.testing.assert_allclose(transforms[i], single.transforms, atol=1e-6)


def test_rotation_formats_agree(anny_body):
    import roma
    import torch

    rotvec = np.array([0.3, -0.2, 0.1])
    mat = roma.rotvec_to_rotmat(torch.as_tensor(rotvec)).numpy()
    homog = np.eye(4)
    homog[:3, :3] = mat
    a = anny_body.pose({"neck01": rotvec}).vertices
    np.testing.assert_allclose(anny_body.pose({"neck01": mat}).vertices, a, atol=1e-5)
    np.testing.assert_allclose(anny_body.pose({"neck01": homog}).vertices, a, atol=1e-5)


@pytest.mark.parametrize("topology", ["smpl", "smplx", "smplx_something"])
def test_downloading_topologies_are_refused_without_network(topology, monkeypatch):
    def no_network(*args, **kwargs):
        raise AssertionError("garsim tried to open a network connection")

    monkeypatch.setattr(socket.socket, "connect", no_network)
    monkeypatch.setattr(socket, "create_connection", no_network)
    with pytest.raises(ValueError, match="downloads non-free SMPL data"):
        AnnyBody(topology=topology)


@pytest.mark.parametrize(
    "phenotype, message",
    [
        ({"age": 1.5}, "must be a number in"),
        ({"height": -0.1}, "must be a number in"),
        ({"weight": float("nan")}, "must be a number in"),
        ({"gender": float("inf")}, "must be a number in"),
        ({"shoe_size": 0.5}, "unknown phenotype keys"),
    ],
)
def test_bad_phenotypes_are_rejected(phenotype, message):
    with pytest.raises(ValueError, match=message):
        AnnyBody(phenotype)


def test_bad_bone_names_and_shapes_are_rejected(anny_body):
    with pytest.raises(ValueError, match="unknown bone 'elbow.L'"):
        anny_body.pose({"elbow.L": [0.0, 0.0, 0.1]})
    with pytest.raises(ValueError, match="unknown bone"):
        anny_body.bone_index("not-a-bone")
    with pytest.raises(ValueError, match="must be axis-angle"):
        anny_body.pose({"neck01": [0.0, 0.1]})
    with pytest.raises(ValueError, match="batch sizes differ"):
        anny_body.pose_batch({"neck01": np.zeros((2, 3)), "spine01": np.zeros((4, 3))})


def test_canonical_kinds(anny_body):
    a, t = anny_body.canonical("apose"), anny_body.canonical()
    np.testing.assert_allclose(a.vertices, anny_body.pose(None).vertices)
    assert not np.allclose(a.vertices, t.vertices)
    with pytest.raises(ValueError, match="tpose"):
        anny_body.canonical("xpose")
