"""Skinning-weight transfer and the LBS prior (paper Sec. 3.1), checked on Anny's own vertices."""

from __future__ import annotations

import numpy as np
import pytest

from garsim.geometry.skinning import (
    apply_transforms,
    blended_transforms,
    dense_weights,
    lbs_prior,
    transfer_weights,
)

POSE = {
    "upperleg01.L": [0.6, 0.0, 0.0],
    "lowerleg01.R": [-0.8, 0.0, 0.0],
    "spine02": [0.2, 0.1, 0.3],
    "lowerarm01.R": [0.0, 0.0, 1.0],
    "neck01": [0.3, 0.0, 0.0],
}


@pytest.fixture(scope="module")
def rig(anny_body):
    """(canonical PosedBody, posed PosedBody, dense (V, J) weights) of the default Anny body."""
    weights = dense_weights(anny_body.skin_indices, anny_body.skin_weights, len(anny_body.bone_labels))
    return anny_body.canonical(), anny_body.pose(POSE), weights


def _rigid(angle: float, axis: np.ndarray, shift: np.ndarray) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    t = np.eye(4)
    t[:3, :3] = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    t[:3, 3] = shift
    return t


def test_dense_weights_hand_computed():
    idx = np.array([[0, 2], [1, 1], [3, 0]])
    w = np.array([[0.25, 0.75], [0.5, 0.5], [1.0, 0.0]])
    np.testing.assert_allclose(dense_weights(idx, w, 4), [[0.25, 0, 0.75, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


def test_blended_transforms_and_apply():
    t = np.stack([np.eye(4), _rigid(0.0, np.array([0, 0, 1.0]), np.array([1.0, 0, 0]))])
    m = blended_transforms(np.array([[0.5, 0.5]]), t)
    np.testing.assert_allclose(apply_transforms(np.array([[0.0, 1.0, 0.0]]), m), [[0.5, 1.0, 0.0]])


def test_anny_dense_weights_are_a_partition_of_unity(anny_body):
    w = dense_weights(anny_body.skin_indices, anny_body.skin_weights, len(anny_body.bone_labels))
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-5)


def test_lbs_prior_reproduces_anny_posed_vertices(rig):
    canonical, posed, weights = rig
    prior = lbs_prior(canonical.vertices, weights, canonical.transforms, posed.transforms)
    assert np.abs(posed.vertices - canonical.vertices).max() > 0.1  # the pose really moves the body
    np.testing.assert_allclose(prior, posed.vertices, atol=1e-5)


def test_identity_pose_gives_identity(rig):
    canonical, _, weights = rig
    prior = lbs_prior(canonical.vertices, weights, canonical.transforms, canonical.transforms)
    np.testing.assert_allclose(prior, canonical.vertices, atol=1e-6)
    rng = np.random.default_rng(1)
    garment = canonical.vertices[rng.choice(len(canonical.vertices), 300)] + rng.normal(0, 0.02, (300, 3))
    gw = transfer_weights(garment, canonical.vertices, weights)
    np.testing.assert_allclose(lbs_prior(garment, gw, canonical.transforms, canonical.transforms), garment, atol=1e-6)


def test_rigid_transform_of_target_moves_prior_rigidly(rig):
    canonical, posed, weights = rig
    rng = np.random.default_rng(2)
    garment = canonical.vertices[rng.choice(len(canonical.vertices), 500)] + rng.normal(0, 0.02, (500, 3))
    gw = transfer_weights(garment, canonical.vertices, weights)
    t = _rigid(0.7, np.array([0.2, -0.4, 1.0]), np.array([0.3, -0.1, 0.5]))
    prior = lbs_prior(garment, gw, canonical.transforms, posed.transforms)
    moved = lbs_prior(garment, gw, canonical.transforms, t[None] @ posed.transforms)
    np.testing.assert_allclose(moved, prior @ t[:3, :3].T + t[:3, 3], atol=2e-5)


def test_transfer_weights_blend_nearby_vertices_and_sum_to_one(rig):
    canonical, _, weights = rig
    rng = np.random.default_rng(3)
    pts = canonical.vertices[rng.choice(len(canonical.vertices), 400)] + rng.normal(0, 0.03, (400, 3))
    w = transfer_weights(pts, canonical.vertices, weights)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-6)
    assert (w >= 0).all()
    # continuous: a 1 µm move changes the weights by far less than a hard nearest-vertex switch would
    w2 = transfer_weights(pts + rng.normal(0, 1e-6, pts.shape), canonical.vertices, weights)
    assert np.abs(w2 - w).max() < 1e-2


def test_transfer_weights_soft_anchor_by_hand():
    body = np.array([[0.0, 0, 0], [0.01, 0, 0], [1.0, 0, 0]])
    w_body = np.eye(3)
    # d^2 = 0.25e-4 and 0.25e-4 (+0 excess) at the midpoint: equal blend; the far vertex is outside the width
    np.testing.assert_allclose(transfer_weights(np.array([[0.005, 0, 0]]), body, w_body), [[0.5, 0.5, 0.0]])
    # at x = 0: excess of vertex 1 = 1e-4 / 0.04^2 = 1/16 -> weight (15/16)^2 against 1
    a = (15 / 16) ** 2
    np.testing.assert_allclose(transfer_weights(np.zeros((1, 3)), body, w_body), [[1 / (1 + a), a / (1 + a), 0.0]])
