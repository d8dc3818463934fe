import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict, replace

import numpy as np
import pytest

from garsim.data.store import DatasetStore
from garsim.garments.templates import PARAMS
from garsim.physics import generate as gen
from garsim.physics.generate import FAMILIES, GenerateConfig, plan_jobs, split_indices
from garsim.physics.newton_sim import SimConfig


def test_plan_is_deterministic_and_split_without_leakage(tmp_path):
    cfg = GenerateConfig(out=tmp_path, seed=3, num_train=48, num_test=12, num_ood=10)
    jobs = plan_jobs(cfg)
    assert [j.__dict__ for j in jobs] == [j.__dict__ for j in plan_jobs(cfg)]
    assert plan_jobs(GenerateConfig(out=tmp_path, seed=4, num_train=48))[0].phenotype != jobs[0].phenotype
    by_split = {s: [j for j in jobs if j.split == s] for s in ("train", "test", "ood")}
    assert [len(v) for v in by_split.values()] == [48, 12, 10]
    train = by_split["train"]
    assert {j.family for j in train} == set(FAMILIES)
    assert {(j.family, j.construction) for j in train} >= {
        ("skirt", "template"),
        ("skirt", "implicit"),
        ("longsleeve", "implicit"),
        ("trousers", "template"),
    }
    assert {j.canonical_arm for j in train} >= {0.0, 40.0} and any(0 < j.canonical_arm < 40 for j in train)
    paired = [j for j in train if j.paired]
    assert len(paired) == 12 and all(
        [f["name"] for f in j.fabrics] == ["silk", "cotton", "denim", "leather"] for j in paired
    )
    assert {(j.family, j.construction) for j in paired} == {(j.family, j.construction) for j in train}
    assert any(j.fabrics[0]["name"] == "custom" for j in train)  # physical values between the presets
    assert all(cfg.min_vertices <= j.vertices <= cfg.max_vertices for j in jobs)

    def keys(split: str, what: str) -> set[str]:
        return {json.dumps(getattr(j, what), sort_keys=True) for j in by_split[split]}

    for what in ("garment_params", "phenotype", "pose_seed"):
        assert not keys("train", what) & keys("test", what), f"{what} shared between train and test"
        assert not keys("train", what) & keys("ood", what)
    assert len({j.job_id for j in jobs}) == len(jobs)


def test_ood_parameters_lie_outside_every_training_range(tmp_path):
    jobs = plan_jobs(GenerateConfig(out=tmp_path, num_train=0, num_test=0, num_ood=20))
    for job in jobs:
        assert job.construction == "template"
        ranges = PARAMS[job.family].RANGES
        outside = [
            not (ranges[k][2] <= v <= ranges[k][3])
            for k, v in job.garment_params.items()
            if ranges[k][:2] != ranges[k][2:]
        ]
        assert all(outside), (job.family, job.garment_params)
        PARAMS[job.family](**job.garment_params)  # still valid parameters


def test_growing_a_split_keeps_every_planned_job(tmp_path):
    base = {
        j.job_id: j.__dict__
        for j in plan_jobs(GenerateConfig(out=tmp_path, seed=1, num_train=50, num_test=8, num_ood=3))
    }
    grown = plan_jobs(GenerateConfig(out=tmp_path, seed=1, num_train=90, num_test=13, num_ood=5))
    by_id = {j.job_id: j.__dict__ for j in grown}
    assert all(by_id[k] == v for k, v in base.items())  # nothing renumbered or reseeded
    assert split_indices("test", 8) == [40, 41, 42, 43, 44, 45, 88, 89]
    assert split_indices("train", 42)[39:] == [39, 48, 49] and split_indices("ood", 3) == [46, 47, 94]


def test_bad_config():
    with pytest.raises(ValueError, match="shard"):
        GenerateConfig(out="x", shard=(2, 2))
    with pytest.raises(ValueError, match="low_ratio"):
        GenerateConfig(out="x", low_ratio=2.0)
    with pytest.raises(ValueError, match="min_vertices"):
        GenerateConfig(out="x", min_vertices=3000, max_vertices=300)


