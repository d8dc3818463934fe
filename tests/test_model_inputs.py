"""Sample -> graph (Eq. 2): every input checked against brute-force values; batching offsets."""

import dataclasses

import numpy as np
import pytest
import torch
from mesh_fixtures import plane_grid
from model_fixtures import make_sample, rot_z, transform_sample

from garsim.geometry.mesh import face_pairs
from garsim.model.config import GarSimConfig
from garsim.model.graph import build_graph, collate
from garsim.model.inputs import body_yaw_frame, semantic_vector


@pytest.fixture(scope="module")
def sample():
    return make_sample(n_around=16, n_down=5, fabric="denim", pose_id=2)


def _anchor_weights(points: np.ndarray, body: np.ndarray, width: float = 0.04) -> np.ndarray:
    """Brute-force dense soft-anchor weights (N, V): (1 - (d^2 - dmin^2) / width^2)_+^2, rows normalised."""
    d2 = ((points[:, None, :].astype(np.float64) - body[None].astype(np.float64)) ** 2).sum(-1)
    w = np.clip(1.0 - (d2 - d2.min(axis=1, keepdims=True)) / width**2, 0.0, None) ** 2
    return w / w.sum(axis=1, keepdims=True)


def test_eq2_quantities_match_brute_force(sample):
    cfg = GarSimConfig(canonicalize_yaw=False)
    g = build_graph(sample, cfg)
    G, B, Bt, P = sample.garment, sample.body_canonical, sample.body_target, sample.prior
    w = _anchor_weights(G, B)
    bq, bq_t = w @ B, w @ Bt
    np.testing.assert_allclose(g.p.numpy(), G - bq, atol=1e-6)
    np.testing.assert_allclose(g.p_prior.numpy(), P - bq_t, atol=1e-6)
    np.testing.assert_allclose(g.delta.numpy(), bq_t - bq, atol=1e-6)
    rows, slots = g.anchor_index.numpy()
    dense = np.zeros((len(G), g.body_rel.shape[0]))
    dense[rows, slots] = g.anchor_weight.numpy()
    np.testing.assert_allclose(dense.sum(axis=1), 1.0, atol=1e-6)
    assert (w > 0).sum() == len(rows)  # exactly the body vertices with a positive weight
    s, r = g.edge_index.numpy()
    np.testing.assert_allclose(g.edge_attr.numpy()[:, :3], G[r] - G[s], atol=1e-6)
    np.testing.assert_allclose(g.edge_attr.numpy()[:, 3:], P[r] - P[s], atol=1e-6)
    assert g.edge_index.shape[1] == 2 * (16 * 5 + 2 * 16 * 4)  # rings + verticals + diagonals, both ways
    # denim on the silk (0) .. leather (1) log scales of bending, density, stretch
    from garsim.garments.fabrics import PRESETS

    expect = [
        (np.log(getattr(PRESETS["denim"], k)) - np.log(getattr(PRESETS["silk"], k)))
        / (np.log(getattr(PRESETS["leather"], k)) - np.log(getattr(PRESETS["silk"], k)))
        for k in ("bending", "density", "stretch")
    ]
    np.testing.assert_allclose(g.fabric.numpy(), np.tile(expect, (len(G), 1)), atol=1e-6)
    assert g.pinned.sum() == 16
    # geometry-encoder neighbourhoods: self first (zero), then mesh neighbours only (edge lengths)
    rel = g.gar_rel.numpy()
    np.testing.assert_allclose(rel[:, 0], 0.0)
    lengths = {round(float(np.linalg.norm(G[a] - G[b])), 5) for a, b in zip(s, r)} | {0.0}
    assert {round(float(x), 5) for x in np.linalg.norm(rel, axis=-1).ravel()} <= lengths
    np.testing.assert_allclose(g.body_rel.numpy()[:, 0], 0.0)
    assert np.array_equal(g.face_pairs.numpy(), face_pairs(sample.garment_faces))


