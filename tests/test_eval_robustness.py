"""garsim.eval.robustness on fake drapers whose answers are computed by hand, and its scene readers."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from garsim.eval.robustness import (
    CHECKS,
    Scene,
    measure,
    perturbation_changes,
    rest_displacement_mm,
    scenes_from_jobs,
    scenes_from_npz,
    scenes_from_store,
    split_at_seam,
    turn_about_vertical,
)
from garsim.geometry.io import load_mesh
from garsim.geometry.rigid import yaw_alignment

FIXTURE = Path(__file__).parent / "fixtures" / "dataset_v2"


class Offset:
    """Drapes by moving the garment with the target body's turn and move from the canonical one, then adding
    ``offset`` (world frame) plus ``ramp`` x the vertex's index / N: not equivariant to turns when ``offset`` is
    horizontal, and dependent on the vertex order when ``ramp`` is not zero."""

    def __init__(self, offset=(0.0, 0.0, 0.0), ramp=(0.0, 0.0, 0.0)):
        self.offset, self.ramp = np.asarray(offset), np.asarray(ramp)

    def drape(self, canonical, target, garment, fabric):
        (v, _), (c, _), (t, _) = (load_mesh(m) if isinstance(m, str) else m for m in (garment, canonical, target))
        rot, shift = yaw_alignment(c, t)
        v = np.asarray(v, dtype=np.float64) @ rot.T + shift
        return v + self.offset + self.ramp * (np.arange(len(v)) / len(v))[:, None]


class Still(Offset):
    """``Offset`` that ignores the target body: the garment stays where the canonical body has it."""

    def drape(self, canonical, target, garment, fabric):
        return super().drape(canonical, canonical, garment, fabric)


def _scene(n: int = 40) -> Scene:
    rng = np.random.default_rng(3)
    strip = np.stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)], axis=1)  # a triangle strip
    body = (rng.normal(size=(n, 3)), strip)
    return Scene("s", "skirt", body, body, (rng.normal(size=(n, 3)), strip), "silk")


def test_turn_about_vertical_is_a_rotation_about_z():
    v = np.array([[1.0, 0.0, 2.0]])
    np.testing.assert_allclose(turn_about_vertical(v, 90.0), [[0.0, 1.0, 2.0]], atol=1e-12)
    np.testing.assert_allclose(turn_about_vertical(v, 180.0, np.array([1.0, 1.0, 0.0])), [[0.0, 1.0, 2.0]], atol=1e-12)


def test_an_equivariant_order_free_draper_passes_every_check():
    changes = perturbation_changes(Offset(offset=(0.0, 0.0, -0.01)), _scene())
    assert set(changes) == set(CHECKS)
    assert changes["noise"] < 0.01  # 1e-6 m noise: at most a few micrometres
    assert max(v for k, v in changes.items() if k != "noise") < 1e-3  # the OBJ text: ~0.1 micrometre


def test_a_world_frame_offset_is_caught_by_the_turns_by_hand():
    changes = perturbation_changes(Offset(offset=(0.01, 0.0, 0.0)), _scene())
    # turned back, a 10 mm offset along x is turned by -37 deg: |R(-37) x - x| = 2 * 10 mm * sin(18.5 deg)
    assert changes["turn_37"] == pytest.approx(20.0 * np.sin(np.radians(18.5)), rel=1e-6)
    assert changes["turn_180"] == pytest.approx(20.0, rel=1e-6)
    assert changes["shift_10m"] < 1e-6 and changes["face_permutation"] < 1e-6
    # the target alone turned 90 deg: the garment follows it, the offset does not turn with it
    assert changes["target_turn_90"] == pytest.approx(10.0 * np.sqrt(2.0), rel=1e-6)
    assert changes["target_shift_2m"] < 1e-6


def test_a_draper_that_ignores_the_target_body_is_caught_when_it_moves_alone():
    changes = perturbation_changes(Still(), _scene())
    assert changes["target_shift_2m"] == pytest.approx(1000.0 * np.linalg.norm([1.2, -1.6, 0.05]), rel=1e-6)
    assert changes["target_turn_90"] > 100.0 and changes["turn_37"] < 1e-3


def test_an_order_dependent_draper_is_caught_by_the_vertex_permutation():
    changes = perturbation_changes(Offset(ramp=(0.01, 0.0, 0.0)), _scene(n=40))
    assert 5.0 < changes["vertex_permutation"] <= 10.0  # the ramp moves some vertex by up to 10 mm x (N-1)/N
    assert changes["face_permutation"] < 1e-6


class Valence(Offset):
    """Drapes by lifting each vertex 1 mm per face that uses it: blind to where a file splits its vertices."""

    def drape(self, canonical, target, garment, fabric):
        v, f = load_mesh(garment) if isinstance(garment, str) else garment
        v = np.asarray(v, dtype=np.float64)
        return v + [0.0, 0.0, 0.001] * np.bincount(np.asarray(f).ravel(), minlength=len(v))[:, None]


def test_split_at_seam_by_hand():
    """A front panel (y = -1) of two squares, left and right of x = 0, and one vertex at the back: the two panel
    vertices on x = 0 get copies (6, 7), which the right square's faces take."""
    v = np.array([[-1, -1, 0], [0, -1, 0], [1, -1, 0], [-1, -1, 1], [0, -1, 1], [1, -1, 1], [0, 1, 0.5]], float)
    f = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    sv, sf, source = split_at_seam(v, f)
    np.testing.assert_array_equal(source, [0, 1, 2, 3, 4, 5, 6, 1, 4])
    np.testing.assert_array_equal(sv, v[source])
    np.testing.assert_array_equal(sf, [[0, 1, 4], [0, 4, 3], [7, 2, 5], [7, 5, 8]])


