import numpy as np
import pytest

from garsim.bodies.anny import AnnyBody
from garsim.bodies.base import PosedBody
from garsim.bodies.prior import garment_prior, rigfree_prior, ring_operator, rotations_between, vertex_rotations

POSE = {"upperleg01.L": [-0.8, 0.0, 0.0], "spine02": [0.0, 0.0, 0.5], "lowerarm01.R": [0.0, 0.0, 1.0]}


@pytest.fixture(scope="module")
def body():
    return AnnyBody({})


def shell(body: AnnyBody, offset: float = 0.02, step: int = 6) -> np.ndarray:
    """Points 2 cm outside the canonical body (a garment-like shell)."""
    from garsim.geometry.mesh import vertex_normals

    c = body.canonical().vertices
    return (c + offset * vertex_normals(c, body.faces))[::step]


def test_rotations_of_a_rigid_rotation_are_that_rotation():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2)
    angle = 0.7
    r = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    rot = vertex_rotations(m.vertices, m.vertices @ r.T + [1.0, 2.0, 3.0], m.faces)
    np.testing.assert_allclose(rot, np.broadcast_to(r, rot.shape), atol=1e-9)


def test_rotations_through_a_ring_operator_equal_vertex_rotations():
    """The per-garment operator (set up once, reused per pose) gives :func:`vertex_rotations`' values on a pose
    that bends the mesh (rotations that differ per vertex)."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2)
    v = np.asarray(m.vertices)
    bent = v + 0.3 * np.stack([np.sin(2 * v[:, 2]), np.cos(3 * v[:, 0]), v[:, 1] ** 2], axis=1)
    expected = vertex_rotations(v, bent, m.faces, rings=2)
    assert np.abs(expected - expected[0]).max() > 0.1  # not one rotation for all: a real comparison
    np.testing.assert_allclose(
        rotations_between(v, bent, *ring_operator(m.faces, len(v), rings=2)), expected, atol=1e-9
    )


def test_rigfree_prior_moves_rigidly_with_a_rigid_body_motion():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=3)
    g = np.asarray(m.vertices[::3]) * 1.1
    angle = -0.4
    r = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]])
    t = np.array([0.3, -0.2, 0.5])
    prior = rigfree_prior(g, m.vertices, m.vertices @ r.T + t, m.faces)
    np.testing.assert_allclose(prior, g @ r.T + t, atol=1e-5)


def test_identity_pose_gives_identity_prior(body):
    c = body.canonical()
    g = shell(body)
    np.testing.assert_allclose(garment_prior(body, c, c, g), g, atol=1e-5)
    np.testing.assert_allclose(rigfree_prior(g, c.vertices, c.vertices, body.faces), g, atol=1e-5)


def test_rigfree_prior_matches_lbs_prior_on_anny(body):
    c, t = body.canonical(), body.pose(POSE)
    g = shell(body)
    lbs = garment_prior(body, c, t, g)
    free = garment_prior(body, PosedBody(c.vertices), PosedBody(t.vertices), g)  # no transforms -> rig-free
    err = np.linalg.norm(lbs - free, axis=1)
    assert err.mean() < 1e-3 and np.percentile(err, 95) < 3e-3, (err.mean(), np.percentile(err, 95))
    moved = np.linalg.norm(lbs - g, axis=1)
    assert moved.max() > 0.3  # the pose really moves the garment (the leg is raised)


def test_sparse_lbs_prior_equals_dense_weight_transfer(body):
    """garment_prior's fast path (per-body-vertex blending) = lbs_prior with dense transferred weights."""
    from garsim.geometry.skinning import dense_weights, lbs_prior, transfer_weights

    c, t = body.canonical(), body.pose(POSE)
    g = shell(body, offset=0.03, step=9)
    w = transfer_weights(g, c.vertices, dense_weights(body.skin_indices, body.skin_weights, len(c.transforms)))
    np.testing.assert_allclose(garment_prior(body, c, t, g), lbs_prior(g, w, c.transforms, t.transforms), atol=2e-6)


def test_prior_skinned_by_some_bones_ignores_the_others(body):
    """``bones``: skinned by the torso's bones alone, points around the torso and shoulders stay put when only an arm
    rises, where the plain prior drags the shoulder's skin along; a mask of every bone is the plain prior."""
    from garsim.physics.generate import TORSO_BONES

    c = body.canonical()
    raised = body.pose({"upperarm01.L": [0.0, -0.6, 0.0]})  # one arm only: no torso bone moves
    g = shell(body, step=1)
    near = g[np.abs(g[:, 0] - c.vertices[:, 0].mean()) < 0.2]  # torso and shoulders, not the arms beyond
    torso = body.bone_mask(TORSO_BONES)
    assert 5 < torso.sum() < len(torso) and not torso[body.bone_index("upperarm01.L")]
    plain = garment_prior(body, c, raised, near)
    held = garment_prior(body, c, raised, near, torso)
    dragged, kept = np.linalg.norm(plain - near, axis=1), np.linalg.norm(held - near, axis=1)
    assert dragged.max() > 0.01 and (dragged > 1e-3).sum() > 50  # the shoulder's skin moves with the arm
    # still, but where the anchoring skin has no torso weight at all (the armpit's arm side keeps its own weights)
    assert np.percentile(kept, 99) < 1e-5 and kept.max() < 0.2 * dragged.max()
    np.testing.assert_allclose(garment_prior(body, c, raised, near, np.ones(len(torso), bool)), plain, atol=1e-6)