def test_anchor_weights_are_continuous_where_the_nearest_vertex_jumps():
    """Half-way between two body points the hard nearest vertex flips; the soft anchor blends both."""
    from garsim.geometry.proximity import soft_anchor

    body = np.array([[-0.1, 0, 0], [0.1, 0, 0], [0.0, 0.5, 0]])
    xs = np.linspace(-1e-4, 1e-4, 5)
    pts = np.stack([xs, np.zeros(5), np.full(5, 0.05)], axis=1)
    w = soft_anchor(pts, body).toarray()
    np.testing.assert_allclose(w[2], [0.5, 0.5, 0.0])
    assert (np.diff(w[:, 0]) < 0).all() and np.abs(np.diff(w[:, 0])).max() < 0.02  # no jump at the medial plane
    far = soft_anchor(np.array([[0.5, 0, 0]]), body).toarray()[0]
    assert far.tolist() == [0.0, 1.0, 0.0]  # a clear nearest vertex alone carries the weight
    assert soft_anchor(np.zeros((0, 3)), body).shape == (0, 3)  # no points (e.g. a garment without pins)


def test_yaw_frame_commutes_with_rotation(sample):
    r0 = body_yaw_frame(sample.body_canonical)
    assert abs(r0[0, 0] - 1.0) < 1e-3  # Anny already faces -Y: the frame is ~identity
    rz = rot_z(1.1)
    r1 = body_yaw_frame(sample.body_canonical @ rz.T + np.array([3.0, -2.0, 0.5]))
    np.testing.assert_allclose(r1, r0 @ rz.T, atol=1e-6)  # frame(R x) = frame(x) R^T
    np.testing.assert_allclose(r1 @ r1.T, np.eye(3), atol=1e-9)


def test_inputs_invariant_to_yaw_and_translation(sample):
    g0 = build_graph(sample)
    moved = transform_sample(sample, rot_z(-2.0), np.array([0.4, 0.3, -0.2]))
    g1 = build_graph(moved)
    for key in ("p", "p_prior", "delta", "edge_attr", "sem", "anchor_weight", "anchor_index"):
        np.testing.assert_allclose(getattr(g1, key).numpy(), getattr(g0, key).numpy(), atol=5e-5, err_msg=key)
    for key in ("gar_rel", "body_rel"):  # neighbourhoods: the same point sets (the encoder max-pools, order-free)
        a, b = (np.sort(np.round(getattr(x, key).numpy(), 4).view([("", "f4")] * 3)[..., 0], axis=1) for x in (g1, g0))
        assert np.array_equal(a, b), key


def test_semantic_vectors(sample):
    cfg_v = GarSimConfig(semantic="vertex", num_body_vertices=len(sample.body_canonical))
    g = build_graph(sample, cfg_v)
    mask = g.sem.numpy()[0]
    w = _anchor_weights(sample.garment, sample.body_canonical)
    np.testing.assert_allclose(mask, w.max(axis=0), atol=1e-6)  # each body vertex's largest anchor weight
    with pytest.raises(ValueError, match="semantic='grid'"):
        build_graph(sample, GarSimConfig(semantic="vertex", num_body_vertices=6890))
    grid = build_graph(sample).sem.numpy()[0].reshape(8, 4, 16)
    assert grid.min() >= 0 and grid.max() < 1
    # the skirt spans z in [-0.45, 0] on a body from z=-0.87 to 0.76: normalised heights 0.26..0.53,
    # i.e. grid coordinates 3.9..8.0 of 15 -> trilinear cells 3..9 only (nothing at the chest or legs)
    occupied_z = np.flatnonzero(grid.sum(axis=(0, 1)) > 0)
    assert occupied_z.min() >= 3 and occupied_z.max() <= 9
    # a single vertex at a grid node lands in that cell with 1 - exp(-1)
    one = semantic_vector(
        np.array([[-0.5, -0.25, 0.0], [0.5, 0.25, 1.0], [0.0, 0.0, 0.0]]), np.array([0]), GarSimConfig()
    )
    assert one.reshape(8, 4, 16)[0, 0, 0] == pytest.approx(1 - np.exp(-1)) and one.sum() == pytest.approx(
        1 - np.exp(-1)
    )