def _fake_job(job, config):
    """Stand-in for the Newton run (tests the orchestration: resume, rejections, transient errors)."""
    from store_fixtures import make_record

    from garsim.physics.newton_sim import SimulationRejected

    if job.index == 2:
        raise SimulationRejected("overstretched", "edge 3 at frame 5 stretched 2.00x rest")
    if job.index == 3 and not os.environ.get("GARSIM_TEST_HEALED"):
        raise OSError("disk full")  # transient: retried, never a rejection
    if job.index == 5:
        raise KeyboardInterrupt  # the run is killed here
    recs = []
    for f in job.fabrics:
        rec = make_record(job.copy_id(f["name"]), job.split, seed=job.index)
        rec.garment_type = job.family
        rec.meta.update(canonical_pose="tpose", fabric_name=f["name"], cpu_seconds=1.0, seconds=1.0, settled=[True] * 3)
        recs.append(rec)
    return recs, []


def test_resume_after_interrupted_run_rejections_and_transient_errors(tmp_path, monkeypatch):
    monkeypatch.setattr(gen, "simulate_job", _fake_job)
    monkeypatch.delenv("GARSIM_TEST_HEALED", raising=False)
    cfg = GenerateConfig(out=tmp_path, num_train=7, num_test=0, num_ood=0, workers=1)
    with pytest.raises(KeyboardInterrupt):
        gen.generate(cfg, progress=False)
    store = DatasetStore(tmp_path)
    # job 3 is paired (every 4th): four fabric copies stored as four sequences of one job
    assert {e["job"] for e in store.entries()} == {"train-00000", "train-00001", "train-00004"}
    assert store.entries("rejected.jsonl")[0]["reason"] == "overstretched"
    assert [e["job"] for e in store.entries("errors.jsonl")] == ["train-00003"]

    monkeypatch.setenv("GARSIM_TEST_HEALED", "1")
    monkeypatch.setattr(
        gen,
        "simulate_job",
        lambda job, config: (
            _fake_job(job, config)
            if job.index != 5
            else _fake_job(job.__class__(**{**job.__dict__, "index": 6}), config)
        ),
    )
    summary = gen.generate(cfg, progress=False)
    assert summary["pending"] == 3 and summary["errors"] == 0  # 3, 5 and 6 ran again; 2 stays rejected
    assert {e["job"] for e in store.entries()} == {f"train-0000{i}" for i in (0, 1, 3, 4, 5, 6)}
    assert len([e for e in store.entries() if e["job"] == "train-00003"]) == 4
    assert store.verify() == []
    info = store.info()
    assert info["paired_complete_groups"] == 1 and info["garment_instances"] == 6
    assert info["per_family"]["skirt"]["jobs"] >= 1


def test_a_rerun_with_other_settings_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(gen, "_run_one", lambda args: {"entries": [], "rejections": []})
    gen.generate(GenerateConfig(out=tmp_path, num_train=2, num_test=0, num_ood=0, workers=1), progress=False)
    # counts may grow, settings may not
    gen.generate(GenerateConfig(out=tmp_path, num_train=4, num_test=1, num_ood=0, workers=1), progress=False)
    with pytest.raises(ValueError, match="seed=0.*seed=1"):
        gen.generate(GenerateConfig(out=tmp_path, seed=1, num_train=2, workers=1), progress=False)
    with pytest.raises(ValueError, match="max_vertices"):
        gen.generate(GenerateConfig(out=tmp_path, max_vertices=900, num_train=2, workers=1), progress=False)
    stored = json.loads((tmp_path / gen.CONFIG_FILE).read_text())
    del stored["plan_version"]  # a folder planned before paired groups rotated over the families
    (tmp_path / gen.CONFIG_FILE).write_text(json.dumps(stored))
    with pytest.raises(ValueError, match="plan_version=None, this run has plan_version=2"):
        gen.generate(GenerateConfig(out=tmp_path, num_train=4, num_test=1, num_ood=0, workers=1), progress=False)


