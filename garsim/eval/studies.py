"""The paper's studies on our data, each trained and scored under one shared protocol (data, split, schedule,
seed): Table 2 (decoder heads and message-passing steps), Table 3 (GarSim beside the DeePSD-style baseline),
generalisation to garment families never trained on, resolution (1x-8x the training resolution, with and without the
API's decimation path), data scaling, and the corrections over the prior (Fig. 8). ``examples/experiments.py`` runs
each as one command.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import subprocess
import sys
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from garsim.api import GarSim
from garsim.atomic import atomic_write
from garsim.data.sample import Sample
from garsim.data.store import DatasetStore, GarmentLevel, SequenceRecord
from garsim.eval.experiments import evaluate_split, score_predictions
from garsim.garments.remesh import subdivide, transfer_barycentric
from garsim.geometry.mesh import cached_vertex_normals, surface_smoother
from garsim.geometry.proximity import soft_surface
from garsim.geometry.render import DEFAULT_COLORS, render_views
from garsim.model.baselines import load_model
from garsim.model.config import HEADS, GarSimConfig
from garsim.model.garsim import GraphModel
from garsim.train.data import train_val_samples
from garsim.train.trainer import TrainConfig, Trainer

STEPS: tuple[int, ...] = (0, 1, 3, 5, 8)
"""Message-passing steps L of the Table 2 analog (0: no message passing)."""
SEEN_FAMILIES: tuple[str, ...] = ("skirt", "top")
"""The paper's generalisation protocol trains on these families only."""
UPPER_BODY: tuple[str, ...] = ("top", "tshirt", "longsleeve")
"""The families v0.7 underfits on its own training samples (docs/studies/breakdown.md)."""
SIZES: tuple[tuple[int, int], ...] = ((64, 5), (128, 5), (64, 10))
"""(latent and MLP width, message-passing steps L) of the capacity study's variants: v0.7's size, twice as wide,
twice as deep."""
FACTORS: tuple[int, ...] = (1, 2, 4, 8)
"""Resolutions scored, as multiples of the training (low) resolution's linear density."""
SIGMAS: tuple[float, ...] = (0.01, 0.02, 0.04, 0.08)
"""Lengths (m) at which the smooth-correction oracle smooths the simulator's correction over the prior."""
FRACTIONS: tuple[float, ...] = (0.25, 0.5, 1.0)
"""Shares of the training jobs of the data-scaling study."""
RUN_ONLY_KEYS: tuple[str, ...] = ("out_dir", "progress", "resume", "threads", "checkpoint_every")
"""TrainConfig fields that do not change what a run learns (left out of its key)."""

Results = dict[str, dict[str, dict[str, float]]]
"""{method: {garment family or 'all': {metric: value, "frames": n}}}, as ``evaluate_split`` returns."""


@dataclass
class StudyConfig:
    """The protocol every variant of a study shares: the dataset, the split scored, the training resolution and
    validation hold-out, the schedule and seed (``train``; its ``out_dir`` is the study's folder, models go to
    ``out_dir/models/<key>``) and the base model, so variants differ only in what their study varies."""

    data: str
    train: TrainConfig = field(default_factory=TrainConfig)
    model: GarSimConfig = field(default_factory=GarSimConfig)
    split: str = "test"
    resolution: str = "low"
    val_every: int = 10
    test_data: str | None = None  # the folder of the scored split, when not ``data`` (e.g. v4 trains, v4test scores)

    @property
    def scored_data(self) -> str:
        """The dataset folder whose ``split`` is scored."""
        return self.test_data or self.data

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON dict (recorded beside every study's results)."""
        return dataclasses.asdict(self)


def train_variant(
    study: StudyConfig,
    model: GarSimConfig | None = None,
    families: Sequence[str] | None = None,
    fraction: float = 1.0,
    kind: str | None = None,
) -> tuple[GraphModel, dict[str, Any]]:
    """Train one variant (``model``: the study's base model; ``families`` / ``fraction``: as
    ``train_val_samples``; ``kind``: a key of ``garsim.model.baselines.MODELS``, default the study's
    ``TrainConfig.model``) under the study's protocol; returns its best checkpoint and a record of the run.

    The run folder is keyed by everything that decides the result (model config, schedule, seed and the
    sequences trained and validated on), so a variant several studies share is trained once, and a rerun
    resumes an interrupted run rather than starting again."""
    config = model or study.model
    schedule = study.train if kind is None else dataclasses.replace(study.train, model=kind)
    train, val = train_val_samples(
        study.data, study.resolution, study.val_every, families=families, fraction=fraction, seed=study.train.seed
    )
    sequences = {name: sorted({s.meta["seq_id"] for s in part}) for name, part in (("train", train), ("val", val))}
    variant = {
        "model": config.to_dict(),
        "train": {k: v for k, v in schedule.to_dict().items() if k not in RUN_ONLY_KEYS},
        "resolution": study.resolution,
        "families": sorted(families) if families is not None else None,
        "fraction": fraction,
        "sequences": sequences,
    }
    key = hashlib.sha256(json.dumps(variant, sort_keys=True).encode()).hexdigest()[:12]
    out = Path(study.train.out_dir) / "models" / key
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "variant.json", lambda p: Path(p).write_text(json.dumps(variant, indent=1)))
    Trainer(config, dataclasses.replace(schedule, out_dir=str(out)), train, val or None).fit()
    record = {
        "dir": str(out / "best"),
        "train_samples": len(train),
        "train_sequences": len(sequences["train"]),
        "val_sequences": len(sequences["val"]),
    }
    return load_model(out / "best"), record


