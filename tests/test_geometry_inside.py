"""Inside-the-body tests: warp winding number (exact) and DeePSD's nearest-normal proxy."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest
import trimesh
from mesh_fixtures import ridge_prism

from garsim.geometry.inside import InsideTester, collision_fraction, inside_mask
from garsim.geometry.mesh import vertex_normals


def test_icosphere_inside_outside_and_offsets(icosphere):
    v, f = icosphere
    tester = InsideTester(v, f)
    assert tester.inside(np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, -5.0, 2.0]])).tolist() == [
        True,
        False,
        False,
    ]
    dirs = v / np.linalg.norm(v, axis=1, keepdims=True)
    assert tester.inside(dirs * 0.97).all()  # 3 cm inside the (slightly faceted) unit sphere
    assert not tester.inside(dirs * 1.03).any()
    # signed distance: -1 at the centre (to within the facets), +1 at radius 2
    sd = tester.signed_distance(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]]))
    np.testing.assert_allclose(sd, [-1.0, 1.0], atol=0.01)
    assert tester.inside(np.zeros((0, 3))).shape == (0,)


def test_update_refits_for_a_moved_mesh(icosphere):
    v, f = icosphere
    tester = InsideTester(v, f)
    p = np.array([[3.0, 0.0, 0.0]])
    assert not tester.inside(p)[0]
    tester.update(v + np.array([3.0, 0.0, 0.0], dtype=np.float32))
    assert tester.inside(p)[0]
    assert not tester.inside(np.zeros((1, 3)))[0]
    with pytest.raises(ValueError, match="same topology"):
        tester.update(v[:10])


def test_bad_inputs(icosphere):
    v, f = icosphere
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        InsideTester(v, f).inside(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="NaN"):
        InsideTester(v, f).inside(np.full((1, 3), np.nan))
    with pytest.raises(ValueError, match="outside"):
        InsideTester(v, f + len(v))
    from garsim.geometry.inside import obstacle

    for blend in (-0.001, np.nan):
        with pytest.raises(ValueError, match="blend must be"):
            obstacle(v, f).query(np.zeros((1, 3)), blend=blend)


def test_collision_fraction_on_a_sphere(icosphere):
    v, f = icosphere
    n = vertex_normals(v, f)
    dirs = v / np.linalg.norm(v, axis=1, keepdims=True)
    pts = np.concatenate([dirs[:100] * 0.95, dirs[100:400] * 1.05])  # 100 in, 300 out
    assert collision_fraction(pts, v, n) == pytest.approx(0.25)
    assert collision_fraction(np.zeros((0, 3)), v, n) == 0.0
    # the exact test agrees on these easy points
    assert inside_mask(pts, v, f).mean() == pytest.approx(0.25)


def test_anny_body_pelvis_inside_front_outside_and_timing(anny_body):
    body = anny_body.canonical()
    tester = InsideTester(body.vertices, anny_body.faces)
    hips = body.vertices[(np.abs(body.vertices[:, 2]) < 0.03) & (np.abs(body.vertices[:, 0]) < 0.2)]
    centre = hips.mean(axis=0)  # centre of the ring of hip-level vertices (pelvis is near the origin)
    front = centre + np.array([0.0, -0.5, 0.0])
    assert tester.inside(np.stack([centre, front])).tolist() == [True, False]
    rng = np.random.default_rng(0)
    lo, hi = body.vertices.min(axis=0), body.vertices.max(axis=0)
    queries = rng.uniform(lo, hi, (10_000, 3)).astype(np.float32)
    tester.inside(queries[:10])  # compile/load the kernel outside the timing
    t0 = time.perf_counter()
    inside = tester.inside(queries)
    dt = time.perf_counter() - t0
    t0 = time.perf_counter()
    tester.update(body.vertices)
    dt_refit = time.perf_counter() - t0
    print(
        f"\ninside test: 10k queries on a {len(body.vertices)}-vertex body in {dt * 1e3:.1f} ms; "
        f"refit {dt_refit * 1e3:.1f} ms"
    )
    assert 0.01 < inside.mean() < 0.3  # a body fills a small part of its bounding box
    # 5 mm off the torso/legs surface (away from the mouth's inner teeth/tongue shell, the eyes and the
    # touching toes, where "outside a shell" is still inside the head or the foot): both tests agree exactly
    v = body.vertices
    n = vertex_normals(v, anny_body.faces)
    sel = np.flatnonzero((v[:, 2] > -0.6) & (v[:, 2] < 0.45) & (np.abs(v[:, 0]) < 0.5))
    assert len(sel) > 2000
    near = np.concatenate([v[sel] - 0.005 * n[sel], v[sel] + 0.005 * n[sel]])
    exact = tester.inside(near)
    assert exact[: len(sel)].all() and not exact[len(sel) :].any()
    assert collision_fraction(near, v, n) == pytest.approx(0.5, abs=0.002)


def test_exact_obstacle_is_shared_and_agrees_with_the_tester(icosphere):
    """One exact closest-point implementation (geometry.inside.Obstacle), the one refine uses; it agrees with
    warp's float32 closest point of InsideTester and signs points like the winding number."""
    from garsim import refine as refine_module
    from garsim.geometry.inside import obstacle

    assert refine_module.obstacle is obstacle
    v, f = icosphere
    rng = np.random.default_rng(3)
    p = rng.normal(size=(200, 3)) * 0.6
    sd, close, normal, found = obstacle(v, f).query(p)
    assert found.all()
    tester = InsideTester(v, f)
    c32, _ = tester.closest(p)
    assert np.abs(close - c32).max() < 1e-5
    assert np.array_equal(sd < 0, tester.inside(p))
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0)
    away = np.abs(sd) > 1e-4  # off the surface the normal is the signed direction from the closest point
    expected = np.sign(sd[away])[:, None] * (p[away] - close[away]) / np.abs(sd[away])[:, None]
    assert np.allclose(normal[away], expected, atol=1e-9)
    assert (np.einsum("ij,ij->i", normal, close) > 0).all()  # a sphere about the origin: normals point outwards


