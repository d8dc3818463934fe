"""Newton VBD simulation: settle, move the body, reject exploded/penetrating results, fabric ordering."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from garsim.geometry.mesh import edge_lengths, unique_edges
from garsim.physics.newton_sim import (
    REJECT_NON_FINITE,
    REJECT_OVERSTRETCHED,
    REJECT_PENETRATION,
    SimConfig,
    SimulationRejected,
    check_result,
    crop_body,
)


def _grid_patch(n: int = 4, size: float = 0.2, z: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """An n x n vertex flat patch at height z above the unit sphere."""
    u = np.linspace(-size / 2, size / 2, n)
    x, y = np.meshgrid(u, u, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.full(n * n, z)], 1).astype(np.float32)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    f = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return v, f


def _reason(*args, **kwargs) -> tuple[str, str]:
    """(reason, "frame K") of the rejection ``check_result`` raises (fails if it accepts)."""
    with pytest.raises(SimulationRejected) as err:
        check_result(*args, **kwargs)
    frame = err.value.detail.split(" at frame ")[-1].split(" ")[0].rstrip(")")
    return err.value.reason, f"frame {frame}"


# -- rejection (no Newton needed) ------------------------------------------------------------------
def test_check_result_accepts_a_clean_result(icosphere):
    bv, bf = icosphere
    v, f = _grid_patch()
    rest = edge_lengths(v, f)
    frames = np.stack([v, v + [0.0, 0.0, 0.1]])
    assert check_result(frames, f, rest, bv, bf) is None


def test_check_result_rejects_nan_with_its_reason(icosphere, caplog):
    bv, bf = icosphere
    v, f = _grid_patch()
    frames = np.stack([v, v.copy()])
    frames[1, 3, 2] = np.nan
    with caplog.at_level(logging.WARNING, logger="garsim.physics.newton_sim"), pytest.raises(SimulationRejected) as err:
        check_result(frames, f, edge_lengths(v, f), bv, bf)
    assert err.value.reason == REJECT_NON_FINITE and "frame 1" in err.value.detail
    assert "rejected" in caplog.text and REJECT_NON_FINITE in caplog.text


def test_check_result_rejects_a_stretched_edge(icosphere):
    bv, bf = icosphere
    v, f = _grid_patch(n=4, size=0.3)  # edges 0.1 m
    edges = unique_edges(f)
    bad = v.copy()
    bad[15] += [0.06, 0.0, 0.0]  # corner vertex: its edges grow to 1.6x (> 1.5x)
    assert _reason(np.stack([v, bad]), f, edge_lengths(v, f), bv, bf) == (REJECT_OVERSTRETCHED, "frame 1")
    fine = v.copy()
    fine[15] += [0.04, 0.0, 0.0]  # 1.4x: accepted
    check_result(fine, f, edge_lengths(v, f), bv, bf)
    assert len(edges) == len(edge_lengths(v, f))
    # edges between two pinned vertices follow the body, not the solver: not tested
    pinned = np.zeros(len(v), dtype=bool)
    pinned[15] = True
    assert _reason(np.stack([v, bad]), f, edge_lengths(v, f), bv, bf, pinned=pinned)[0] == REJECT_OVERSTRETCHED
    pinned[np.unique(edges[(edges == 15).any(axis=1)])] = True
    check_result(np.stack([v, bad]), f, edge_lengths(v, f), bv, bf, pinned=pinned)


def test_check_result_rejects_penetration_over_one_percent(icosphere):
    bv, bf = icosphere
    v, f = _grid_patch(n=11, size=0.5, z=0.0)  # 121 vertices in the sphere's equatorial plane: all inside
    outside = v + [0.0, 0.0, 1.5]
    loose = edge_lengths(v, f) * 100  # isolate the inside test from the stretch test
    one = outside.copy()
    one[0] = [0.0, 0.0, 0.0]  # 1/121 < 1 %: accepted
    check_result(np.stack([outside, one]), f, loose, bv, bf)
    two = one.copy()
    two[1] = [0.1, 0.0, 0.0]  # 2/121 > 1 %: rejected at frame 1
    assert _reason(np.stack([outside, two]), f, loose, bv, bf) == (REJECT_PENETRATION, "frame 1")
    # per-frame bodies: a body moved away makes the same frame clean
    bodies = np.stack([bv, bv + [5.0, 0.0, 0.0]])
    check_result(np.stack([outside, two]), f, loose, bodies, bf)


def test_check_result_validates_rest_lengths(icosphere):
    bv, bf = icosphere
    v, f = _grid_patch()
    with pytest.raises(ValueError, match="unique_edges"):
        check_result(v[None], f, np.ones(3), bv, bf)


def test_sim_config_validation():
    assert SimConfig().dt == pytest.approx(1.0 / (SimConfig().fps * SimConfig().substeps))
    with pytest.raises(ValueError, match="damping"):
        SimConfig(damping=1.5)
    with pytest.raises(ValueError, match="substeps"):
        SimConfig(substeps=0)


def test_crop_body_keeps_faces_near_the_garment_at_any_frame():
    # two triangles: one at the origin, one 1 m away that only comes near at frame 1
    v0 = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [1, 0, 0], [1.1, 0, 0], [1, 0.1, 0]], np.float32)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    box = np.array([[[-0.05, -0.05, -0.05], [0.05, 0.05, 0.05]]] * 2)
    used, fc = crop_body(v0[None], f, box[:1], 0.01)
    assert used.tolist() == [0, 1, 2] and fc.tolist() == [[0, 1, 2]]
    v1 = v0 - [1.0, 0.0, 0.0]
    used, fc = crop_body(np.stack([v0, v1]), f, box, 0.01)
    assert used.tolist() == [0, 1, 2, 3, 4, 5] and fc.tolist() == f.tolist()
    used, fc = crop_body(v0[None], f, box[:1], None)
    assert len(used) == 6


# -- simulation ------------------------------------------------------------------------------------
newton = pytest.importorskip("newton")

from garsim.bodies.base import PosedBody  # noqa: E402
from garsim.bodies.prior import garment_prior  # noqa: E402
from garsim.garments.fabrics import PRESET_NAMES  # noqa: E402
from garsim.garments.templates import make_garment  # noqa: E402
from garsim.physics.newton_sim import (  # noqa: E402
    inside_fraction,
    mean_body_distance,
    mean_fold_angle,
    settle,
    simulate_poses,
)


@pytest.fixture(scope="module")
def lowres_skirt(anny_body):
    return make_garment("skirt", anny_body, {"length": 0.45, "flare": 0.5}, target_vertices=300)


def _segment(body, can, template, pinned, pose, frames):
    """Body and pin trajectories canonical -> ``pose`` (pins on the garment prior)."""
    from garsim.bodies.poses import batched_matrices, interpolate_poses, stack_poses

    verts, transforms = body.pose_batch(batched_matrices(stack_poses(interpolate_poses(body.t_pose(), pose, frames))))
    pins = np.stack([garment_prior(body, can, PosedBody(v, t), template[pinned]) for v, t in zip(verts, transforms)])
    return verts, pins


def test_settle_then_chained_poses_settle_at_each(anny_body, lowres_skirt):
    """Coarse settle, then two chained leg poses: each state settled (speed below the threshold), pins on their
    targets, the physics checks pass, and the skirt followed the raised thigh."""
    body, g = anny_body, lowres_skirt
    can = body.canonical()
    cfg = SimConfig(max_settle_frames=40, max_hold_frames=40)
    template, info = settle(g, can.vertices, body.faces, "cotton", cfg)
    assert info["aborted"] is None and info["settled"] and info["final_speed"][0] < cfg.settle_speed
    np.testing.assert_allclose(template[g.pinned], g.vertices[g.pinned], atol=1e-6)  # pins held
    assert (template[~g.pinned, 2] - g.vertices[~g.pinned, 2]).mean() < -0.002  # it fell
    pose_a = {"upperleg01.L": np.array([-0.5, 0.0, 0.0])}
    seg_a, pins_a = _segment(body, can, template, g.pinned, pose_a, 10)
    from garsim.bodies.poses import batched_matrices, interpolate_poses, stack_poses

    pose_b = {"upperleg01.R": np.array([-0.3, 0.0, 0.0])}
    verts, transforms = body.pose_batch(batched_matrices(stack_poses(interpolate_poses(pose_a, pose_b, 10))))
    pins_b = np.stack(
        [garment_prior(body, can, PosedBody(v, t), template[g.pinned]) for v, t in zip(verts, transforms)]
    )
    states, infos = simulate_poses(
        template, g.faces, g.pinned, [seg_a, verts], body.faces, [pins_a, pins_b], ["cotton"], cfg
    )
    assert len(states) == 2 and [i["target"] for i in infos] == [0, 1]
    rest = edge_lengths(g.vertices, g.faces)
    for state, info, seg, pins in zip(states, infos, (seg_a, verts), (pins_a, pins_b)):
        assert state.shape == (1, len(template), 3) and info["settled"]
        assert max(info["final_speed"]) < cfg.settle_speed  # a settled sample is below the threshold
        np.testing.assert_allclose(state[0][g.pinned], pins[-1], atol=1e-5)
        check_result(state[0], g.faces, rest, seg[-1], body.faces, pinned=g.pinned)
        assert inside_fraction(state[0], seg[-1], body.faces) < 0.01
    assert np.abs(states[0][0] - template).max() > 0.02


def test_absurd_timestep_is_caught(anny_body, lowres_skirt):
    """One 2-second step under 100x gravity: the simulator aborts or check_result rejects it."""
    g = lowres_skirt
    can = anny_body.canonical()
    cfg = SimConfig(fps=0.5, substeps=1, iterations=1, gravity=-981.0, max_settle_frames=2, min_settle_frames=2)
    v, info = settle(g, can.vertices, anny_body.faces, "silk", cfg)
    if info["aborted"] is None:
        with pytest.raises(SimulationRejected):
            check_result(v[None], g.faces, edge_lengths(g.vertices, g.faces), can.vertices, anny_body.faces)


def paired_group(body, kind: str, params: dict, target_vertices: int, cfg: SimConfig):
    """One template settled once (cotton), then held on the same body in all four presets (one Newton model)."""
    g = make_garment(kind, body, params, target_vertices=target_vertices)
    can = body.canonical()
    template, _ = settle(g, can.vertices, body.faces, "cotton", cfg)
    still = np.repeat(can.vertices[None], 2, axis=0)
    pins = np.repeat(template[g.pinned][None], 2, axis=0)
    states, infos = simulate_poses(template, g.faces, g.pinned, [still], body.faces, [pins], PRESET_NAMES, cfg)
    state = states[0]
    out = {
        name: (1000 * mean_body_distance(state[c], can.vertices), mean_fold_angle(state[c], g.faces))
        for c, name in enumerate(PRESET_NAMES)
    }
    print(out, infos)
    return out


def test_paired_fabrics_are_ordered_by_stiffness(anny_body):
    """One shared skirt template in four fabrics: folds ordered (silk most folded), leather farthest from the body."""
    m = paired_group(anny_body, "skirt", {"length": 0.5, "flare": 0.6}, 400, SimConfig(max_hold_frames=40))
    angles = [m[n][1] for n in PRESET_NAMES]
    assert all(a > b for a, b in zip(angles, angles[1:])), m
    assert m["leather"][0] > m["silk"][0] + 1.0, (
        m
    )  # measured 1.9 mm (44.3 / 44.3 / 44.4 / 46.3 mm): real fabrics differ in folds


@pytest.mark.slow
@pytest.mark.xfail(
    strict=False,
    reason="measured 2026-12-01 with the then default SimConfig (10 x 4; 40 x 4 since 2026-12-02), this skirt "
    "settled alone on the canonical body: denim 37.8 / "
    "35.2 / 36.9 / 38.4 / 33.8 / 37.0 / 35.9 / 35.5 / 34.0 mm at 800 / 1,000 / 1,200 / 1,400 / 1,600 / 2,000 / "
    "2,400 / 2,800 / 3,200 target vertices (no trend: the fold pattern changes with the mesh, range 4.6 mm); "
    "cotton 38.5 / 36.9 / 33.2 / 34.4 at 800 / 1,000 / 1,600 / 3,200; leather falls steadily, 44.0 / 43.3 / 40.7 / "
    "40.3 / 38.0 / 36.8 at 800 / 1,000 / 1,200 / 1,600 / 2,400 / 3,200 (coarse meshes drape stiffer), and more so "
    "with 20 substeps x 8 iterations (63.4 vs 46.2 mm at 800 / 3,200, every fabric ~10 mm farther out at 1,600); "
    "settling to 0.004 m/s instead of 0.02 changed leather by < 1.1 mm. The hinge stiffness 3 B L / (A1 + A2) "
    "times Newton's rest-length factor is the discrete-shell energy 3 B |e|^2 / A theta^2, so the mesh dependence "
    "is the solver's and the discretisation's. At 40 x 4 (2026-12-03, this test): denim 51.7 / 43.9 / 39.5 mm at "
    "800 / 1,600 / 3,200, a steady trend (range 12.2 mm): with the solve nearer convergence coarse meshes drape "
    "stiffer, as leather did at 10 x 4",
)
def test_one_fabric_drapes_alike_at_three_resolutions(anny_body):
    """The same skirt in denim settles to the same mean distance from the body (within 3 mm) at 800, 1,600 and
    3,200 vertices: the hinge stiffness follows each edge's length and triangle areas."""
    can = anny_body.canonical()
    dist = []
    for n in (800, 1600, 3200):
        g = make_garment("skirt", anny_body, {"length": 0.5, "flare": 0.6}, target_vertices=n)
        v, info = settle(g, can.vertices, anny_body.faces, "denim", SimConfig())
        dist.append(1000 * mean_body_distance(v, can.vertices))
    print(dist)
    assert max(dist) - min(dist) < 3.0, dist


