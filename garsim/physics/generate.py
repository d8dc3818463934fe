"""Resumable, parallel dataset generation: sample garments, fabrics, bodies and poses from a
seed, simulate them with Newton, reject bad results, store full + low resolution samples.

Every sequence is a job planned from ``(seed, index)`` alone, so a run can be split across
machines (``shard``), interrupted and resumed (finished and rejected ids are skipped), and
regenerated bit-for-bit from its seed.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import os
import time
import traceback
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from garsim.data.sample import FABRICS
from garsim.data.store import REJECTED, DatasetStore, GarmentLevel, SequenceRecord

log = logging.getLogger(__name__)

TRAIN_TYPES: tuple[str, ...] = ("skirt", "top")
GENERALIZATION_TYPES: tuple[str, ...] = ("tshirt", "trousers", "dress")
PHENOTYPE_RANGES: dict[str, tuple[float, float]] = {
    "gender": (0.0, 1.0),
    "age": (0.35, 0.9),
    "muscle": (0.2, 0.8),
    "weight": (0.2, 0.8),
    "height": (0.2, 0.8),
    "proportions": (0.3, 0.7),
}


@dataclass
class GenerateConfig:
    """What to generate; the seed and these numbers fully determine the dataset."""

    out: Path
    seed: int = 0
    num_train: int = 300  # sequences (skirts and tops)
    num_test: int = 50  # sequences (skirts and tops; unseen instances, shapes, poses)
    num_generalization: int = 20  # sequences of garment types never used in training
    target_vertices: int = 1600  # full-resolution garment size
    low_ratio: float = 0.25  # low resolution = this fraction of the full vertex count
    motion_frames: int = 24  # canonical -> target over this many frames (0.8 s at 30 fps)
    store_every: int = 2  # store every k-th motion frame (from frame k on) and the final settled frame
    workers: int = 2
    shard: tuple[int, int] = (0, 1)  # (k, n): run jobs with index % n == k
    limit: int | None = None  # run at most this many pending jobs (for smoke runs)
    sim: dict[str, Any] = field(default_factory=dict)  # SimConfig overrides

    def __post_init__(self) -> None:
        self.out = Path(self.out)
        k, n = self.shard
        if not (n >= 1 and 0 <= k < n):
            raise ValueError(f"shard must be K/N with 0 <= K < N, got {k}/{n}")
        if min(self.num_train, self.num_test, self.num_generalization) < 0:
            raise ValueError("sequence counts must be >= 0")
        if self.motion_frames < 2 or self.store_every < 1:
            raise ValueError("motion_frames >= 2 and store_every >= 1 required")
        if not (0.05 <= self.low_ratio <= 1.0):
            raise ValueError(f"low_ratio must be in [0.05, 1], got {self.low_ratio}")
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")


@dataclass
class JobSpec:
    """One sequence to simulate."""

    seq_id: str
    index: int
    split: str
    garment_type: str
    garment_params: dict[str, Any]
    fabric: str
    phenotype: dict[str, float]
    pose_seed: int


# Job indices are laid out in a fixed repeating block of (split, slots): block b holds train indices
# 370b..370b+299, test 370b+300..370b+349, generalization 370b+350..370b+369. A split of N sequences
# takes its first N slots across blocks, so growing one split appends jobs and never renumbers (or
# reseeds) a sequence of any split: an existing dataset stays valid when it is grown.
INDEX_BLOCK: tuple[tuple[str, int], ...] = (("train", 300), ("test", 50), ("generalization", 20))
SPLIT_TYPES: dict[str, tuple[str, ...]] = {
    "train": TRAIN_TYPES, "test": TRAIN_TYPES, "generalization": GENERALIZATION_TYPES,
}


def split_indices(split: str, count: int) -> list[int]:
    """Global job indices of the first ``count`` sequences of ``split`` in the repeating block layout."""
    block = sum(n for _, n in INDEX_BLOCK)
    offset = 0
    for name, slots in INDEX_BLOCK:
        if name == split:
            return [(j // slots) * block + offset + j % slots for j in range(count)]
        offset += slots
    raise ValueError(f"unknown split {split!r}; expected one of {[n for n, _ in INDEX_BLOCK]}")


def plan_jobs(config: GenerateConfig) -> list[JobSpec]:
    """All jobs of the dataset, deterministic in the seed (independent of shard and workers)."""
    from garsim.garments.templates import sample_garment_params

    counts = {"train": config.num_train, "test": config.num_test, "generalization": config.num_generalization}
    jobs = []
    for split, count in counts.items():
        types = SPLIT_TYPES[split]
        for i in split_indices(split, count):
            rng = np.random.default_rng([config.seed, i])
            kind = types[i % len(types)]
            fabric = FABRICS[(i // len(types)) % len(FABRICS)]
            phenotype = {k: round(float(rng.uniform(lo, hi)), 4) for k, (lo, hi) in PHENOTYPE_RANGES.items()}
            params = sample_garment_params(kind, rng)
            jobs.append(
                JobSpec(
                    seq_id=f"{split}-{i:05d}",
                    index=i,
                    split=split,
                    garment_type=kind,
                    garment_params=params,
                    fabric=fabric,
                    phenotype=phenotype,
                    pose_seed=int(rng.integers(2**31)),
                )
            )
    return jobs


def stored_frame_indices(num_frames: int, motion_frames: int, store_every: int) -> np.ndarray:
    """Motion frames store_every, 2*store_every, ... below motion_frames, and the last (settled) frame."""
    idx = list(range(store_every, motion_frames, store_every))
    idx.append(num_frames - 1)
    return np.unique(np.asarray(idx, dtype=np.int64))


def simulate_job(job: JobSpec, config: GenerateConfig) -> SequenceRecord:
    """Simulate one sequence; raises ``SimulationRejected`` for results that must not be stored."""
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.poses import PoseSampler, pose_sequence
    from garsim.garments.garment import Garment
    from garsim.garments.remesh import decimate, transfer_barycentric
    from garsim.garments.templates import make_garment
    from garsim.geometry.skinning import dense_weights, lbs_prior, transfer_weights
    from garsim.physics.newton_sim import (
        SimConfig,
        SimulationRejected,
        check_result,
        rest_edge_lengths,
        settle,
        simulate_motion,
    )

    t0 = time.perf_counter()
    sim_cfg = SimConfig(**config.sim)
    body = AnnyBody(job.phenotype)
    canonical = body.canonical()
    garment = make_garment(job.garment_type, body, job.garment_params, target_vertices=config.target_vertices)
    rest = rest_edge_lengths(garment.vertices, garment.faces)
    template, settle_info = settle(garment, canonical.vertices, body.faces, job.fabric, sim_cfg)
    ok, reason = check_result(template, garment.faces, rest, canonical.vertices, body.faces, pinned=garment.pinned)
    if not ok:
        raise SimulationRejected(reason.split(":")[0], "settle: " + reason)

    target_pose = PoseSampler(seed=job.pose_seed).sample(1)[0]
    body_frames, transforms = pose_sequence(body, target_pose, config.motion_frames)
    body_w = dense_weights(body.skin_indices, body.skin_weights, len(body.bone_labels))
    weights = transfer_weights(template, canonical.vertices, body_w, k=4)
    pins = np.flatnonzero(garment.pinned)
    pin_targets = np.stack([lbs_prior(template[pins], weights[pins], canonical.transforms, t) for t in transforms])
    frames, motion_info = simulate_motion(
        template, garment.faces, garment.pinned, body_frames, body.faces, pin_targets, job.fabric, sim_cfg
    )
    if motion_info["aborted"]:  # stopped early (exploding): fewer frames than planned, nothing to store
        raise SimulationRejected(motion_info["aborted"], f"{motion_info['aborted']}: simulation stopped at frame "
                                 f"{len(frames) - 1} (an edge beyond {sim_cfg.abort_stretch}x rest, or non-finite)")
    keep = stored_frame_indices(len(frames), config.motion_frames, config.store_every)
    body_idx = np.minimum(keep, config.motion_frames - 1)  # hold frames keep the target pose
    ok, reason = check_result(frames[keep], garment.faces, rest, body_frames[body_idx], body.faces,
                              pinned=garment.pinned)
    if not ok:
        raise SimulationRejected(reason.split(":")[0], reason)
    if not motion_info["settled"]:
        log.info("%s: final frame not fully settled (mean speed %.3f m/s)", job.seq_id, motion_info["final_speed"])

    targets = frames[keep]
    priors = np.stack([lbs_prior(template, weights, canonical.transforms, transforms[b]) for b in body_idx])
    full = GarmentLevel(template, garment.faces, garment.pinned, priors, targets)

    low_garment, mapping = decimate(
        Garment(template, garment.faces, garment.pinned, garment.kind, garment.params), ratio=config.low_ratio
    )
    w_low = transfer_weights(low_garment.vertices, canonical.vertices, body_w, k=4)
    low = GarmentLevel(
        template=low_garment.vertices,
        faces=low_garment.faces,
        pinned=low_garment.pinned,
        priors=np.stack(
            [lbs_prior(low_garment.vertices, w_low, canonical.transforms, transforms[b]) for b in body_idx]
        ),
        targets=np.stack([transfer_barycentric(t, mapping) for t in targets]).astype(np.float32),
    )
    meta = {
        "index": job.index,
        "seed": config.seed,
        "garment_params": job.garment_params,
        "phenotype": job.phenotype,
        "target_pose": {k: np.asarray(v, dtype=float).round(6).tolist() for k, v in target_pose.items()},
        "settle": {k: settle_info[k] for k in ("frames", "final_speed", "settled", "seconds")},
        "motion": {k: motion_info[k] for k in ("motion_frames", "hold_frames", "final_speed", "settled", "seconds")},
        "seconds": time.perf_counter() - t0,
    }
    return SequenceRecord(
        seq_id=job.seq_id,
        split=job.split,
        garment_type=job.garment_type,
        fabric=job.fabric,
        body_canonical=canonical.vertices,
        body_targets=body_frames[body_idx],
        body_faces=body.faces,
        frames=keep,
        levels={"full": full, "low": low},
        meta=meta,
    )


def _run_one(args: tuple[JobSpec, GenerateConfig]) -> dict[str, Any]:
    """Worker: simulate and write one sequence; returns a manifest or rejection entry."""
    from garsim.physics.newton_sim import SimulationRejected

    job, config = args
    t0 = time.perf_counter()
    try:
        rec = simulate_job(job, config)
        entry = DatasetStore(config.out).write_sequence(rec)
        entry["seconds"] = round(time.perf_counter() - t0, 2)
        return {"ok": True, "entry": entry}
    except SimulationRejected as exc:
        reason, detail = exc.reason, exc.detail
    except Exception as exc:  # a crash in one job must not kill the run; it is logged as rejected
        reason, detail = "error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"
    return {"ok": False, "entry": {"id": job.seq_id, "reason": reason, "detail": detail,
                                   "seconds": round(time.perf_counter() - t0, 2)}}


def generate(config: GenerateConfig, progress: bool = True) -> dict[str, Any]:
    """Run (or resume) generation; returns counts, rejection reasons and timings of this run."""
    from tqdm import tqdm

    store = DatasetStore(config.out)
    config.out.mkdir(parents=True, exist_ok=True)
    jobs = plan_jobs(config)
    k, n = config.shard
    done = store.done_ids()
    pending = [j for j in jobs if j.index % n == k and j.seq_id not in done]
    # interleave the splits so that a partial run (or a stopped one) holds every split in proportion
    rank = {j.seq_id: r for split in SPLIT_TYPES for r, j in enumerate(x for x in jobs if x.split == split)}
    size = Counter(j.split for j in jobs)
    pending.sort(key=lambda j: (rank[j.seq_id] / size[j.split], j.index))
    if config.limit is not None:
        pending = pending[: config.limit]
    summary: dict[str, Any] = {"planned": len(jobs), "pending": len(pending), "stored": 0, "rejected": {},
                               "seconds": []}
    if not pending:
        return summary
    ctx = mp.get_context("spawn")
    work = [(j, config) for j in pending]
    t0 = time.perf_counter()
    pool_cm = (
        _single_threaded_pool(ctx, config.workers) if config.workers > 1 else _InlinePool()
    )
    with pool_cm as pool:
        bar = tqdm(pool.imap_unordered(_run_one, work), total=len(work), disable=not progress, unit="seq")
        for result in bar:
            entry = result["entry"]
            summary["seconds"].append(entry["seconds"])
            if result["ok"]:
                store.append_manifest(entry)
                summary["stored"] += 1
            else:
                store.append_manifest(entry, REJECTED)
                summary["rejected"][entry["reason"]] = summary["rejected"].get(entry["reason"], 0) + 1
                log.warning("rejected %s: %s", entry["id"], entry["detail"].splitlines()[0])
            bar.set_postfix(stored=summary["stored"], rejected=sum(summary["rejected"].values()))
    summary["wall_seconds"] = time.perf_counter() - t0
    return summary


_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _one_thread() -> None:
    """Worker initializer: one torch/BLAS thread per worker (workers share the cores)."""
    import torch

    torch.set_num_threads(1)


@contextlib.contextmanager
def _single_threaded_pool(ctx: Any, workers: int) -> Iterator[Any]:
    """A process pool whose workers each use one thread (N workers x N threads thrash N cores).

    The thread variables stay set while the pool lives, so workers it respawns inherit them too.
    """
    saved = {k: os.environ.get(k) for k in _THREAD_VARS}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    try:
        with ctx.Pool(workers, initializer=_one_thread, maxtasksperchild=20) as pool:
            yield pool
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _InlinePool:
    """A one-process stand-in for ``multiprocessing.Pool`` (workers=1: easier debugging)."""

    def __enter__(self) -> "_InlinePool":
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    @staticmethod
    def imap_unordered(fn, items):  # type: ignore[no-untyped-def]
        return map(fn, items)


def config_dict(config: GenerateConfig) -> dict[str, Any]:
    d = asdict(config)
    d["out"] = str(config.out)
    return d