def test_a_draper_that_reads_the_file_s_connectivity_is_caught_by_the_seam_split():
    changes = perturbation_changes(Valence(), _scene())
    assert changes["seam_split"] >= 1.0  # a seam vertex of the strip loses at least one of its faces to its copy
    assert changes["face_permutation"] < 1e-6 and changes["vertex_permutation"] < 1e-6


def test_the_noise_check_takes_the_largest_change_over_its_draws():
    """A draper that leaves the garment in place moves a vertex exactly as much as the noise does: the check is the
    largest noise vector's length over the draws (the first draw is the single-draw check's own), in micrometres."""
    sim = Still()
    one = perturbation_changes(sim, _scene(), seed=5)["noise"]
    three = perturbation_changes(sim, _scene(), seed=5, noise_draws=3)["noise"]
    rng = np.random.default_rng(5)
    sizes = []
    for _ in range(3):
        draws = [rng.normal(0.0, 1e-6, (40, 3)) for _ in range(3)]  # canonical, target, garment: the garment's counts
        sizes.append(1000.0 * np.linalg.norm(draws[2], axis=1).max())
    assert one == pytest.approx(sizes[0]) and three == pytest.approx(max(sizes)) and three >= one
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="noise_draws"):
            perturbation_changes(sim, _scene(), noise_draws=bad)


def test_rest_displacement_and_the_summary_by_hand():
    sim = Offset(offset=(0.0, 0.0, -0.002))
    assert rest_displacement_mm(sim, _scene()) == pytest.approx(2.0)
    out = measure(sim, [_scene(), replace(_scene(), name="t", garment_type="top")])
    assert [r["name"] for r in out["rows"]] == ["s", "t"]
    assert set(out["summary"]) == {"all", "skirt", "top"} and out["summary"]["all"]["n"] == 2
    assert out["summary"]["all"]["rest_max_mm"] == pytest.approx(2.0)
    assert out["summary"]["all"]["equivariance_max_mm"] < 1e-6
    with pytest.raises(ValueError, match="no scenes"):
        measure(sim, [])