def test_settling_phase_switches_iterations_and_damping_and_collision_runs_every_kth_substep(icosphere):
    """A tiny patch above a sphere: the settle loop runs with ``settle_iterations`` / ``settle_damping`` and
    restores the motion settings afterwards; collision detection runs on every ``collide_every``-th substep."""
    from garsim.physics.newton_sim import ClothScene, _settle_loop

    v, f = _grid_patch(4, z=1.05)
    cfg = SimConfig(
        substeps=4, iterations=6, settle_iterations=2, damping=0.9, settle_damping=0.5, collide_every=2, graphs=False
    )  # launched one by one, so that the wrapped calls below see every substep
    scene = ClothScene(v, f, np.zeros(len(v), bool), *icosphere, ["cotton"], cfg)
    calls = []
    collide = scene.pipeline.collide
    scene.pipeline.collide = lambda *a: calls.append(1) or collide(*a)
    seen = []
    step = scene.solver.step
    scene.solver.step = lambda *a: seen.append((scene.solver.iterations, scene.damping)) or step(*a)
    scene.frame()
    assert len(calls) == 2 and set(seen) == {(6, 0.9)}  # motion settings, 4 substeps / 2
    seen.clear()
    edges = unique_edges(f)
    _settle_loop(scene, 2, cfg, edges, np.linalg.norm(v[edges[:, 1]] - v[edges[:, 0]], axis=1))
    assert set(seen) == {(2, 0.5)} and (scene.solver.iterations, scene.damping) == (6, 0.9)
    with pytest.raises(ValueError):
        SimConfig(collide_every=0)
    with pytest.raises(ValueError):
        SimConfig(settle_damping=0.0)