def test_batch_offsets_indices(sample):
    other = make_sample(n_around=12, n_down=4, fabric="silk", pose_id=3)
    g0, g1 = build_graph(sample, with_collision=True), build_graph(other, with_collision=True)
    b = collate([g0, g1])
    n0, f0 = g0.num_nodes, g0.faces.shape[0]
    assert b.num_graphs == 2 and b.num_nodes == n0 + g1.num_nodes
    assert torch.equal(b.edge_index[:, g0.edge_index.shape[1] :], g1.edge_index + n0)
    assert torch.equal(b.faces[f0:], g1.faces + n0)
    assert torch.equal(b.face_pairs[g0.face_pairs.shape[0] :], g1.face_pairs + f0)
    assert b.sem.shape == (2, 512) and b.rot.shape == (2, 3, 3)
    assert set(b.col_batch.tolist()) == {0, 1}
    assert b.name == [sample.meta["name"], other.meta["name"]]


def test_bad_input_messages(sample):
    from dataclasses import replace

    with pytest.raises(ValueError, match="reference vertices outside"):
        build_graph(replace(sample, garment_faces=sample.garment_faces + 1000))
    bad = sample.prior.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        build_graph(replace(sample, prior=bad))


def test_body_rings_and_caches_follow_content():
    from garsim.model.inputs import body_frame, garment_topology

    # a square split in two triangles + a pendant triangle: vertex 0 touches 1, 2, 3
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], dtype=np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 2]])
    ring = body_frame(verts, faces, canonicalize_yaw=False).ring(4)
    # nearest neighbours first (ties by index), padded with self
    assert ring.tolist() == [[0, 1, 3, 2], [1, 0, 2, 4], [2, 1, 3, 0], [3, 0, 2, 3], [4, 1, 2, 4]]
    # cut to the nearest neighbours when the ring is larger than k - 1
    assert body_frame(verts, faces, canonicalize_yaw=False).ring(3)[0].tolist() == [0, 1, 3]
    # the cache is keyed by content: edited vertices or faces give a new frame, never a stale one
    moved = verts.copy()
    moved[4] = [3, 0, 0]
    assert body_frame(moved, faces, False) is not body_frame(verts, faces, False)
    assert body_frame(verts, faces[:2], False).ring(4)[4].tolist() == [4, 4, 4, 4]
    ring2, ei = garment_topology(verts, faces, 2)
    assert ring2[:, 0].tolist() == [0, 1, 2, 3, 4]
    assert (np.diff(ei[1]) >= 0).all() and ei.shape == (2, 2 * 7)  # receiver-sorted, 7 edges both ways
    assert ring2[4, 1] == 1
    other = verts.copy()
    other[4] = [1, 1.5, 0]  # now nearer to its neighbour 2: the cached answer must not be reused
    assert garment_topology(other, faces, 2)[0][4, 1] == 2


def test_collision_normals_equal_full_vertex_normals(sample):
    from garsim.geometry.mesh import vertex_normals
    from garsim.model.graph import collision_body

    col = collision_body(sample)
    full = vertex_normals(sample.body_target, sample.body_faces)
    d2 = ((col["col_body"].numpy()[:, None, :] - sample.body_target[None, :, :]) ** 2).sum(-1)
    sel = d2.argmin(axis=1)
    np.testing.assert_array_equal(col["col_normal"].numpy(), full[sel])  # bitwise: same faces, same order
    assert len(sel) > 50 and np.allclose(np.linalg.norm(col["col_normal"].numpy(), axis=1), 1.0, atol=1e-5)


def test_pose_free_part_is_shared_and_read_only(sample):
    """Two poses of one garment share one StaticGraph; graph_arrays is its arrays plus the pose's, fresh copies."""
    import dataclasses

    from garsim.model.inputs import graph_arrays, pose_arrays, static_graph

    other = dataclasses.replace(sample, body_target=sample.body_target + 0.01, prior=sample.prior + 0.01)
    static = static_graph(sample)
    assert static_graph(other) is static  # the pose does not enter the key
    assert not static.arrays["p"].flags.writeable  # shared by every pose: nobody may edit it
    full = graph_arrays(other, loss_inputs=False)
    assert full["p"].flags.writeable and not np.shares_memory(full["p"], static.arrays["p"])
    pose = pose_arrays(static, other)
    for key, value in {**static.arrays, **pose}.items():
        np.testing.assert_array_equal(full[key], value, err_msg=key)
    # moving the target and the prior by the same 1 cm moves only the anchor and the prior
    base = graph_arrays(sample)
    shift = np.full(3, 0.01) @ static.rot64.T  # the 1 cm world shift in the body frame
    np.testing.assert_allclose(full["delta"] - base["delta"], np.broadcast_to(shift, base["delta"].shape), atol=1e-5)
    np.testing.assert_allclose(full["p_prior"], base["p_prior"], atol=1e-5)