def test_scenes_from_the_fixture_store_and_from_npz_files(tmp_path):
    scenes = scenes_from_store(FIXTURE, split="test", per_type=1)
    assert sorted(s.garment_type for s in scenes) == ["dress", "longsleeve", "skirt", "top", "trousers", "tshirt"]
    assert all(s.canonical[0].dtype == np.float64 for s in scenes)
    wide = scenes_from_store(FIXTURE, split="test", per_type=1, wide_poses=7)[0]
    assert np.abs(wide.target[0] - scenes[0].target[0]).max() > 0.05  # the same body posed anew
    np.testing.assert_array_equal(wide.canonical[0], scenes[0].canonical[0])
    with pytest.raises(ValueError, match="no 'full' resolution"):
        scenes_from_store(FIXTURE, resolution="full")
    s = scenes[0]
    np.save(tmp_path / "body_faces.npy", s.canonical[1])
    np.savez(
        tmp_path / "h000.npz",
        body_canonical=s.canonical[0].astype(np.float32),
        body_target=s.target[0].astype(np.float32),
        garment_template=s.garment[0].astype(np.float32),
        garment_faces=s.garment[1].astype(np.int32),
        garment_type=np.array(s.garment_type),
        fabric=np.array("silk"),
    )
    (read,) = scenes_from_npz(tmp_path)
    assert read.name == "h000" and read.garment_type == s.garment_type and read.fabric == "silk"
    np.testing.assert_allclose(read.garment[0], s.garment[0], atol=1e-6)
    with pytest.raises(ValueError, match="body_faces.npy"):
        scenes_from_npz(tmp_path / "missing")


def test_scenes_from_jobs_build_the_planned_garments_in_wide_poses():
    from garsim.physics.generate import GenerateConfig, plan_jobs

    scenes = scenes_from_jobs(2, seed=3, wide_poses=5)
    jobs = plan_jobs(GenerateConfig(out=Path("."), seed=3, num_train=2, num_test=0, num_ood=0))
    assert [s.garment_type for s in scenes] == [j.family for j in jobs] == ["skirt", "top"]
    for scene, job in zip(scenes, jobs, strict=True):
        assert scene.name == f"{job.job_id}-{job.construction}"
        assert 0.6 * job.vertices < len(scene.garment[0]) < 1.6 * job.vertices  # built at the planned resolution
        assert scene.garment[1].max() < len(scene.garment[0]) and scene.canonical[1] is scene.target[1]
        moved = np.linalg.norm(scene.target[0] - scene.canonical[0], axis=1)
        assert moved.max() > 0.05  # posed away from the canonical body, same topology
        values = {k: v for k, v in job.fabrics[0].items() if k != "name"}
        name = job.fabrics[0]["name"]
        assert scene.fabric == (values if name == "custom" else name)  # a preset by name, else its physical values
    again = scenes_from_jobs(1, seed=3, wide_poses=5)[0]  # deterministic in the seeds
    np.testing.assert_array_equal(again.target[0], scenes[0].target[0])
    np.testing.assert_array_equal(again.garment[0], scenes[0].garment[0])
    with pytest.raises(ValueError, match="count must be an integer >= 1"):
        scenes_from_jobs(0)


def test_the_robustness_script_on_one_planned_garment(tmp_path):
    """examples/robustness.py --jobs: the shipped model's checks on a garment the generator plans, no dataset folder."""
    import json
    import os
    import subprocess
    import sys

    out = tmp_path / "r.json"
    script = Path(__file__).parents[1] / "examples" / "robustness.py"
    cmd = [sys.executable, str(script), "--jobs", "1", "--seed", "4", "--wide-poses", "9", "--json", str(out)]
    subprocess.run(cmd, check=True, capture_output=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    report = json.loads(out.read_text())
    (row,) = report["sets"]["jobs:1"]["rows"]
    assert row["name"] == "train-00000-template" and row["garment_type"] == "skirt"  # the plan's first job
    assert set(CHECKS) <= set(row) and all(np.isfinite(row[c]) for c in CHECKS)
    assert row["obj_round_trip"] <= 0.5 and row["turn_180"] <= 0.5 and row["rest_mm"] <= 3.0