def test_a_second_run_of_the_same_shard_into_one_folder_is_refused(tmp_path, monkeypatch):
    """While one run holds a shard of the folder, a second run of that shard is refused with a message naming it and
    the holder's pid (nothing is written); another shard may run beside it; once the holder ends, a run proceeds."""
    import fcntl

    ran = []
    monkeypatch.setattr(gen, "_run_one", lambda args: ran.append(args[0].job_id) or {"entries": [], "rejections": []})
    cfg = GenerateConfig(out=tmp_path, num_train=4, num_test=0, num_ood=0, workers=1)
    with open(tmp_path / ".generate-0-of-1.lock", "w", encoding="utf-8") as holder:
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        holder.write("4242")
        holder.flush()
        with pytest.raises(RuntimeError, match=r"shard 0/1\) is being generated by another process \(pid 4242\)"):
            gen.generate(cfg, progress=False)
        assert ran == [] and not (tmp_path / gen.CONFIG_FILE).exists()
        gen.generate(replace(cfg, shard=(1, 2)), progress=False)  # another shard: its own lock
        assert len(ran) == 2
    assert gen.generate(cfg, progress=False)["pending"] == 4  # the holder is gone
    assert (tmp_path / ".generate-0-of-1.lock").read_text(encoding="utf-8") == str(os.getpid())


_HOLDER_SCRIPT = """
import sys, time
from pathlib import Path
from garsim.physics import generate as gen
def slow(args):
    print("running", flush=True)
    time.sleep(60)
gen._run_one = slow
gen.generate(gen.GenerateConfig(out=Path(sys.argv[1]), num_train=2, num_test=0, num_ood=0, workers=1), progress=False)
"""


def test_a_killed_run_frees_its_folder_at_once(tmp_path, monkeypatch):
    """SIGKILL of a run that holds the folder leaves no stale lock: the next run starts at once."""
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER_SCRIPT, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "running"
    cfg = GenerateConfig(out=tmp_path, num_train=2, num_test=0, num_ood=0, workers=1)
    with pytest.raises(RuntimeError, match=f"pid {proc.pid}"):
        gen.generate(cfg, progress=False)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    monkeypatch.setattr(gen, "_run_one", lambda args: {"entries": [], "rejections": []})
    assert gen.generate(cfg, progress=False)["pending"] == 2


def test_strap_pins_bind_the_folder_only_when_not_the_legacy_band(tmp_path, monkeypatch):
    """``strap_pins="band"`` is left out of ``settings()`` (folders made before it match); "crest" is a setting, so
    a band folder refuses a crest rerun; an unknown value is refused."""
    monkeypatch.setattr(gen, "_run_one", lambda args: {"entries": [], "rejections": []})
    band = GenerateConfig(out=tmp_path, num_train=2, num_test=0, num_ood=0, workers=1)
    assert "strap_pins" not in band.settings() and replace(band, strap_pins="crest").settings()["strap_pins"] == "crest"
    gen.generate(band, progress=False)
    with pytest.raises(ValueError, match="strap_pins"):
        gen.generate(replace(band, strap_pins="crest"), progress=False)
    with pytest.raises(ValueError, match="strap_pins must be one of"):
        GenerateConfig(out=tmp_path, strap_pins="straps")


@pytest.mark.parametrize("strap_pins", ["band", "crest"])
def test_strapped_templates_are_pinned_at_the_bodice_or_at_the_straps_crest(strap_pins, tmp_path):
    """A parametric top: "band" pins its bodice's top ring (below the shoulders), "crest" only the straps within
    ``SHOULDER_PIN_BAND`` of its top; implicit tops and the other families keep their pins either way."""
    from garsim.bodies.anny import AnnyBody

    cfg = GenerateConfig(out=tmp_path, num_train=24, num_test=0, num_ood=0, strap_pins=strap_pins)
    jobs = plan_jobs(cfg)
    top = next(j for j in jobs if j.family == "top" and j.construction == "template")
    skirt = next(j for j in jobs if j.family == "skirt" and j.construction == "template")
    body = AnnyBody(top.phenotype)
    g = gen.build_garment(top, body, strap_pins)
    z, zp = g.vertices[:, 2], g.vertices[g.pinned, 2]
    assert g.pinned.sum() > 4
    if strap_pins == "crest":
        assert zp.min() >= z.max() - gen.SHOULDER_PIN_BAND - 1e-6 and np.isclose(zp.max(), z.max())
    else:
        assert zp.max() < z.max() - gen.SHOULDER_PIN_BAND  # the bodice's ring, below the straps
    skirt_body = AnnyBody(skirt.phenotype)
    np.testing.assert_array_equal(
        gen.build_garment(skirt, skirt_body, strap_pins).pinned, gen.build_garment(skirt, skirt_body).pinned
    )


