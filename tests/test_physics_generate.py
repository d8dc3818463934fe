import json

import numpy as np
import pytest

from garsim.data.store import DatasetStore
from garsim.physics import generate as gen
from garsim.physics.generate import GenerateConfig, plan_jobs, stored_frame_indices


def test_plan_is_deterministic_and_split_without_leakage(tmp_path):
    cfg = GenerateConfig(out=tmp_path, seed=3, num_train=40, num_test=12, num_generalization=9)
    jobs = plan_jobs(cfg)
    assert [j.__dict__ for j in jobs] == [j.__dict__ for j in plan_jobs(cfg)]
    assert plan_jobs(GenerateConfig(out=tmp_path, seed=4, num_train=40))[0].phenotype != jobs[0].phenotype
    by_split = {s: [j for j in jobs if j.split == s] for s in ("train", "test", "generalization")}
    assert [len(v) for v in by_split.values()] == [40, 12, 9]
    assert {j.garment_type for j in by_split["train"]} == {"skirt", "top"}
    assert {j.garment_type for j in by_split["generalization"]} == {"tshirt", "trousers", "dress"}
    assert {j.fabric for j in by_split["train"]} == {"silk", "cotton", "denim", "leather"}

    def keys(split: str, what: str) -> set[str]:
        return {json.dumps(getattr(j, what), sort_keys=True) for j in by_split[split]}

    for what in ("garment_params", "phenotype", "pose_seed"):
        assert not keys("train", what) & keys("test", what), f"{what} shared between train and test"
        assert not keys("train", what) & keys("generalization", what)
    assert len({j.seq_id for j in jobs}) == len(jobs)


def test_growing_a_split_keeps_every_planned_sequence(tmp_path):
    base = {j.seq_id: j.__dict__ for j in plan_jobs(GenerateConfig(out=tmp_path, seed=1))}
    grown = plan_jobs(GenerateConfig(out=tmp_path, seed=1, num_train=320, num_test=60, num_generalization=25))
    by_id = {j.seq_id: j.__dict__ for j in grown}
    assert all(by_id[k] == v for k, v in base.items())  # nothing renumbered or reseeded
    # the layout is a fixed repeating block: 300 train, 50 test, 20 generalization slots per 370 indices
    assert [j.index for j in grown if j.split == "test"][48:58] == [348, 349, 670, 671, 672, 673, 674, 675, 676, 677]
    assert [j.index for j in grown if j.split == "train"][299:302] == [299, 370, 371]
    assert [j.index for j in grown if j.split == "generalization"][19:21] == [369, 720]
    assert len(by_id) == 320 + 60 + 25


def test_stored_frames():
    assert stored_frame_indices(41, 30, 3).tolist() == [3, 6, 9, 12, 15, 18, 21, 24, 27, 40]
    assert stored_frame_indices(30, 30, 10).tolist() == [10, 20, 29]


def test_bad_config():
    with pytest.raises(ValueError, match="shard"):
        GenerateConfig(out="x", shard=(2, 2))
    with pytest.raises(ValueError, match="low_ratio"):
        GenerateConfig(out="x", low_ratio=2.0)


def _fake_job(job, config):
    """Stand-in for the Newton run (tests the orchestration: sharding, resume, rejection log)."""
    from test_data_store import make_record

    from garsim.physics.newton_sim import SimulationRejected

    if job.index == 2:
        raise SimulationRejected("overstretched", "edge 3 at frame 5 stretched 2.00x rest")
    if job.index == 4:
        raise KeyboardInterrupt  # the run is killed here
    rec = make_record(job.seq_id, job.split, seed=job.index)
    rec.garment_type, rec.fabric = job.garment_type, job.fabric
    return rec