def test_graph_replay_and_tight_contacts_are_bit_identical_to_launching_one_by_one(icosphere):
    """Two fabric copies of a patch with two pinned vertices, a moving sphere and moving pins, damping, collision
    every 2nd of 3 substeps (the state buffers swap parity every frame), then settling settings: replaying the
    captured substeps with the tight contact buffer gives exactly the positions of launching every kernel with
    Newton's full-size buffer, and each kind of substep is captured once."""
    from garsim.physics import newton_sim
    from garsim.physics.newton_sim import ClothScene

    v, f = _grid_patch(5, z=1.04)
    pinned = np.zeros(len(v), bool)
    pinned[[0, 4]] = True
    bv, bf = icosphere
    results = []
    for fast in (False, True):
        cfg = SimConfig(
            substeps=3,
            iterations=2,
            damping=0.95,
            settle_damping=0.8,
            settle_iterations=3,
            collide_every=2,
            graphs=fast,
            tight_contacts=fast,
        )
        scene = ClothScene(v, f, pinned, bv, bf, ["silk", "leather"], cfg)
        trace = []
        for j in range(4):  # the sphere rises 4 mm per substep under the patch, the pins slide sideways
            for i in range(cfg.substeps):
                k = j * cfg.substeps + i
                scene.substep(bv + [0.0, 0.0, 0.004 * k], v[pinned] + [0.002 * k, 0.0, 0.0])
            trace.append(scene.positions())
        scene.settling(True)
        trace.append(scene.frame())
        scene.settling(False)
        trace.append(scene.frame())
        results.append(np.stack(trace))
        assert int(scene._most_contacts.numpy()[0]) > 10  # the patch lies on the sphere
        if fast:
            assert 0 < len(scene._graphs) <= 8 < 6 * cfg.substeps  # reused: (pins, phase, settings, buffer) kinds
            assert scene.contacts.soft_contact_max == scene.contact_capacity == newton_sim.MIN_CONTACT_CAPACITY
        else:
            assert scene.contact_capacity is None
    eager, replayed = results
    assert np.isfinite(eager).all() and np.abs(eager[-1] - v).max() > 0.01  # the cloth moved
    assert np.allclose(eager[3][:, pinned], v[pinned] + [0.002 * 11, 0.0, 0.0], atol=1e-6)  # pins on target
    assert np.array_equal(eager, replayed)