def test_target_surface_on_a_plane_by_hand():
    """A flat grid body (normal +Z): a point straight above a grid vertex has its offset and signed distance = its
    height (negative below), the normal +Z; turning the frame turns the offset and the normal, not the distance."""
    from garsim.model.inputs import target_surface

    body, faces = plane_grid()  # 2 cm grid, the soft anchor's blend is symmetric about a vertex
    pts = np.array([[0.02, -0.04, 0.05], [0.0, 0.0, -0.03]])
    f = target_surface(pts, body, faces, np.eye(3))
    np.testing.assert_allclose(f[:, :3], [[0, 0, 0.05], [0, 0, -0.03]], atol=1e-6)
    np.testing.assert_allclose(f[:, 3:6], [[0, 0, 1], [0, 0, 1]], atol=1e-6)
    np.testing.assert_allclose(f[:, 6], [0.05, -0.03], atol=1e-6)
    r = rot_z(0.7)
    pts2 = np.array([[0.01, 0.0, 0.04]])  # between two grid vertices: the offset has a horizontal part
    a, b = target_surface(pts2, body, faces, np.eye(3)), target_surface(pts2, body, faces, r)
    assert abs(a[0, 0]) < 1e-6 and a[0, 2] == pytest.approx(0.04, abs=1e-6)  # symmetric blend: straight above
    np.testing.assert_allclose(b[:, :3], a[:, :3] @ r.T, atol=1e-6)
    np.testing.assert_allclose(b[:, 6], a[:, 6], atol=1e-7)


def test_target_surface_input_follows_the_scene_and_is_continuous(sample):
    """The target-surface input is invariant to a yaw and translation of the whole scene, and 1e-7 m of noise on
    the prior moves it by about as much (no hard nearest-vertex choice)."""
    cfg = GarSimConfig(target_surface=True)
    g0 = build_graph(sample, cfg)
    assert g0.surface.shape == (len(sample.garment), 7)
    g1 = build_graph(transform_sample(sample, rot_z(-2.0), np.array([0.4, 0.3, -0.2])), cfg)
    np.testing.assert_allclose(g1.surface.numpy(), g0.surface.numpy(), atol=5e-5)
    rng = np.random.default_rng(0)
    noisy = dataclasses.replace(sample, prior=sample.prior + rng.normal(0, 1e-7, sample.prior.shape).astype("f4"))
    assert np.abs(build_graph(noisy, cfg).surface.numpy() - g0.surface.numpy()).max() < 1e-4
    assert not hasattr(build_graph(sample), "surface")  # off by default: the paper's inputs only


def test_local_rotations_follow_the_scene_and_are_continuous(sample):
    """The per-vertex rotations of ``local_rotation`` turn with a yaw of the whole scene (R -> Rz R Rz^T), ignore a
    translation, are proper rotations, and 1e-7 m of noise on the prior moves them by about as much."""
    cfg = GarSimConfig(local_rotation=True)
    r0 = build_graph(sample, cfg).local_rot.numpy().astype(np.float64)
    assert r0.shape == (len(sample.garment), 3, 3)
    np.testing.assert_allclose(np.linalg.det(r0), 1.0, atol=1e-5)
    np.testing.assert_allclose(r0 @ r0.transpose(0, 2, 1), np.broadcast_to(np.eye(3), r0.shape), atol=1e-5)
    assert np.abs(r0 - np.eye(3)).max() > 0.05  # the pose turns the garment somewhere: a real test
    rz = rot_z(-2.0)
    r1 = build_graph(transform_sample(sample, rz, np.array([0.4, 0.3, -0.2])), cfg).local_rot.numpy()
    np.testing.assert_allclose(r1, rz @ r0 @ rz.T, atol=5e-5)
    rng = np.random.default_rng(0)
    noisy = dataclasses.replace(sample, prior=sample.prior + rng.normal(0, 1e-7, sample.prior.shape).astype("f4"))
    assert np.abs(build_graph(noisy, cfg).local_rot.numpy() - r0).max() < 1e-4
    assert not hasattr(build_graph(sample), "local_rot")  # off by default
