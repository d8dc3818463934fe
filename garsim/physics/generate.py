"""Resumable, parallel dataset generation (ground truth v2): settled drapes of six garment families
from two independent constructions, on Anny bodies in T-, A- and in-between canonical poses, moved
to everyday or wider target poses (one per job by default), in preset, paired and physically sampled fabrics.

One job = one garment instance (family, construction, parameters, resolution) on one body:
build it on the T-pose body, skin it to the job's canonical pose, settle it there (the template),
then move the body through ``targets_per_job`` target poses in turn and let the cloth settle at
each (the body holds still until the mean speed is below ``SimConfig.settle_speed``); every
settled state paired with the template is one sample. A paired-fabric job simulates the same
template in all four preset fabrics at once (one Newton model, four copies), so the fabric alone
explains the differences. Each fabric copy is stored as one sequence record (its K settled states).

Every job is planned from ``(seed, index)`` alone, so a run can be split across machines
(``shard``), stopped and resumed (jobs with a stored or rejected record are skipped), and
regenerated bit-for-bit from its seed. The dataset folder keeps the generation settings
(``config.json``); a rerun with other settings is refused, naming the setting that differs.
A simulation result the physics checks refuse is a permanent rejection; any other error (a
failed write, a killed worker) is logged and retried on the next run.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import logging
import math
import multiprocessing as mp
import os
import time
import traceback
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.data.store import MANIFEST, REJECTED, DatasetStore, GarmentLevel, SequenceRecord, StoreError

log = logging.getLogger(__name__)

CONFIG_FILE = "config.json"
REJECT_INVALID_GARMENT = "invalid_garment"
"""Rejection reason of a job whose garment construction yields a mesh the validator refuses (e.g. zero-area faces)."""
ERRORS = "errors.jsonl"
FAMILIES: tuple[str, ...] = ("skirt", "top", "tshirt", "longsleeve", "trousers", "dress")
TEMPLATE_FAMILIES: tuple[str, ...] = ("skirt", "top", "tshirt", "trousers", "dress")
"""Families the parametric templates build (long sleeves come from the implicit construction only)."""
ARMHOLE_FAMILIES: frozenset[str] = frozenset({"top", "tshirt", "longsleeve", "dress"})
"""Families with armholes or sleeves: arms more than ~50 deg below or ~25 deg above their canonical position
trap the cloth between arm and torso (edges stretched ~2x in every fabric alike), so their poses keep the
arms in that range (``ARM_BELOW_CANONICAL``, ``ARM_ABOVE_CANONICAL``)."""
ARM_BELOW_CANONICAL = 50.0
ARM_ABOVE_CANONICAL = 25.0
CONSTRUCTIONS: tuple[str, ...] = ("template", "implicit")
PAIRING_CYCLE = len(FAMILIES) * len(CONSTRUCTIONS)
"""Jobs in one pass over every family and construction (a job's family is j % 6, its construction (j // 6) % 2)."""
WAIST_FAMILIES: frozenset[str] = frozenset({"skirt", "trousers"})
STRAP_PINS: tuple[str, ...] = ("band", "crest")
"""``GenerateConfig.strap_pins`` choices (the first is the legacy default)."""
STRAPPED_FAMILIES: frozenset[str] = frozenset({"top", "dress"})
"""Families whose parametric templates hang on straps (``garments/templates/builders.py: _band_pins``)."""
TORSO_BONES: tuple[str, ...] = ("root", "spine", "clavicle", "neck", "head")
"""Anny bone-label prefixes that skin crest pins: not the arms, so a raised arm does not drag a strap's crest."""
SHOULDER_PIN_BAND = 0.04
"""m: garments hung from the shoulders keep only the pins this close below their highest pin (pins that run
down a strap towards the armpit follow the skinned arm and tore the cloth next to them: 1.8x edges)."""
PHENOTYPE_RANGES: dict[str, tuple[float, float]] = {
    "gender": (0.0, 1.0),
    "age": (0.3, 1.0),
    "muscle": (0.0, 1.0),
    "weight": (0.0, 1.0),
    "height": (0.0, 1.0),
    "proportions": (0.0, 1.0),
}
T_POSE_ARM = 40.0
"""Canonical arm raise (degrees above Anny's rest A-pose) of the T-pose; 0 is the A-pose."""
PAIRED_TEMPLATE_FABRIC = "cotton"
"""A paired group's template is settled once, in this fabric, then simulated in all four."""

# Job indices are laid out in a fixed repeating block of (split, slots): a split of N jobs takes its
# first N slots across blocks, so growing one split appends jobs and never renumbers (or reseeds) a job.
INDEX_BLOCK: tuple[tuple[str, int], ...] = (("train", 40), ("test", 6), ("ood", 2))
SPLITS: tuple[str, ...] = tuple(name for name, _ in INDEX_BLOCK)


@dataclass
class GenerateConfig:
    """What to generate; the seed and these settings fully determine the dataset."""

    out: Path
    seed: int = 0
    num_train: int = 600  # jobs (garment instances) per split; each yields up to targets x fabrics samples
    num_test: int = 90
    num_ood: int = 30
    # target poses per job, chained, each settled. One: a settled state after a chain depends on the poses before
    # it, which the model never sees (docs/studies/path_dependence.md: the 2nd target of a chain vs the same pose
    # reached from the canonical one differ by 11-41% of the prior's error); one target costs ~1.3x per sample
    targets_per_job: int = 1
    min_vertices: int = 300  # garment resolution, log-uniform in [min, max]
    max_vertices: int = 2500
    max_paired_vertices: int = 800  # paired groups simulate four copies: cap their resolution
    paired_every: int = 4  # every k-th job is a paired-fabric group (all four presets)
    physical_share: float = 0.5  # share of the other jobs with fabric values sampled between silk and leather
    motion_frames: int = 12  # frames from one pose to the next
    low_ratio: float = 0.25  # low resolution = this fraction of the vertices (at least MIN_LOW_VERTICES)
    workers: int = 2
    shard: tuple[int, int] = (0, 1)  # (k, n): run jobs with index % n == k
    limit: int | None = None  # run at most this many pending jobs (smoke runs)
    paired_first: bool = False  # run the paired-fabric jobs before the others (same jobs, another order)
    sim: dict[str, Any] = field(default_factory=dict)  # SimConfig overrides
    plan_version: int = 2  # the job-planning rule (2: paired groups in every family); other folders are refused
    # how parametric tops and dresses are held: "band" (their bodice's top ring; the straps slide) or "crest" (pins
    # where the straps cross the shoulders, skinned by the torso alone; docs/studies/anatomy.md)
    strap_pins: str = "band"
    # a finished folder of the same plan: its jobs whose simulation these settings leave unchanged are copied, not
    # simulated again (``job_settings``; e.g. every job but the parametric tops and dresses when only strap_pins differ)
    reuse: Path | None = None

    def __post_init__(self) -> None:
        self.out = Path(self.out)
        self.shard = tuple(self.shard)  # type: ignore[assignment]
        k, n = self.shard
        if not (n >= 1 and 0 <= k < n):
            raise ValueError(f"shard must be K/N with 0 <= K < N, got {k}/{n}")
        if min(self.num_train, self.num_test, self.num_ood) < 0:
            raise ValueError("job counts must be >= 0")
        if self.targets_per_job < 1 or self.motion_frames < 2:
            raise ValueError("targets_per_job >= 1 and motion_frames >= 2 required")
        if not (100 <= self.min_vertices <= self.max_vertices <= 30000):
            raise ValueError(
                f"need 100 <= min_vertices <= max_vertices <= 30000, got {self.min_vertices}, {self.max_vertices}"
            )
        if not (0.05 <= self.low_ratio <= 1.0):
            raise ValueError(f"low_ratio must be in [0.05, 1], got {self.low_ratio}")
        if self.workers < 1 or self.paired_every < 1 or not (0.0 <= self.physical_share <= 1.0):
            raise ValueError("workers >= 1, paired_every >= 1 and physical_share in [0, 1] required")
        if self.strap_pins not in STRAP_PINS:
            raise ValueError(f"strap_pins must be one of {STRAP_PINS}, got {self.strap_pins!r}")

    def settings(self) -> dict[str, Any]:
        """The settings a dataset folder is bound to (counts may grow, the rest must match)."""
        from garsim.physics.newton_sim import SimConfig

        d = asdict(self)
        for key in ("out", "num_train", "num_test", "num_ood", "workers", "shard", "limit", "paired_first", "reuse"):
            d.pop(key)
        if d["strap_pins"] == STRAP_PINS[0]:  # added later: folders made before it still match
            d.pop("strap_pins")
        sim = asdict(SimConfig(**self.sim))  # the effective simulator settings, defaults included
        for key in EXECUTION_SIM_SETTINGS:
            sim.pop(key)
        for key, legacy in OPTIONAL_SIM_SETTINGS.items():  # added later: folders made before them still match
            if key in sim and sim[key] == legacy:
                sim.pop(key)
        d["sim"] = sim
        return json.loads(json.dumps(d))


MIN_LOW_VERTICES = 120
EXECUTION_SIM_SETTINGS: tuple[str, ...] = ("graphs", "tight_contacts")
"""``SimConfig`` fields that say how a simulation is run, not what it computes (bit-identical either way,
``tests/test_physics_newton_sim.py``): not part of a folder's settings."""
OPTIONAL_SIM_SETTINGS: dict[str, Any] = {"settle_damping": None, "settle_iterations": None, "collide_every": 1}
"""``SimConfig`` fields added after datasets were made without them, and the value that reproduces the old
behaviour: left out of ``settings()`` at that value, so those folders still match."""


@dataclass
class JobSpec:
    """One garment instance to simulate (planned from the seed and its index alone)."""

    job_id: str
    index: int
    split: str
    family: str
    construction: str
    garment_params: dict[str, Any]
    vertices: int
    fabrics: list[dict[str, Any]]  # one entry per simulated copy: name + physical values
    paired: bool
    phenotype: dict[str, float]
    canonical_arm: float  # degrees above the A-pose (0 = A-pose, 40 = T-pose)
    pose_modes: list[str]  # per target: everyday / walk / wide
    pose_seed: int

    def copy_id(self, fabric_name: str) -> str:
        """The sequence id of one fabric copy."""
        return f"{self.job_id}-{fabric_name}" if self.paired else self.job_id


def split_indices(split: str, count: int) -> list[int]:
    """Global job indices of the first ``count`` jobs of ``split`` in the repeating block layout."""
    block = sum(n for _, n in INDEX_BLOCK)
    offset = 0
    for name, slots in INDEX_BLOCK:
        if name == split:
            return [(j // slots) * block + offset + j % slots for j in range(count)]
        offset += slots
    raise ValueError(f"unknown split {split!r}; expected one of {SPLITS}")


def _canonical_arm(rng: np.random.Generator) -> float:
    u = rng.uniform()
    if u < 1 / 3:
        return T_POSE_ARM
    if u < 2 / 3:
        return 0.0
    return round(float(rng.uniform(5.0, 35.0)), 2)


def _pose_modes(family: str, rng: np.random.Generator, count: int) -> list[str]:
    """Everyday poses for all; walking frames and the sampler's wide range where the family survives them."""
    if family in ARMHOLE_FAMILIES:
        return ["everyday"] * count
    if family == "skirt":
        return [str(m) for m in rng.choice(["everyday", "walk", "wide"], size=count, p=[0.55, 0.25, 0.2])]
    return [str(m) for m in rng.choice(["everyday", "walk"], size=count, p=[0.7, 0.3])]


def plan_jobs(config: GenerateConfig) -> list[JobSpec]:
    """All jobs of the dataset, deterministic in the seed (independent of shard and workers)."""
    from garsim.garments.fabrics import PRESET_NAMES, PRESETS, sample_fabric
    from garsim.garments.implicit import sample_implicit_params
    from garsim.garments.templates import sample_garment_params

    counts = {"train": config.num_train, "test": config.num_test, "ood": config.num_ood}
    jobs = []
    for split, count in counts.items():
        for j, i in enumerate(split_indices(split, count)):
            rng = np.random.default_rng([config.seed, i])
            if split == "ood":  # templates with parameters beyond every training sample's range
                family = TEMPLATE_FAMILIES[j % len(TEMPLATE_FAMILIES)]
                construction = "template"
                params = sample_garment_params(family, rng, region="ood")
            else:
                family = FAMILIES[j % len(FAMILIES)]
                construction = (
                    "implicit" if family not in TEMPLATE_FAMILIES else CONSTRUCTIONS[(j // len(FAMILIES)) % 2]
                )
                params = (
                    sample_garment_params(family, rng)
                    if construction == "template"
                    else sample_implicit_params(family, rng)
                )
            # the paired slot moves on by one every family x construction cycle: with a fixed j % k, k = 4, only
            # every other family (and one construction) was ever paired
            paired = (j + j // PAIRING_CYCLE) % config.paired_every == config.paired_every - 1
            hi = config.max_paired_vertices if paired else config.max_vertices
            lo = min(config.min_vertices, hi)
            vertices = int(round(math.exp(rng.uniform(math.log(lo), math.log(hi)))))
            if paired:
                fabrics = [{"name": n, **PRESETS[n].values()} for n in PRESET_NAMES]
            elif rng.uniform() < config.physical_share:
                fab = sample_fabric(rng)
                fabrics = [{"name": "custom", **fab.values()}]
            else:
                name = PRESET_NAMES[int(rng.integers(len(PRESET_NAMES)))]
                fabrics = [{"name": name, **PRESETS[name].values()}]
            phenotype = {k: round(float(rng.uniform(a, b)), 4) for k, (a, b) in PHENOTYPE_RANGES.items()}
            jobs.append(
                JobSpec(
                    job_id=f"{split}-{i:05d}",
                    index=i,
                    split=split,
                    family=family,
                    construction=construction,
                    garment_params=params,
                    vertices=vertices,
                    fabrics=fabrics,
                    paired=paired,
                    phenotype=phenotype,
                    canonical_arm=_canonical_arm(rng),
                    pose_modes=_pose_modes(family, rng, config.targets_per_job),
                    pose_seed=int(rng.integers(2**31)),
                )
            )
    return jobs


# -- one job ---------------------------------------------------------------------------------------
def _arm_pose(arm: float) -> dict[str, np.ndarray]:
    """Anny pose with both upper arms raised ``arm`` degrees above the rest A-pose (40 = the T-pose)."""
    a = math.radians(arm)
    return {"upperarm01.L": np.array([0.0, -a, 0.0]), "upperarm01.R": np.array([0.0, a, 0.0])}


def armhole_elevation_range(canonical_arm: float) -> tuple[float, float]:
    """Everyday shoulder elevation range (degrees, the pose sampler's: 0 = T-pose, -40 = A-pose) of a garment
    with armholes or sleeves cut for arms ``canonical_arm`` degrees above the A-pose: within
    ``ARM_BELOW_CANONICAL`` below and ``ARM_ABOVE_CANONICAL`` above the canonical arms.

    (The sampler measures elevation from the T-pose, ``canonical_arm`` from the A-pose: mixing the two let
    A-pose garments see arms raised 65 deg above their canonical position and kept T-pose ones near the T.)
    """
    from garsim.bodies.poses import EVERYDAY_LIMITS

    lo, hi = EVERYDAY_LIMITS.shoulder_elevation
    canonical = canonical_arm - T_POSE_ARM  # the canonical arms in the sampler's angle
    return max(lo, canonical - ARM_BELOW_CANONICAL), min(hi, canonical + ARM_ABOVE_CANONICAL)


def target_poses(job: JobSpec, body: Any) -> list[dict[str, np.ndarray]]:
    """The job's chain of target poses (bone -> axis-angle), drawn from its pose seed."""
    from dataclasses import replace

    from garsim.bodies.poses import EVERYDAY_LIMITS, JointLimits, PoseSampler, walk_pose

    rng = np.random.default_rng(job.pose_seed)
    everyday = EVERYDAY_LIMITS
    if job.family in ARMHOLE_FAMILIES:
        everyday = replace(everyday, shoulder_elevation=armhole_elevation_range(job.canonical_arm))
    poses = []
    for mode in job.pose_modes:
        seed = int(rng.integers(2**31))
        if mode == "walk":
            phase = float(rng.uniform(0.0, 2.0 * math.pi))
            poses.append({b: v[0] for b, v in walk_pose(phase, stride=float(rng.uniform(0.3, 0.7))).items()})
        else:
            limits = everyday if mode == "everyday" else JointLimits()
            poses.append(PoseSampler(limits, seed=seed, body=body).sample(1)[0])
    return poses


def crest_pinned(job: JobSpec, strap_pins: str) -> bool:
    """Whether the job's garment hangs on pins at its straps' crest (``GenerateConfig.strap_pins``)."""
    return strap_pins == "crest" and job.construction == "template" and job.family in STRAPPED_FAMILIES


def job_settings(job: JobSpec, settings: dict[str, Any]) -> dict[str, Any]:
    """The part of a folder's ``settings()`` that one job's simulation depends on: the strap pins only where they
    hold the garment (``crest_pinned``); two folders agreeing on it store the same records for the job."""
    d = {k: v for k, v in settings.items() if k != "strap_pins"}
    d["crest_pinned"] = crest_pinned(job, settings.get("strap_pins", STRAP_PINS[0]))
    return d


def reuse_jobs(config: GenerateConfig, jobs: Sequence[JobSpec]) -> tuple[int, int]:
    """Copy into ``config.out`` the finished ``jobs`` of ``config.reuse`` whose ``job_settings`` agree (stored
    sequences checked against their sha256, rejections as they were) -> (sequences, rejections) copied."""
    source = DatasetStore(config.reuse)
    path = source.root / CONFIG_FILE
    if not path.is_file():
        raise ValueError(
            f"--reuse {config.reuse}: no {CONFIG_FILE} there (not a folder made by `garsim data generate`)"
        )
    if source.root.resolve() == config.out.resolve():
        raise ValueError(f"--reuse {config.reuse} is the --out folder itself: give another dataset folder")
    theirs, mine = json.loads(path.read_text(encoding="utf-8")), config.settings()
    found: dict[str, tuple[list[dict[str, Any]], list[dict[str, Any]]]] = {}
    for name, slot in ((MANIFEST, 0), (REJECTED, 1)):
        for e in source.entries(name):
            found.setdefault(e.get("job", e["id"]), ([], []))[slot].append(e)
    store = DatasetStore(config.out)
    copied = [0, 0]
    for job in jobs:
        if job.job_id not in found or job_settings(job, theirs) != job_settings(job, mine):
            continue
        entries, rejections = found[job.job_id]
        for e in entries:
            try:
                data = (source.root / e["file"]).read_bytes()
            except OSError as exc:
                raise StoreError(
                    f"--reuse {source.root / e['file']}: {exc.strerror}; run `garsim data verify`"
                ) from None
            if hashlib.sha256(data).hexdigest() != e["sha256"]:
                raise StoreError(
                    f"--reuse {source.root / e['file']} does not match its manifest sha256: run `garsim data verify`"
                )
            atomic_write_bytes(store.root / e["file"], data)
            faces = store.root / "body_faces" / f"{e['body_faces']}.npy"
            if not faces.exists():
                atomic_write_bytes(faces, (source.root / "body_faces" / faces.name).read_bytes())
        for e in entries:  # the manifest after every file it names
            store.append_manifest(e)
        for r in rejections:
            store.append_manifest(r, REJECTED)
        copied[0] += len(entries)
        copied[1] += len(rejections)
    return copied[0], copied[1]


def build_garment(job: JobSpec, body: Any, strap_pins: str = STRAP_PINS[0]) -> Any:
    """The job's garment on the T-pose canonical body (either construction), pinned as ``strap_pins`` says."""
    from garsim.garments.implicit import make_implicit_garment
    from garsim.garments.templates import make_garment

    if job.construction == "template":
        g = make_garment(job.family, body, job.garment_params, target_vertices=job.vertices)
    else:
        g = make_implicit_garment(
            job.family,
            body.canonical().vertices,
            body.faces,
            body.skin_indices,
            body.skin_weights,
            body.bone_labels,
            job.garment_params,
            target_vertices=job.vertices,
        )
    g.params["construction"] = job.construction
    if crest_pinned(job, strap_pins):  # the straps' crest over the shoulders, not the bodice's ring
        g.pinned[:] = g.vertices[:, 2] >= g.vertices[:, 2].max() - SHOULDER_PIN_BAND
    elif job.family not in WAIST_FAMILIES:  # hung from the shoulders: pin only their tops
        g.pinned &= g.vertices[:, 2] >= g.vertices[g.pinned, 2].max() - SHOULDER_PIN_BAND
    return g


def simulate_job(
    job: JobSpec, config: GenerateConfig, visit: Sequence[int] | None = None
) -> tuple[list[SequenceRecord], list[dict[str, Any]]]:
    """Simulate one job: the stored records (one per fabric copy with at least one accepted state) and
    the rejections (copy id, reason, detail). Raises ``SimulationRejected`` when the template itself fails.
    ``visit``: indices of the job's target poses to chain, in order (default all; studies of the path)."""
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.base import PosedBody
    from garsim.bodies.poses import batched_matrices, interpolate_poses, stack_poses
    from garsim.bodies.prior import garment_prior
    from garsim.garments.fabrics import fabric_from_values, nearest_preset
    from garsim.garments.garment import Garment
    from garsim.garments.remesh import decimate, transfer_barycentric
    from garsim.geometry.io import MeshError, validate_mesh
    from garsim.geometry.mesh import edge_lengths
    from garsim.physics.newton_sim import SimConfig, SimulationRejected, check_result, settle, simulate_poses

    t0, c0 = time.perf_counter(), time.process_time()
    sim_cfg = SimConfig(**config.sim)
    body = AnnyBody(job.phenotype)
    tpose = body.canonical()
    try:
        garment = build_garment(job, body, config.strap_pins)
        validate_mesh(garment.vertices, garment.faces, f"{job.construction} {job.family}")
    except MeshError as exc:  # a construction that yields a broken mesh is a permanent, named rejection
        raise SimulationRejected(REJECT_INVALID_GARMENT, str(exc)) from None
    arm_pose = _arm_pose(job.canonical_arm)
    canonical = body.pose(arm_pose)
    if job.canonical_arm != T_POSE_ARM:  # skin the T-pose garment to the job's canonical arms
        moved = garment_prior(body, tpose, canonical, garment.vertices)
        garment = Garment(moved, garment.faces, garment.pinned, garment.kind, garment.params)
    rest = edge_lengths(garment.vertices, garment.faces)
    fabrics = [fabric_from_values({k: v for k, v in f.items() if k != "name"}, f["name"]) for f in job.fabrics]
    settle_fabric = (
        fabric_from_values(
            {
                k: v
                for k, v in next(f for f in job.fabrics if f["name"] == PAIRED_TEMPLATE_FABRIC).items()
                if k != "name"
            },
            PAIRED_TEMPLATE_FABRIC,
        )
        if job.paired
        else fabrics[0]
    )
    template, settle_info = settle(garment, canonical.vertices, body.faces, settle_fabric, sim_cfg)
    try:
        check_result(template, garment.faces, rest, canonical.vertices, body.faces, pinned=garment.pinned)
    except SimulationRejected as exc:
        raise SimulationRejected(exc.reason, "settle: " + exc.detail) from None
    if not settle_info["settled"]:
        raise SimulationRejected(
            "unsettled",
            f"template still moving at {settle_info['final_speed']} m/s after {settle_info['frames']} frames",
        )

    poses = target_poses(job, body)
    modes = job.pose_modes
    if visit is not None:
        poses, modes = [poses[i] for i in visit], [modes[i] for i in visit]
    pins = np.flatnonzero(garment.pinned)
    pin_bones = body.bone_mask(TORSO_BONES) if crest_pinned(job, config.strap_pins) else None
    chain = [arm_pose, *poses]
    body_segs, pin_segs, targets = [], [], []
    for a, b in zip(chain[:-1], chain[1:]):
        verts, transforms = body.pose_batch(
            batched_matrices(stack_poses(interpolate_poses(a, b, config.motion_frames + 1)))
        )
        body_segs.append(verts)
        pin_segs.append(
            np.stack(
                [
                    garment_prior(body, canonical, PosedBody(v, t), template[pins], pin_bones)
                    for v, t in zip(verts, transforms)
                ]
            )
        )
        targets.append(PosedBody(verts[-1], transforms[-1]))
    states, infos = simulate_poses(
        template, garment.faces, garment.pinned, body_segs, body.faces, pin_segs, fabrics, sim_cfg
    )

    priors = [garment_prior(body, canonical, t, template) for t in targets[: len(states)]]
    low_garment, mapping = decimate(
        Garment(template, garment.faces, garment.pinned, garment.kind, garment.params),
        ratio=max(config.low_ratio, min(1.0, MIN_LOW_VERTICES / len(template))),
    )
    low_priors = [garment_prior(body, canonical, t, low_garment.vertices) for t in targets[: len(states)]]
    seconds = time.perf_counter() - t0
    records, rejections = [], []
    for c, fabric in enumerate(fabrics):
        accepted: list[int] = []
        reason = None
        for k, state in enumerate(states):
            if not infos[k].get("settled"):
                reason = ("unsettled", f"target {k}: mean speed {infos[k].get('final_speed')} m/s")
                break
            try:
                check_result(state[c], garment.faces, rest, targets[k].vertices, body.faces, pinned=garment.pinned)
            except SimulationRejected as exc:
                reason = (exc.reason, f"target {k}: {exc.detail}")
                break
            accepted.append(k)
        if len(states) < len(infos) and reason is None:  # the chain stopped at an exploding segment
            reason = (infos[-1]["aborted"], f"target {len(states)}: simulation aborted")
        seq_id = job.copy_id(fabric.name)
        if reason is not None:
            rejections.append(
                {"id": seq_id, "job": job.job_id, "reason": reason[0], "detail": reason[1], "accepted": len(accepted)}
            )
        if not accepted:
            continue
        gt = np.stack([states[k][c] for k in accepted]).astype(np.float32)
        full = GarmentLevel(template, garment.faces, garment.pinned, np.stack([priors[k] for k in accepted]), gt)
        low = GarmentLevel(
            template=low_garment.vertices,
            faces=low_garment.faces,
            pinned=low_garment.pinned,
            priors=np.stack([low_priors[k] for k in accepted]),
            targets=np.stack([transfer_barycentric(t, mapping) for t in gt]).astype(np.float32),
        )
        meta = {
            "index": job.index,
            "seed": config.seed,
            "job": job.job_id,
            "family": job.family,
            "construction": job.construction,
            "garment_params": job.garment_params,
            "phenotype": job.phenotype,
            "canonical_arm": job.canonical_arm,
            "canonical_pose": canonical_pose_name(job.canonical_arm),
            "paired": job.paired,
            "fabric_name": fabric.name,
            "fabric_values": fabric.values(),
            "settled": [True] * len(accepted),
            "dynamic": [False] * len(accepted),
            "final_speed": [infos[k]["final_speed"][c] for k in accepted],
            "pose_modes": [modes[k] for k in accepted],
            "target_poses": [
                {b: np.asarray(v, dtype=float).round(6).tolist() for b, v in poses[k].items()} for k in accepted
            ],
            "settle": {k: settle_info[k] for k in ("frames", "final_speed", "settled", "seconds")},
            "targets": [{k: v for k, v in infos[t].items() if k != "final_speed"} for t in accepted],
            "seconds": seconds / len(fabrics),
            "cpu_seconds": (time.process_time() - c0) / len(fabrics),
        }
        records.append(
            SequenceRecord(
                seq_id=seq_id,
                split=job.split,
                garment_type=job.family,
                fabric=fabric.name if fabric.name != "custom" else nearest_preset(fabric),
                body_canonical=canonical.vertices,
                body_targets=np.stack([targets[k].vertices for k in accepted]),
                body_faces=body.faces,
                frames=np.asarray(accepted, dtype=np.int64),
                levels={"full": full, "low": low},
                meta=meta,
            )
        )
    return records, rejections


def canonical_pose_name(arm: float) -> str:
    """``tpose``, ``apose`` or ``between`` for a canonical arm raise in degrees."""
    return "tpose" if arm == T_POSE_ARM else "apose" if arm == 0.0 else "between"


def _run_one(args: tuple[JobSpec, GenerateConfig]) -> dict[str, Any]:
    """Worker: simulate one job and write its records; returns manifest / rejection entries, or an error."""
    from garsim.physics.newton_sim import SimulationRejected

    job, config = args
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        _check_worker_settings(config)
        records, rejections = simulate_job(job, config)
        store = DatasetStore(config.out)
        entries = []
        for rec in records:
            entry = store.write_sequence(rec)
            entry.update(
                job=job.job_id,
                construction=job.construction,
                paired=job.paired,
                canonical_pose=rec.meta["canonical_pose"],
                fabric_name=rec.meta["fabric_name"],
                cpu_seconds=round(rec.meta["cpu_seconds"], 2),
                seconds=round(rec.meta["seconds"], 2),
                num_settled=int(sum(rec.meta["settled"])),
                phenotype=job.phenotype,
            )
            entries.append(entry)
    except SimulationRejected as exc:
        records, entries = [], []
        rejections = [
            {"id": job.copy_id(f["name"]), "job": job.job_id, "reason": exc.reason, "detail": exc.detail, "accepted": 0}
            for f in job.fabrics
        ]
    except Exception as exc:  # transient or a bug: not a permanent rejection, retried on the next run
        return {
            "error": {
                "job": job.job_id,
                "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc(limit=5),
            }
        }
    cpu = (time.process_time() - c0) / max(len(job.fabrics), 1)
    for r in rejections:
        r.update(
            family=job.family,
            construction=job.construction,
            split=job.split,
            targets=len(job.pose_modes),
            cpu_seconds=round(cpu, 2) if r["accepted"] == 0 else 0.0,  # a stored copy carries its own time
            seconds=round((time.perf_counter() - t0) / len(job.fabrics), 2),
        )
    return {"entries": entries, "rejections": rejections}


def _check_worker_settings(config: GenerateConfig) -> None:
    """Refuse (a retried error, not a rejection) to simulate with settings other than the folder's
    ``config.json``: a worker started after the code's defaults changed would otherwise mix them in."""
    path = config.out / CONFIG_FILE
    if not path.exists():
        return
    theirs = json.loads(path.read_text(encoding="utf-8"))
    mine = config.settings()
    differ = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
    if differ:
        raise RuntimeError(
            f"this worker's settings differ from {path} in {differ} (code defaults changed since the run "
            "started?): restart the run, or generate into another --out folder"
        )


def check_settings(config: GenerateConfig) -> None:
    """Bind the dataset folder to these settings, or refuse a rerun whose settings differ."""
    path = config.out / CONFIG_FILE
    mine = config.settings()
    if path.exists():
        try:
            theirs = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path} is corrupt ({exc}); remove it only if the folder holds no samples") from None
        for key in sorted(set(mine) | set(theirs)):
            if mine.get(key) != theirs.get(key):
                raise ValueError(
                    f"{config.out} was generated with {key}={theirs.get(key)!r}, this run has "
                    f"{key}={mine.get(key)!r}: use the same setting or another --out folder"
                )
        return
    if (config.out / "manifest.jsonl").exists():
        raise ValueError(
            f"{config.out} holds a dataset without {CONFIG_FILE} (an older format): use another --out folder"
        )
    atomic_write_bytes(path, json.dumps(mine, indent=2, sort_keys=True).encode())


def _finished_jobs(store: DatasetStore) -> set[str]:
    """Jobs with a stored sequence or a rejection (skipped when resuming)."""
    return {e.get("job", e["id"]) for name in (MANIFEST, REJECTED) for e in store.entries(name)}


@contextlib.contextmanager
def _shard_lock(out: Path, shard: tuple[int, int]) -> Iterator[None]:
    """Hold this shard of the dataset folder for one run: a second run of the same shard into the same folder (which
    would simulate the same jobs again and append them twice) is refused. The lock is the kernel's (flock), so it
    goes with the process that holds it, however that process ends."""
    k, n = shard
    with open(out / f".generate-{k}-of-{n}.lock", "a+", encoding="utf-8") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            raise RuntimeError(
                f"{out} (shard {k}/{n}) is being generated by another process (pid {fh.read().strip() or '?'}): "
                "wait for it to finish or stop it"
            ) from None
        fh.seek(0)
        fh.truncate()
        fh.write(str(os.getpid()))
        fh.flush()
        yield


def generate(config: GenerateConfig, progress: bool = True) -> dict[str, Any]:
    """Run (or resume) generation; returns counts, rejection reasons and timings of this run. Refused while another
    run generates the same shard into the same folder."""
    config.out.mkdir(parents=True, exist_ok=True)
    with _shard_lock(config.out, config.shard):
        return _generate(config, progress)


def _generate(config: GenerateConfig, progress: bool) -> dict[str, Any]:
    from tqdm import tqdm

    check_settings(config)
    from dataclasses import replace

    from garsim.physics.newton_sim import SimConfig

    # workers get the simulator settings resolved here, not their own code's defaults at spawn time
    config = replace(config, sim=asdict(SimConfig(**config.sim)))
    store = DatasetStore(config.out)
    jobs = plan_jobs(config)
    k, n = config.shard
    done, reused = _finished_jobs(store), (0, 0)
    if config.reuse is not None:
        reused = reuse_jobs(config, [j for j in jobs if j.index % n == k and j.job_id not in done])
        done = _finished_jobs(store)
    pending = [j for j in jobs if j.index % n == k and j.job_id not in done]
    # interleave the splits so that a partial run (or a stopped one) holds every split in proportion
    rank = {j.job_id: r for split in SPLITS for r, j in enumerate(x for x in jobs if x.split == split)}
    size = Counter(j.split for j in jobs)
    pending.sort(key=lambda j: (config.paired_first and not j.paired, rank[j.job_id] / size[j.split], j.index))
    if config.limit is not None:
        pending = pending[: config.limit]
    summary: dict[str, Any] = {
        "planned": len(jobs),
        "pending": len(pending),
        "stored": 0,
        "rejected": {},
        "errors": 0,
        "reused": {"sequences": reused[0], "rejections": reused[1]},
        "seconds": [],
    }
    if not pending:
        return summary
    work = [(j, config) for j in pending]
    t0 = time.perf_counter()
    pool_cm = _worker_pool(config.workers) if config.workers > 1 else _InlinePool()
    with pool_cm as pool:
        bar = tqdm(pool.imap_unordered(_run_one, work), total=len(work), disable=not progress, unit="job")
        for result in bar:
            if "error" in result:
                summary["errors"] += 1
                store.append_manifest(result["error"], ERRORS)
                log.error(
                    "job %s failed (retried on the next run): %s", result["error"]["job"], result["error"]["error"]
                )
                continue
            for entry in result["entries"]:
                store.append_manifest(entry)
                summary["stored"] += 1
                summary["seconds"].append(entry["seconds"])
            for rej in result["rejections"]:  # ``accepted`` > 0: the copy's states before the failing one are stored
                store.append_manifest(rej, REJECTED)
                summary["rejected"][rej["reason"]] = summary["rejected"].get(rej["reason"], 0) + 1
                log.info("rejected %s: %s", rej["id"], rej["detail"].splitlines()[0])
            bar.set_postfix(stored=summary["stored"], rejected=sum(summary["rejected"].values()))
    summary["wall_seconds"] = time.perf_counter() - t0
    return summary


_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _worker_init(parent: int) -> None:
    """Worker initializer: die with the parent (a watchdog thread polls the parent pid), one torch/BLAS thread.

    Not PR_SET_PDEATHSIG: it fires when the parent *thread* ends, and the pool's handler thread, which starts the
    workers that replace recycled ones, ends when the pool closes; its workers were then killed while waiting on the
    task queue, holding its lock, and the parent hung for good on that lock (seen here after a finished run)."""
    import threading

    if os.getppid() != parent:  # the parent died before the watchdog was armed
        os._exit(1)

    def watchdog() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watchdog, name="garsim-parent-watchdog", daemon=True).start()
    import torch

    torch.set_num_threads(1)


@contextlib.contextmanager
def _worker_pool(workers: int) -> Iterator[Any]:
    """A spawn process pool whose workers use one thread each and are killed if the parent dies.

    The thread variables stay set while the pool lives, so workers it respawns inherit them too.
    """
    saved = {k: os.environ.get(k) for k in _THREAD_VARS}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    try:
        pool = mp.get_context("spawn").Pool(
            workers, initializer=_worker_init, initargs=(os.getpid(),), maxtasksperchild=10
        )
        try:
            yield pool
        except BaseException:
            pool.terminate()
            raise
        pool.close()  # a finished run lets its workers finish and waits for them (terminate() is for failures)
        pool.join()
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _InlinePool:
    """A one-process stand-in for ``multiprocessing.Pool`` (workers=1: easier debugging)."""

    def __enter__(self) -> _InlinePool:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    @staticmethod
    def imap_unordered(fn, items):  # type: ignore[no-untyped-def]
        return map(fn, items)