def test_warp_starts_quietly():
    """A fresh process that starts warp through garsim prints nothing: no banner, and no CUDA-driver warning on a
    machine without one (garsim runs on the CPU)."""
    from garsim.geometry.inside import _cuda_driver_present

    code = "from garsim.geometry.inside import quiet_warp; quiet_warp().zeros(3)"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert run.stdout == ""
    if not _cuda_driver_present():
        assert run.stderr == ""


def test_contact_plane_turns_continuously_across_a_ridge():
    """Inside a convex ridge (a prism whose two roof faces meet at 160 degrees), the closest face changes at the
    bisector plane and its normal jumps by the ridge's 20 degrees under a 2e-6 m move; the contact half-space's
    normal (``blend``) does not: on the bisector it is the mean of the two roof normals, 1 mm beyond the reach of the
    second face it is the face's own, and its point is always p - s * normal (the first-order model of the signed
    distance at p)."""
    from garsim.geometry.inside import obstacle

    half = np.radians(10.0)  # each roof face is tilted 10 degrees off horizontal
    v, f, h = ridge_prism(10.0)
    obs = obstacle(v, f)
    depth = 0.004
    p = np.array([[-1e-6, 0.0, h - depth], [1e-6, 0.0, h - depth], [0.0, 0.0, h - depth]])
    sd, _, exact, _ = obs.query(p)
    roof = np.array([[-np.sin(half), 0.0, np.cos(half)], [np.sin(half), 0.0, np.cos(half)]])
    assert (sd < 0).all()
    np.testing.assert_allclose(exact[:2], roof, atol=1e-9)  # the closest face's normal jumps by 20 degrees
    sd_b, point, normal, _ = obs.query(p, blend=0.001)
    np.testing.assert_array_equal(sd_b, sd)  # the distance stays exact
    assert np.abs(normal[0] - normal[1]).max() < 1e-3
    np.testing.assert_allclose(normal[2], [0.0, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(point, p - sd[:, None] * normal, atol=1e-12)
    # far enough from the bisector that the other roof face is more than 1 mm farther: the exact half-space
    x = 0.01
    q = np.array([[x, 0.0, h - x * np.tan(half) - depth]])
    sd_q, close_q, exact_q, _ = obs.query(q)
    _, point_q, normal_q, _ = obs.query(q, blend=0.001)
    np.testing.assert_allclose(normal_q, exact_q, atol=1e-12)
    np.testing.assert_allclose(point_q, close_q, atol=1e-12)


def test_contact_plane_keeps_the_nearest_side_of_a_gap():
    """Between two boxes 4 mm apart (a gap between body parts, their faces opposite), a point 1.9 mm from the lower
    box and 2.1 mm from the upper one has both in reach: their normals cancel, so the contact normal is the nearest
    side's own, not an average along the gap."""
    from garsim.geometry.inside import obstacle

    low = trimesh.creation.box(extents=[0.2, 0.2, 0.1])
    low.apply_translation([0.0, 0.0, -0.05])  # top face at z = 0
    high = trimesh.creation.box(extents=[0.2, 0.2, 0.1])
    high.apply_translation([0.0, 0.0, 0.054])  # bottom face at z = 0.004
    both = trimesh.util.concatenate([low, high])
    obs = obstacle(np.asarray(both.vertices), np.asarray(both.faces))
    p = np.array([[0.01, 0.02, 0.0019], [0.01, 0.02, 0.0021]])
    sd, close, exact, _ = obs.query(p)
    _, point, normal, _ = obs.query(p, blend=0.001)
    np.testing.assert_allclose(sd, [0.0019, 0.0019], atol=1e-12)
    np.testing.assert_allclose(normal, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], atol=1e-12)
    np.testing.assert_allclose(point, close, atol=1e-12)
    # the far side finely tessellated (a fan of 48 triangles facing down over p), the near side two triangles: the
    # far side's many normals outweigh the near side's in the mean, which must not turn the normal into the near side
    ring = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    fan_v = np.vstack(
        [[0.01, 0.02, 0.004], np.c_[0.01 + 0.01 * np.cos(ring), 0.02 + 0.01 * np.sin(ring), np.full(48, 0.004)]]
    )
    fan_f = np.array([[0, 1 + (k + 1) % 48, 1 + k] for k in range(48)]) + len(low.vertices)
    obs = obstacle(np.vstack([low.vertices, fan_v]), np.vstack([low.faces, fan_f]))
    _, _, normal, _ = obs.query(p[:1], blend=0.001)
    np.testing.assert_allclose(normal, [[0.0, 0.0, 1.0]], atol=1e-12)