def _study(study: StudyConfig, variants: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Train each variant (``train_variant`` keyword arguments by row label) and score its raw network on the
    split beside one set of baseline rows."""
    models: dict[str, dict[str, Any]] = {}
    results: Results = {}
    for label, kwargs in variants.items():
        model, models[label] = train_variant(study, **kwargs)
        scored = evaluate_split(
            model, study.scored_data, study.split, study.resolution, collision_margin=None, name=label, baselines=False
        )
        results[label] = scored[label]
    results.update(evaluate_split(None, study.scored_data, study.split, study.resolution))
    return {"protocol": study.to_dict(), "models": models, "results": results}


def heads_and_steps(study: StudyConfig, heads: Sequence[str] = HEADS, steps: Sequence[int] = STEPS) -> dict[str, Any]:
    """Table 2 analog: each decoder head (at the base model's L) and each number of message-passing steps L
    (with the base model's head), trained under one protocol and scored per family (raw network)."""
    base = study.model
    configs = {f"{h}, L={base.num_steps}": dataclasses.replace(base, head=h) for h in heads}
    configs.update({f"{base.head}, L={n}": dataclasses.replace(base, num_steps=n) for n in steps})
    return _study(study, {label: {"model": cfg} for label, cfg in configs.items()})


def deepsd_comparison(study: StudyConfig, resolutions: Sequence[str] = ("low", "full")) -> dict[str, Any]:
    """Table 3 analog: GarSim beside the DeePSD-style baseline (``--model deepsd``, trained under the same protocol:
    data, split, schedule, seed) and the prior and nearest-vertex rows, every metric per family, at each of the
    ``resolutions`` of the scored split (both models trained at the study's resolution; raw networks)."""
    trained = {
        label: train_variant(study, kind=kind) for label, kind in (("GarSim", "garsim"), ("DeePSD-style", "deepsd"))
    }
    results: Results = {}
    for res in resolutions:
        for label, (model, _) in trained.items():
            scored = evaluate_split(
                model, study.scored_data, study.split, res, collision_margin=None, name=label, baselines=False
            )
            results[f"{label} @ {res}"] = scored[label]
        for method, per in evaluate_split(None, study.scored_data, study.split, res).items():
            results[f"{method} @ {res}"] = per
    ratio = {
        res: {
            k: v["euclidean_mm"] / results[f"DeePSD-style @ {res}"][k]["euclidean_mm"]
            for k, v in results[f"GarSim @ {res}"].items()
        }
        for res in resolutions
    }
    models = {label: info for label, (_, info) in trained.items()}
    return {"protocol": study.to_dict(), "models": models, "results": results, "garsim_over_deepsd": ratio}


def generalisation(study: StudyConfig, seen: Sequence[str] = SEEN_FAMILIES) -> dict[str, Any]:
    """The paper's protocol: the base model trained on the ``seen`` families only beside the same model trained on
    every family, both scored per family (validation also holds only the seen families)."""
    label = f"trained on {' and '.join(seen)}"
    return {**_study(study, {label: {"families": tuple(seen)}, "trained on all families": {}}), "seen": list(seen)}


def capacity(
    study: StudyConfig, sizes: Sequence[tuple[int, int]] = SIZES, families: Sequence[str] = UPPER_BODY
) -> dict[str, Any]:
    """Whether the base model is too small for ``families``: variants of its width (node latent and MLP width,
    the edge latent half of it) and message-passing steps L, trained under one protocol on ``families`` only, each
    scored (raw network) on the split with its best checkpoint and, under "fit", with its last one on the very
    samples it was trained on (what it can fit, whatever validation picks)."""
    base = study.model
    variants = {
        f"width {w}, L={steps}": {
            "model": dataclasses.replace(base, latent=w, mlp_hidden=w, edge_latent=w // 2, num_steps=steps),
            "families": tuple(families),
        }
        for w, steps in sizes
    }
    out = _study(study, variants)
    train, _ = train_val_samples(  # without the rest samples, whose prior is exact
        study.data, study.resolution, study.val_every, rest=False, families=families, seed=study.train.seed
    )
    last = {label: Path(info["dir"]).parent / "checkpoint" for label, info in out["models"].items()}
    predictions = {label: load_model(folder).predict(train) for label, folder in last.items()}
    out["fit"] = score_predictions(train, {**predictions, "prior": [s.prior for s in train]})
    out["families"] = list(families)
    return out


def data_scaling(
    study: StudyConfig, fractions: Sequence[float] = FRACTIONS, external: str | Path | None = None
) -> dict[str, Any]:
    """Error vs training-set size: the base model trained on each share of the training jobs (nested subsets of
    whole jobs, one validation set), scored per family; with ``external`` (``check.py`` of the external set,
    never trained on) also each model's summary there."""
    out = _study(study, {f"{100 * f:g}% of the training jobs": {"fraction": f} for f in fractions})
    if external is not None:
        folder = Path(study.train.out_dir) / "external"
        out["external"] = {
            label: external_check(external, info["dir"], folder / f"{Path(info['dir']).parent.name}.json")
            for label, info in out["models"].items()
        }
    return out


def external_check(script: str | Path, model_dir: str | Path, out_json: Path) -> dict[str, Any]:
    """Run the external set's ``check.py --model DIR --json OUT`` in a subprocess; its per-family summary."""
    out_json.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, str(script), "--model", str(model_dir), "--json", str(out_json)]
    subprocess.run(cmd, check=True)
    return json.loads(out_json.read_text())["summary"]


def subdivide_level(level: GarmentLevel) -> GarmentLevel:
    """A stored garment level midpoint-subdivided: template, priors and ground truth carried linearly (the
    simulated surface is piecewise linear, so the truth is exact), pinned where both edge ends are."""
    faces, mapping = subdivide(level.faces, len(level.template))

    def frames(values: np.ndarray) -> np.ndarray:
        return transfer_barycentric(values.transpose(1, 0, 2), mapping).transpose(1, 0, 2)

    return GarmentLevel(
        template=transfer_barycentric(level.template, mapping),
        faces=faces,
        pinned=transfer_barycentric(level.pinned.astype(np.float64), mapping) == 1.0,
        priors=frames(level.priors),
        targets=frames(level.targets),
    )


def resolution_levels(rec: SequenceRecord, factors: Sequence[int] = FACTORS) -> dict[int, GarmentLevel]:
    """The record's garment at each factor (a power of 2) of the training resolution's linear density: 1 the low
    level, 2 the full level (the generator keeps ~1/4 of the vertices at low; the low level subdivided where
    there is none), higher factors the finest of these midpoint-subdivided once per doubling."""
    levels = {1: rec.levels["low"]}
    if "full" in rec.levels:
        levels[2] = rec.levels["full"]
    for f in sorted(factors):
        if f < 1 or f & (f - 1):
            raise ValueError(f"resolution factors must be powers of 2, got {f}")
        base = max(b for b in levels if b <= f)
        while base < f:
            levels[2 * base] = subdivide_level(levels[base])
            base *= 2
    return {f: levels[f] for f in factors}


def resolution_study(study: StudyConfig, model: Any, factors: Sequence[int] = FACTORS) -> dict[str, Any]:
    """A model trained at the low resolution scored on the split's garments at each factor of that resolution
    (``resolution_levels``), run on the garment as given ("network") and through the API's decimation path
    ("network, decimated": ``GarSim(max_vertices=)`` at the garment's low vertex count, the correction carried
    back), beside the prior; also the mean vertex count and measured linear factor (sqrt of the vertex ratio to
    the low level) of each factor. No collision post-process: pinned vertices follow the prior in both."""
    plain = GarSim(model, collision_margin=None, refine=False)
    samples: dict[int, list[Sample]] = defaultdict(list)
    preds: dict[int, dict[str, list[np.ndarray]]] = defaultdict(lambda: defaultdict(list))
    linear: dict[int, list[float]] = defaultdict(list)
    for rec in DatasetStore(study.scored_data).sequences(study.split):
        low = len(rec.levels["low"].template)
        coarse = GarSim(model, collision_margin=None, refine=False, max_vertices=max(100, low))
        for f, level in resolution_levels(rec, factors).items():
            for s in dataclasses.replace(rec, levels={f"{f}x": level}).samples(f"{f}x"):
                samples[f].append(s)
                preds[f]["network"].append(plain.predict(s))
                preds[f]["network, decimated"].append(coarse.predict(s))
                preds[f]["prior"].append(s.prior)
                linear[f].append(float(np.sqrt(len(s.garment) / low)))
    if not samples:
        raise ValueError(f"{study.scored_data}: no {study.split!r} sequences to score")
    results: Results = {}
    for f in factors:
        for method, per_family in score_predictions(samples[f], preds[f]).items():
            results[f"{method} @ {f}x"] = per_family
    levels = {
        f: {
            "vertices": float(np.mean([len(s.garment) for s in samples[f]])),
            "linear_factor": float(np.mean(linear[f])),
        }
        for f in factors
    }
    return {"protocol": study.to_dict(), "levels": levels, "results": results}


def corrections(study: StudyConfig, model: Any, per_family: int = 1, size: int = 512) -> dict[str, Any]:
    """Fig. 8: the raw network's per-vertex correction over the prior |Ḡ − G^prior| (mm) on ``per_family`` random
    samples (seeded) of every family of the split, rendered on the garment with a colour bar beside the
    simulator's own correction |G_sim − G^prior| on the same scale (left: network, right: simulation); one PNG
    per sample under ``out_dir/corrections`` and the mean and max of both."""
    by_family: dict[str, list[Sample]] = defaultdict(list)
    for s in DatasetStore(study.scored_data).samples(study.split, study.resolution):
        by_family[s.garment_type].append(s)
    rng = np.random.default_rng(study.train.seed)
    folder = Path(study.train.out_dir) / "corrections"
    rows = []
    for family, group in sorted(by_family.items()):
        for i in sorted(rng.choice(len(group), size=min(per_family, len(group)), replace=False)):
            s = group[i]
            pred = model.predict(s)
            net = 1000.0 * np.linalg.norm(pred - s.prior, axis=1)
            sim = 1000.0 * np.linalg.norm(s.target - s.prior, axis=1)
            shift = np.array([1.15 * np.ptp(s.body_target[:, 0]), 0.0, 0.0], np.float32)
            body = (s.body_target, s.body_faces)
            png = render_views(
                folder / f"{s.meta['name'].replace('@', '_')}.png",
                [body, (pred, s.garment_faces), (body[0] + shift, s.body_faces), (s.target + shift, s.garment_faces)],
                views=("front",),
                colors=[DEFAULT_COLORS[0], net, DEFAULT_COLORS[0], sim],
                size=size,
                vmin=0.0,
                vmax=float(max(net.max(), sim.max())),
                title=f"{family}/{s.fabric}: network (left), simulation (right)",
                colorbar_label="|Ḡ − G^prior| (mm)",
            )
            rows.append(
                {
                    "sample": s.meta["name"],
                    "garment": family,
                    "fabric": s.fabric,
                    "png": str(png),
                    "network_mean_mm": float(net.mean()),
                    "network_max_mm": float(net.max()),
                    "simulation_mean_mm": float(sim.mean()),
                    "simulation_max_mm": float(sim.max()),
                    "error_mm": float(1000.0 * np.linalg.norm(pred - s.target, axis=1).mean()),
                }
            )
    return {"protocol": study.to_dict(), "samples": rows}


def smooth_oracle(study: StudyConfig, model: Any = None, sigmas: Sequence[float] = SIGMAS) -> dict[str, Any]:
    """What a prediction exact at every length above sigma would leave of the prior's error: per family and overall,
    the mean Euclidean error (mm, mean over samples of the per-vertex mean) of G^prior + S_sigma(G_sim - G^prior),
    the simulator's correction smoothed along the template's surface at about sigma (``surface_smoother``), beside
    the prior's and the model's (when given). The rest is detail finer than sigma: folds and wrinkles."""
    samples = DatasetStore(study.scored_data).samples(study.split, study.resolution)
    if not samples:
        raise ValueError(f"{study.scored_data}: no {study.split!r} samples")
    preds = model.predict(samples) if model is not None else [None] * len(samples)
    per: dict[str, list[dict[str, float]]] = defaultdict(list)
    for s, pred in zip(samples, preds):
        needed = np.asarray(s.target, np.float64) - s.prior
        row = {"prior": 1000.0 * float(np.linalg.norm(needed, axis=1).mean())}
        for sigma in sigmas:
            rest = needed - surface_smoother(s.garment, s.garment_faces, sigma)(needed)
            row[f"oracle@{sigma:g}"] = 1000.0 * float(np.linalg.norm(rest, axis=1).mean())
        if pred is not None:
            row["model"] = 1000.0 * float(np.linalg.norm(pred - s.target, axis=1).mean())
        per[s.garment_type].append(row)
        per["all"].append(row)
    results = {
        family: {"samples": len(rows), **{k: float(np.mean([r[k] for r in rows])) for k in rows[0]}}
        for family, rows in sorted(per.items(), key=lambda kv: (kv[0] != "all", kv[0]))
    }
    return {"protocol": study.to_dict(), "sigmas": list(sigmas), "oracle": results}


ANATOMY_BANDS = 4
"""Height bands (quantiles of the template's vertex heights) of ``error_anatomy``'s error profile."""


def anatomy_row(
    template: np.ndarray,
    prior: np.ndarray,
    pred: np.ndarray,
    target: np.ndarray,
    body_target: np.ndarray,
    body_faces: np.ndarray,
) -> dict[str, float]:
    """Where one drape's error lies (mm): for the prior and the prediction, the mean error's part along the target
    body's normal (at the simulated vertex's soft anchor) and across it, and the mean error in each of
    ``ANATOMY_BANDS`` height bands of the template, lowest first; ``cosine``: the prediction's correction over the
    prior against the simulator's (1: the right direction, 0: unrelated)."""
    truth = np.asarray(target, dtype=np.float64)
    _, n = soft_surface(truth, body_target, cached_vertex_normals(body_target, np.asarray(body_faces, dtype=np.int64)))
    z = np.asarray(template, dtype=np.float64)[:, 2]
    band = np.minimum((np.argsort(np.argsort(z, kind="stable")) * ANATOMY_BANDS) // len(z), ANATOMY_BANDS - 1)
    row: dict[str, float] = {}
    for name, x in (("prior", prior), ("model", pred)):
        e = np.asarray(x, dtype=np.float64) - truth
        along = np.einsum("ij,ij->i", e, n)
        norm = np.linalg.norm(e, axis=1)
        row[f"{name}_mm"] = 1000.0 * float(norm.mean())
        row[f"{name}_normal_mm"] = 1000.0 * float(np.abs(along).mean())
        row[f"{name}_tangential_mm"] = 1000.0 * float(np.linalg.norm(e - along[:, None] * n, axis=1).mean())
        for b in range(ANATOMY_BANDS):
            row[f"{name}_band{b}_mm"] = 1000.0 * float(norm[band == b].mean())
    need, got = truth - prior, np.asarray(pred, dtype=np.float64) - prior
    row["cosine"] = float((need * got).sum() / max(np.sqrt((need**2).sum() * (got**2).sum()), 1e-30))
    return row


def error_anatomy(rows: Sequence[tuple[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """``anatomy_row`` results (family, row) averaged per family and over all, with the sample count."""
    per: dict[str, list[dict[str, float]]] = defaultdict(list)
    for family, row in rows:
        per[family].append(row)
        per["all"].append(row)
    return {
        family: {"samples": len(rs), **{k: float(np.mean([r[k] for r in rs])) for k in rs[0]}}
        for family, rs in sorted(per.items(), key=lambda kv: (kv[0] != "all", kv[0]))
    }


def anatomy_table(anatomy: dict[str, dict[str, float]]) -> str:
    """A Markdown table of ``error_anatomy``: per family, prior -> model for the error, its normal and tangential
    parts and each height band, and the correction's cosine."""
    parts = ["", "_normal", "_tangential", *(f"_band{b}" for b in range(ANATOMY_BANDS))]
    names = ["error", "normal", "tangential", *(f"band {b + 1}" for b in range(ANATOMY_BANDS))]
    lines = [
        "| family | samples | " + " | ".join(names) + " | cosine |",
        "|---|---|" + "---|" * (len(names) + 1),
    ]
    for family, r in anatomy.items():
        cells = [f"{r[f'prior{p}_mm']:.1f} -> {r[f'model{p}_mm']:.1f}" for p in parts]
        lines.append(f"| {family} | {r['samples']} | " + " | ".join(cells) + f" | {r['cosine']:.2f} |")
    return "\n".join(lines)


def dataset_anatomy(study: StudyConfig, model: Any) -> list[tuple[str, dict[str, float]]]:
    """``anatomy_row`` of every sample of the study's scored split, the model's raw network against the prior."""
    samples = DatasetStore(study.scored_data).samples(study.split, study.resolution)
    if not samples:
        raise ValueError(f"{study.scored_data}: no {study.split!r} samples")
    preds = model.predict(samples)
    return [
        (s.garment_type, anatomy_row(s.garment, s.prior, p, s.target, s.body_target, s.body_faces))
        for s, p in zip(samples, preds)
    ]


def external_anatomy(data_dir: str | Path, model_dir: str | Path) -> list[tuple[str, dict[str, float]]]:
    """``anatomy_row`` of every drape of the external check set (``../shared/external-eval/data``), predicted as its
    checker does (``GarSim.load(...).drape``) but with the raw network (no push-out), against the set's own prior."""
    d = Path(data_dir)
    body_faces = np.load(d / "body_faces.npy")
    sim = GarSim.load(model_dir, collision_margin=None)
    rows = []
    for path in sorted(d.glob("[hr]*.npz")):
        x = np.load(path)
        pred = sim.drape(
            (x["body_canonical"], body_faces),
            (x["body_target"], body_faces),
            (x["garment_template"], x["garment_faces"]),
            fabric=str(x["fabric"]),
        )
        family = str(x["garment_type"]) + ("@hires" if path.name.startswith("r") else "")
        row = anatomy_row(
            x["garment_template"], x["garment_prior"], pred, x["garment_target_gt"], x["body_target"], body_faces
        )
        rows.append((family, row))
    return rows


def oracle_table(oracle: dict[str, dict[str, float]]) -> str:
    """A Markdown table of ``smooth_oracle``'s results: per family the prior's error (mm) and each column's error
    with its ratio to the prior's."""
    columns = [k for k in next(iter(oracle.values())) if k not in ("samples", "prior")]
    lines = ["| family | samples | prior (mm) | " + " | ".join(columns) + " |", "|---|---|---|" + "---|" * len(columns)]
    for family, row in oracle.items():
        cells = [f"{row[k]:.2f} ({row[k] / row['prior']:.2f}x)" for k in columns]
        lines.append(f"| {family} | {row['samples']} | {row['prior']:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def family_table(results: Results, metric: str = "euclidean_mm", fmt: str = ".2f", seen: Sequence[str] = ()) -> str:
    """A Markdown table of one metric: rows the methods, columns 'all' and each family ("-": no samples there);
    families in ``seen`` are marked as trained on."""
    families = sorted({k for per in results.values() for k in per if k != "all"})
    header = ["all", *(f"{k} (trained on)" if k in seen else k for k in families)]
    lines = [f"| {metric} | " + " | ".join(header) + " |", "|---|" + "---|" * len(header)]
    for method, per in results.items():
        cells = [format(per[k][metric], fmt) if k in per else "-" for k in ("all", *families)]
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def external_table(external: dict[str, dict[str, Any]]) -> str:
    """A Markdown table of the external set's mean Euclidean error (mm) per family for each model, prior beside."""
    families = sorted({k for summary in external.values() for k in summary if k != "all"})
    lines = ["| model | " + " | ".join(["all", *families]) + " |", "|---|" + "---|" * (len(families) + 1)]
    for label, summary in external.items():
        cells = [
            f"{summary[k].get('pred', {}).get('euclid_mm', float('nan')):.1f} "
            f"(prior {summary[k]['prior']['euclid_mm']:.1f})"
            if k in summary
            else "-"
            for k in ("all", *families)
        ]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