def test_shards_partition_the_jobs(tmp_path, monkeypatch):
    ran = []
    monkeypatch.setattr(gen, "_run_one", lambda args: ran.append(args[0].index) or {"entries": [], "rejections": []})
    for k in range(3):
        gen.generate(
            GenerateConfig(out=tmp_path / str(k), num_train=7, num_test=2, num_ood=1, workers=1, shard=(k, 3)),
            progress=False,
        )
    assert sorted(ran) == list(range(7)) + [40, 41, 46]


def test_splits_are_interleaved(tmp_path, monkeypatch):
    ran = []
    monkeypatch.setattr(gen, "_run_one", lambda args: ran.append(args[0].split) or {"entries": [], "rejections": []})
    gen.generate(GenerateConfig(out=tmp_path, num_train=8, num_test=4, num_ood=2, workers=1), progress=False)
    assert ran[:3] == ["train", "test", "ood"] and ran.count("test") == 4


def test_paired_first_runs_the_paired_groups_first_and_binds_no_setting(tmp_path, monkeypatch):
    ran = []
    monkeypatch.setattr(gen, "_run_one", lambda args: ran.append(args[0]) or {"entries": [], "rejections": []})
    cfg = GenerateConfig(out=tmp_path, num_train=24, num_test=0, num_ood=0, workers=1, paired_first=True)
    gen.generate(cfg, progress=False)
    paired = [j.paired for j in ran]
    assert len(ran) == 24 and 0 < sum(paired) < 24
    assert paired == sorted(paired, reverse=True)  # every paired job before every other one
    assert {j.job_id for j in ran} == {j.job_id for j in gen.plan_jobs(cfg)}  # the same jobs
    assert cfg.settings() == GenerateConfig(out=tmp_path, num_train=24).settings()  # a resumable order, not a setting


_ORPHAN_SCRIPT = """
import sys, time
from garsim.physics.generate import _worker_pool
with _worker_pool(2) as pool:
    results = [pool.apply_async(time.sleep, (60,)) for _ in range(2)]
    time.sleep(0.5)
    for p in pool._pool:
        print(p.pid, flush=True)
    time.sleep(60)
"""


def test_killing_the_parent_leaves_no_worker(tmp_path):
    """SIGKILL of the generating process takes its simulation workers with it (no orphan keeps simulating)."""
    proc = subprocess.Popen([sys.executable, "-c", _ORPHAN_SCRIPT], stdout=subprocess.PIPE, text=True)
    pids = [int(proc.stdout.readline()) for _ in range(2)]
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 10
    alive = pids
    while alive and time.time() < deadline:
        alive = [
            p for p in alive if os.path.exists(f"/proc/{p}") and "Z" not in open(f"/proc/{p}/stat").read().split()[2]
        ]
        time.sleep(0.1)
    assert not alive, f"workers {alive} outlived their parent"


_FINISH_SCRIPT = """
from garsim.physics.generate import _worker_pool
with _worker_pool(2) as pool:
    print(sum(pool.imap_unordered(abs, range(-45, 0))), flush=True)  # 45 tasks: workers recycled every 10
print("exited", flush=True)
"""