def test_resume_after_interrupted_run_and_rejections(tmp_path, monkeypatch):
    monkeypatch.setattr(gen, "simulate_job", _fake_job)
    cfg = GenerateConfig(out=tmp_path, num_train=6, num_test=0, num_generalization=0, workers=1)
    with pytest.raises(KeyboardInterrupt):
        gen.generate(cfg, progress=False)
    store = DatasetStore(tmp_path)
    assert {e["id"] for e in store.entries()} == {"train-00000", "train-00001", "train-00003"}
    assert store.entries("rejected.jsonl")[0]["reason"] == "overstretched"

    monkeypatch.setattr(gen, "simulate_job", lambda job, config: _fake_job(job, config) if job.index != 4
                        else _fake_job(job.__class__(**{**job.__dict__, "index": 5}), config))
    summary = gen.generate(cfg, progress=False)
    assert summary["pending"] == 2 and summary["stored"] == 2  # only 4 and 5 ran again
    assert len(store.entries()) == 5 and store.verify() == []


def test_shards_partition_the_jobs(tmp_path, monkeypatch):
    ran = []
    monkeypatch.setattr(gen, "_run_one", lambda args: ran.append(args[0].index) or
                        {"ok": False, "entry": {"id": args[0].seq_id, "reason": "x", "detail": "x", "seconds": 0}})
    for k in range(3):
        gen.generate(GenerateConfig(out=tmp_path / str(k), num_train=7, num_test=2, num_generalization=1,
                                    workers=1, shard=(k, 3)), progress=False)
    assert sorted(ran) == list(range(7)) + [300, 301, 350]


def test_splits_are_interleaved(tmp_path, monkeypatch):
    ran = []
    monkeypatch.setattr(gen, "_run_one", lambda args: ran.append(args[0].split) or
                        {"ok": False, "entry": {"id": args[0].seq_id, "reason": "x", "detail": "x", "seconds": 0}})
    gen.generate(GenerateConfig(out=tmp_path, num_train=8, num_test=4, num_generalization=2, workers=1),
                 progress=False)
    assert ran[:3] == ["train", "test", "generalization"] and ran.count("test") == 4


@pytest.mark.slow
def test_real_generation_end_to_end(tmp_path):
    cfg = GenerateConfig(out=tmp_path, num_train=1, num_test=0, num_generalization=0, workers=1,
                         target_vertices=600, motion_frames=12, store_every=4)
    summary = gen.generate(cfg, progress=False)
    assert summary["stored"] == 1, summary
    rec = next(DatasetStore(tmp_path).sequences())
    for res in ("full", "low"):
        lv = rec.levels[res]
        assert np.isfinite(lv.targets).all() and lv.targets.shape[0] == len(rec.frames)
    assert len(rec.levels["low"].template) < 0.4 * len(rec.levels["full"].template)


def test_simulation_stopped_during_motion_is_rejected_not_crashed(tmp_path, monkeypatch):
    """A run the simulator stops early (fewer frames than planned) is a rejection with its reason."""
    from garsim.physics import newton_sim
    from garsim.physics.newton_sim import SimulationRejected

    monkeypatch.setattr(newton_sim, "settle", lambda garment, *a, **k: (
        garment.vertices, {"frames": 10, "final_speed": 0.0, "settled": True, "seconds": 0.0}))

    def exploding_motion(template, faces, pinned, body_frames, *a, **k):
        frames = np.repeat(template[None], 5, axis=0)  # stopped after 4 of 12 motion frames
        return frames, {"aborted": "overstretched", "settled": False, "final_speed": float("nan")}

    monkeypatch.setattr(newton_sim, "simulate_motion", exploding_motion)
    cfg = GenerateConfig(out=tmp_path, num_train=1, num_test=0, num_generalization=0, workers=1,
                         target_vertices=300, motion_frames=12, store_every=4)
    job = plan_jobs(cfg)[0]
    with pytest.raises(SimulationRejected, match="stopped at frame 4") as info:
        gen.simulate_job(job, cfg)
    assert info.value.reason == "overstretched"
