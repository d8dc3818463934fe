"""Nearest-body-vertex queries and the signed side test."""

from __future__ import annotations

import numpy as np

from garsim.geometry.proximity import nearest_vertices, signed_offset_to_nearest


def test_nearest_vertices_hand_computed():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0]], dtype=np.float64)
    pts = np.array([[0.9, 0.1, 0.0], [0.0, 1.5, 0.0], [-1.0, 0.0, 0.0]])
    idx, dist = nearest_vertices(pts, verts)
    np.testing.assert_array_equal(idx, [1, 2, 0])
    np.testing.assert_allclose(dist, [np.sqrt(0.02), 0.5, 1.0])
    idx2, dist2 = nearest_vertices(pts, verts, k=2)
    assert idx2.shape == (3, 2)
    np.testing.assert_array_equal(idx2[:, 0], [1, 2, 0])
    np.testing.assert_array_equal(idx2[:, 1], [0, 0, 1])
    np.testing.assert_allclose(dist2[:, 1], [np.hypot(0.9, 0.1), 1.5, 2.0])


def test_nearest_vertices_match_brute_force():
    rng = np.random.default_rng(0)
    verts = rng.normal(size=(500, 3))
    pts = rng.normal(size=(200, 3))
    idx, dist = nearest_vertices(pts, verts)
    d = np.linalg.norm(pts[:, None] - verts[None], axis=2)
    np.testing.assert_array_equal(idx, d.argmin(axis=1))
    np.testing.assert_allclose(dist, d.min(axis=1))


def test_signed_offset_plane():
    # a plane z = 0 sampled on a grid, normals +Z
    xs, ys = np.meshgrid(np.linspace(-1, 1, 11), np.linspace(-1, 1, 11))
    verts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    normals = np.tile([0.0, 0.0, 1.0], (len(verts), 1))
    pts = np.array([[0.0, 0.0, 0.3], [0.41, -0.2, -0.05], [0.5, 0.5, 0.0]])
    np.testing.assert_allclose(signed_offset_to_nearest(pts, verts, normals), [0.3, -0.05, 0.0], atol=1e-12)


def test_signed_offset_sphere(icosphere):
    v, f = icosphere
    normals = v / np.linalg.norm(v, axis=1, keepdims=True)
    dirs = v[::7] / np.linalg.norm(v[::7], axis=1, keepdims=True)
    outside = signed_offset_to_nearest(dirs * 1.05, v, normals)
    inside = signed_offset_to_nearest(dirs * 0.95, v, normals)
    np.testing.assert_allclose(outside, 0.05, atol=1e-5)  # the nearest vertex is the one the point was pushed from
    np.testing.assert_allclose(inside, -0.05, atol=1e-5)


def test_push_outside_moves_only_inside_points_to_the_margin():
    import trimesh

    from garsim.geometry.mesh import vertex_normals
    from garsim.geometry.proximity import push_outside, signed_offset_to_nearest

    s = trimesh.creation.icosphere(subdivisions=3)
    v, n = np.asarray(s.vertices), vertex_normals(np.asarray(s.vertices), s.faces)
    pts = np.concatenate([v[:20] * 0.95, v[20:40] * 1.05])
    out = push_outside(pts, v, n, margin=0.002)
    np.testing.assert_allclose(out[20:], pts[20:])  # outside points untouched
    np.testing.assert_allclose(signed_offset_to_nearest(out[:20], v, n), 0.002, atol=1e-9)