def test_a_finished_pool_exits_and_reaps_its_workers():
    """A run whose jobs are all done leaves the pool (closed and joined, its recycled workers reaped) and returns:
    Pool.__exit__'s terminate() once left a finished generator asleep for good on the task queue's lock."""
    out = subprocess.run([sys.executable, "-c", _FINISH_SCRIPT], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.split() == [str(sum(range(1, 46))), "exited"], out.stderr[-2000:]


def test_armhole_poses_keep_the_arms_near_their_canonical_position(tmp_path, monkeypatch):
    """Shoulder elevation is the sampler's angle (0 = T-pose), the canonical arm is degrees above the A-pose:
    the everyday range of a garment with armholes is centred on its canonical arms, in the sampler's angle."""
    import garsim.bodies.poses as poses

    assert gen.armhole_elevation_range(gen.T_POSE_ARM) == (-50.0, 25.0)
    assert gen.armhole_elevation_range(0.0) == (-75.0, -15.0)  # A-pose: -40; -90 clipped to the everyday -75
    assert gen.armhole_elevation_range(20.0) == (-70.0, 5.0)
    seen = []

    class Sampler:
        def __init__(self, limits, seed, body):
            seen.append(limits)

        def sample(self, n):
            return [{}] * n

    monkeypatch.setattr(poses, "PoseSampler", Sampler)
    jobs = plan_jobs(GenerateConfig(out=tmp_path, num_train=12, num_test=0, num_ood=0))
    for job in jobs:
        seen.clear()
        gen.target_poses(job, body=None)
        for limits in seen:
            if job.family in gen.ARMHOLE_FAMILIES:
                assert limits.shoulder_elevation == gen.armhole_elevation_range(job.canonical_arm)
            else:
                assert (
                    limits.shoulder_elevation == poses.EVERYDAY_LIMITS.shoulder_elevation
                    or limits == poses.JointLimits()
                )


@pytest.mark.slow
def test_a_tshirt_over_heavy_hips_settles_without_stretching():
    """A t-shirt whose hem reaches the thighs of a heavy, muscular body (job train-00002 of seed 1) used to
    follow the body's waist-hip-thigh profile and stretched 1.52x over the thighs as it slid under its own
    weight; below the waist its tube now keeps the widest radius above, as skirts do."""
    from garsim.bodies.anny import AnnyBody
    from garsim.garments.templates import make_garment
    from garsim.geometry.mesh import edge_lengths
    from garsim.physics.newton_sim import check_result, settle

    phenotype = {"gender": 0.206, "age": 0.6641, "muscle": 0.9879, "weight": 0.8875, "height": 0.3327}
    body = AnnyBody({**phenotype, "proportions": 0.1849})
    params = {"length": 0.4231, "looseness": 0.0275, "sleeve_length": 0.1504, "sleeve_looseness": 0.0269}
    params |= {"neck_width": 0.1047, "armpit_clearance": 0.041}
    g = make_garment("tshirt", body, params, target_vertices=332)
    g.pinned &= g.vertices[:, 2] >= g.vertices[g.pinned, 2].max() - gen.SHOULDER_PIN_BAND
    canonical = body.canonical()
    state, info = settle(g, canonical.vertices, body.faces, "cotton")
    assert info["settled"]
    check_result(state, g.faces, edge_lengths(g.vertices, g.faces), canonical.vertices, body.faces, pinned=g.pinned)


@pytest.mark.slow
def test_real_jobs_tshirt_and_trousers_pass_the_physics_checks(tmp_path):
    """A coarse t-shirt and a pair of trousers in everyday poses settle and pass every check (one target each)."""
    cfg = GenerateConfig(
        out=tmp_path,
        num_train=6,
        targets_per_job=1,
        min_vertices=300,
        max_vertices=400,
        paired_every=1000,
        physical_share=0.0,
        workers=1,
    )
    jobs = {j.family: j for j in plan_jobs(cfg) if j.construction == "template"}
    for family in ("tshirt", "trousers"):
        job = jobs[family]
        job.pose_modes = ["everyday"]
        records, rejections = gen.simulate_job(job, cfg)
        assert rejections == [] and len(records) == 1, rejections
        rec = records[0]
        assert rec.meta["settled"] == [True] and max(rec.meta["final_speed"]) < 0.02
        for res in ("full", "low"):
            lv = rec.levels[res]
            assert np.isfinite(lv.targets).all() and lv.targets.shape == (1, len(lv.template), 3)


def test_a_garment_the_validator_refuses_is_a_named_rejection(tmp_path, monkeypatch):
    """A construction that yields zero-area faces is rejected for good (not retried as a transient error)."""
    from garsim.garments.garment import Garment
    from garsim.physics.newton_sim import SimulationRejected

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], dtype=np.float32)
    f = np.array([[0, 1, 2], [0, 1, 3]])  # the second face is collinear: zero area
    monkeypatch.setattr(gen, "build_garment", lambda job, body, _pins: Garment(v, f, np.zeros(4, bool), job.family, {}))
    cfg = GenerateConfig(out=tmp_path, num_train=1, num_test=0, num_ood=0, workers=1)
    with pytest.raises(SimulationRejected) as err:
        gen.simulate_job(plan_jobs(cfg)[0], cfg)
    assert err.value.reason == gen.REJECT_INVALID_GARMENT and "zero area" in err.value.detail