def test_an_overflowing_contact_buffer_runs_again_with_the_full_one(icosphere, monkeypatch, caplog):
    """A contact buffer too small for the patch lying on the sphere: the scene refuses to hand out positions, and
    ``settle`` runs again with Newton's full-size buffer, giving the full-buffer result."""
    from garsim.garments.garment import Garment
    from garsim.physics import newton_sim
    from garsim.physics.newton_sim import ClothScene, ContactOverflow, settle

    v, f = _grid_patch(5, z=1.003)
    bv, bf = icosphere
    cfg = SimConfig(substeps=3, iterations=2, max_settle_frames=3, min_settle_frames=3)
    full, _ = settle(Garment(v, f, np.zeros(len(v), bool), "top"), bv, bf, "cotton", replace(cfg, tight_contacts=False))
    monkeypatch.setattr(newton_sim, "MIN_CONTACT_CAPACITY", 1)
    monkeypatch.setattr(newton_sim, "CONTACTS_PER_PARTICLE", 0)
    scene = ClothScene(v, f, np.zeros(len(v), bool), bv, bf, ["cotton"], cfg)
    scene.substep()
    scene.substep()
    with pytest.raises(ContactOverflow, match="over 1 contact record"):
        scene.positions()
    with caplog.at_level(logging.INFO, logger="garsim.physics.newton_sim"):
        again, _ = settle(Garment(v, f, np.zeros(len(v), bool), "top"), bv, bf, "cotton", cfg)
    assert "full-size contact buffer" in caplog.text
    assert np.array_equal(full, again)