def test_settings_added_later_keep_older_folders_and_workers_refuse_changed_defaults(tmp_path, monkeypatch):
    """Optional sim settings at their legacy value are left out of ``settings()`` (folders bound before they
    existed still match); a worker whose effective settings differ from the folder's (code defaults changed
    under a running pool) refuses with a retried error instead of mixing settings."""
    legacy = dict(gen.OPTIONAL_SIM_SETTINGS)
    cfg = GenerateConfig(out=tmp_path, num_train=1, num_test=0, num_ood=0, workers=1, sim=legacy)
    assert not set(legacy) & set(cfg.settings()["sim"])
    gen.check_settings(cfg)  # binds the folder
    gen.check_settings(cfg)  # and matches again
    for key in gen.EXECUTION_SIM_SETTINGS:  # how a simulation is run is not a setting of the folder
        gen.check_settings(replace(cfg, sim={**legacy, key: False}))
    execution = set(gen.EXECUTION_SIM_SETTINGS)
    assert execution <= set(asdict(SimConfig())) and not execution & set(cfg.settings()["sim"])
    with pytest.raises(ValueError, match="sim"):
        gen.check_settings(GenerateConfig(out=tmp_path, num_train=1, sim={**legacy, "collide_every": 3}))
    monkeypatch.setattr(gen, "simulate_job", lambda job, config: pytest.fail("must not simulate"))
    other = GenerateConfig(out=tmp_path, num_train=1, num_test=0, num_ood=0, sim={**legacy, "collide_every": 3})
    out = gen._run_one((plan_jobs(cfg)[0], other))
    assert "settings differ" in out["error"]["error"]


def test_reuse_copies_the_jobs_other_strap_pins_leave_unchanged(tmp_path, monkeypatch):
    """A crest folder reusing a band folder copies every finished job but the parametric tops and dresses (which it
    simulates), files checked against their sha256, rejections kept; other differing settings copy nothing."""
    monkeypatch.setattr(gen, "simulate_job", _fake_job)
    monkeypatch.setenv("GARSIM_TEST_HEALED", "1")
    src = tmp_path / "band"
    band = GenerateConfig(out=src, num_train=24, num_test=0, num_ood=0, workers=1)
    monkeypatch.setattr(gen, "plan_jobs", lambda c: [j for j in plan_jobs(c) if j.index != 5])  # no interrupt
    gen.generate(band, progress=False)
    source = DatasetStore(src)
    ran = []
    monkeypatch.setattr(gen, "simulate_job", lambda job, config: ran.append(job) or _fake_job(job, config))
    crest = replace(band, out=tmp_path / "crest", strap_pins="crest", reuse=src)
    summary = gen.generate(crest, progress=False)
    held = {j.job_id for j in plan_jobs(crest) if gen.crest_pinned(j, "crest")}
    assert len(held) == 4 and {j.job_id for j in ran} == held - {"train-00005"}  # job 5 is left out of the plan
    copied = [e for e in source.entries() if e["job"] not in held]
    assert summary["reused"] == {"sequences": len(copied), "rejections": 1}  # job 2's rejection
    out = DatasetStore(tmp_path / "crest")
    assert out.verify() == [] and {e["id"] for e in out.entries()} >= {e["id"] for e in copied}
    assert [e for e in out.entries() if e["job"] not in held] == copied  # the same lines, files and hashes
    assert out.entries("rejected.jsonl") == source.entries("rejected.jsonl")
    # a second run copies nothing more; another vertex range would simulate (and plan) differently: nothing reused
    assert gen.generate(crest, progress=False)["reused"] == {"sequences": 0, "rejections": 0}
    other = replace(band, out=tmp_path / "other", max_vertices=900, reuse=src, limit=0)
    assert gen.generate(other, progress=False)["reused"] == {"sequences": 0, "rejections": 0}
    (src / out.entries()[0]["file"]).write_bytes(b"torn")
    with pytest.raises(gen.StoreError, match="sha256"):
        gen.generate(replace(crest, out=tmp_path / "again"), progress=False)
    (src / out.entries()[0]["file"]).unlink()
    with pytest.raises(gen.StoreError, match="No such file"):
        gen.generate(replace(crest, out=tmp_path / "again"), progress=False)
    with pytest.raises(ValueError, match="is the --out folder itself"):
        gen.generate(replace(crest, reuse=tmp_path / "crest"), progress=False)
