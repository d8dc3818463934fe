"""The paper's experiments on a generated dataset: accuracy per garment type against the LBS prior and the
nearest-vertex client (Table 3), with the API's post-processes and refinement beside the raw network, and
fabric awareness on paired groups (Fig. 7: one template in four fabrics, simulated vs predicted).
"""

from __future__ import annotations

import dataclasses
import os
from collections import defaultdict
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from garsim.api import postprocess
from garsim.data.sample import CUSTOM_FABRIC, FABRICS, Sample
from garsim.data.store import DatasetStore
from garsim.eval.metrics import correction_alignment, euclidean_error_mm, garment_metrics, jitter_mm
from garsim.garments.fabrics import interpolate_fabric
from garsim.geometry.proximity import nearest_vertices
from garsim.model.baselines import nearest_vertex_drape

POSTPROCESS_OPTIMISES: dict[str, tuple[str, ...]] = {
    "push": ("collision_pct",),
    "refine": ("hood_collision_pct", "inside_pct", "edge_crossing_pct"),
}
"""Collision metrics each post-process enforces by construction, left out of its rows (the raw network's row
always has them): the push-out moves vertices out along the soft anchor's blend of body vertex normals
(DeePSD's test); refinement projects onto the closest point of the body's triangles (HOOD's and the
winding-number test) and keeps edge samples outside (edge crossings)."""


GROUPS: dict[str, Callable[[Sample], str]] = {
    "family": lambda s: s.garment_type,
    "construction": lambda s: str(s.meta.get("construction", "unknown")),
    "canonical_pose": lambda s: str(s.meta.get("canonical_pose", "unknown")),
    "pose_mode": lambda s: str(s.meta.get("pose_mode", "unknown")),
    "fabric": lambda s: str(s.meta.get("fabric_name", s.fabric)),
    "paired": lambda s: "paired" if s.meta.get("paired") else "single",
}
"""What results can be grouped by (``score_predictions(by=...)``): the garment family, its construction
(template / implicit), the canonical pose (tpose / apose / between), the target pose's sampling mode (everyday /
walk / wide), the fabric name (custom: physical values between the presets) and whether the sample belongs to a
paired-fabric group; "unknown" where a sample's metadata predates the key."""


def sample_groups(sample: Sample, by: Sequence[str]) -> list[str]:
    """The row labels of ``sample`` under each grouping of ``by``: the family as it is, any other ``key=value``;
    a crossed grouping ``a/b`` (e.g. ``family/construction``) gives ``a/b=value_a/value_b``."""
    unknown = sorted({k for key in by for k in key.split("/") if k not in GROUPS})
    if unknown:
        raise ValueError(f"cannot group results by {unknown}; choose from {sorted(GROUPS)}, or cross them as a/b")
    return [
        GROUPS[key](sample) if key == "family" else f"{key}={'/'.join(GROUPS[k](sample) for k in key.split('/'))}"
        for key in by
    ]


def _predict_all(model: Any, samples: list[Sample], batch: int = 16) -> list[np.ndarray]:
    if model is None:
        return [s.prior for s in samples]
    out: list[np.ndarray] = []
    for i in range(0, len(samples), batch):
        out.extend(model.predict(samples[i : i + batch]))
    return out


def _animations(samples: list[Sample]) -> list[list[int]]:
    """Indices (in frame order) of the samples of each sequence of >= 3 consecutive dynamic frames (an
    animation, not independent settled poses): the sequences whose jitter means something."""
    seqs: dict[str, list[int]] = defaultdict(list)
    for i, s in enumerate(samples):
        seqs[s.meta["seq_id"]].append(i)
    runs = []
    for idx in seqs.values():
        idx = sorted(idx, key=lambda i: samples[i].meta["frame"])
        frames = np.array([samples[i].meta["frame"] for i in idx])
        if len(idx) >= 3 and all(samples[idx[0]].meta.get("dynamic") or [False]) and (np.diff(frames) == 1).all():
            runs.append(idx)
    return runs


def evaluate_split(
    model: Any,
    data_dir: str | os.PathLike,
    split: str = "test",
    resolution: str = "low",
    collision_margin: float | None = 0.002,
    refine: bool = False,
    name: str = "garsim",
    baselines: bool = True,
    by: Sequence[str] = ("family",),
) -> dict[str, dict[str, dict[str, float]]]:
    """Mean metrics per garment type (or the groupings ``by``, see ``GROUPS``) and 'all' for the model and for
    the baselines.

    Returns {method: {garment_type: {metric: value, "frames": n}}} with methods ``name`` (the raw network
    output of ``model``, which has ``predict(samples)``), ``name+push`` (with the API's collision post-process,
    when ``collision_margin`` is not None), "prior" (the LBS prior), "nearest" (each vertex moves with its nearest body
    vertex) and "ground truth" (the simulation itself: the reference for normal consistency, smoothness and
    the collision counts, which flag some simulated cloth too on a coarse body mesh); with ``refine`` also
    ``name+refine`` and "prior+refine" (``garsim.refine`` after the network / after the prior alone).
    ``baselines=False`` leaves out the prior, nearest and ground-truth rows (several models scored beside one
    set of them). Metrics as ``score_predictions``.
    """
    samples = DatasetStore(data_dir).samples(split, resolution)
    if not samples:
        raise ValueError(f"{data_dir}: no {split!r} samples to evaluate")
    predictions: dict[str, list[np.ndarray]] = {}
    if baselines:
        predictions = {
            "prior": _predict_all(None, samples),
            "nearest": [nearest_vertex_drape(s) for s in samples],
            "ground truth": [s.target for s in samples],
        }
    if model is not None:
        predictions[name] = _predict_all(model, samples)
        if collision_margin is not None:
            predictions[f"{name}+push"] = [
                postprocess(p, s, collision_margin, refine=False) for p, s in zip(predictions[name], samples)
            ]
        if refine and collision_margin is not None:
            predictions[f"{name}+refine"] = [
                postprocess(p, s, collision_margin) for p, s in zip(predictions[name], samples)
            ]
    if refine and baselines and collision_margin is not None:
        prior = predictions["prior"]
        predictions["prior+refine"] = [postprocess(p, s, collision_margin) for p, s in zip(prior, samples)]
    return score_predictions(samples, predictions, by)


def score_predictions(
    samples: list[Sample], predictions: dict[str, list[np.ndarray]], by: Sequence[str] = ("family",)
) -> dict[str, dict[str, dict[str, float]]]:
    """{method: {group: {metric: mean, "frames": n}}} (and 'all') of each method's predictions of the samples;
    groups are the garment types by default, ``sample_groups``' labels of the groupings ``by`` otherwise.

    Metrics: ``garsim.eval.metrics.GarmentMetrics`` and ``correction_alignment`` (its cosine and gain); a method
    named ``base+post`` (a post-processed row: ``post`` after the last "+") leaves out the collision metrics its
    post-process enforces (``POSTPROCESS_OPTIMISES``). Where the samples hold animations (>= 3 consecutive dynamic
    frames of a sequence) every row also has ``jitter_mm`` (mean over them) and ``sequences``. Methods are ordered
    models first, then "prior", "nearest", "ground truth".
    """
    results: dict[str, dict[str, dict[str, float]]] = {}
    animations = _animations(samples)
    labels = [[*sample_groups(s, by), "all"] for s in samples]  # each sample's rows, the same for every method
    for method in sorted(predictions, key=lambda k: (k in ("prior", "nearest", "ground truth"), k)):
        preds = predictions[method]
        enforced = POSTPROCESS_OPTIMISES.get(method.rpartition("+")[2], ()) if "+" in method else ()
        rows: dict[str, list[dict[str, float]]] = defaultdict(list)
        for s, p, groups in zip(samples, preds, labels):
            row = garment_metrics(p, s.target, s.garment_faces, s.body_target, s.body_faces).as_dict()
            row = {k: v for k, v in row.items() if k not in enforced}
            row["correction_cosine"], row["correction_gain"] = correction_alignment(p, s.prior, s.target)
            for group in groups:
                rows[group].append(row)
        results[method] = {
            kind: {**{k: float(np.mean([r[k] for r in rs])) for k in rs[0]}, "frames": len(rs)}
            for kind, rs in sorted(rows.items())
        }
        jitter: dict[str, list[float]] = defaultdict(list)
        for idx in animations:
            value = jitter_mm(np.stack([preds[i] for i in idx]))
            for group in labels[idx[0]]:
                jitter[group].append(value)
        for kind, values in jitter.items():
            results[method][kind].update(jitter_mm=float(np.mean(values)), sequences=len(values))
    return results


def cluster_bootstrap(
    diff: np.ndarray, clusters: Sequence[str], resamples: int = 2000, seed: int = 0, level: float = 0.95
) -> tuple[float, float, float]:
    """(mean, low, high): the mean of per-sample ``diff`` and its ``level`` percentile interval when whole clusters
    are resampled with replacement (samples of one cluster, e.g. a paired group's fabrics, are not independent)."""
    names, idx = np.unique(np.asarray(clusters), return_inverse=True)
    sums = np.bincount(idx, weights=np.asarray(diff, dtype=np.float64), minlength=len(names))
    counts = np.bincount(idx, minlength=len(names)).astype(np.float64)
    draw = np.random.default_rng(seed).integers(0, len(names), size=(resamples, len(names)))
    means = sums[draw].sum(axis=1) / counts[draw].sum(axis=1)
    tail = 50.0 * (1.0 - level)
    low, high = np.percentile(means, [tail, 100.0 - tail])
    return float(sums.sum() / counts.sum()), float(low), float(high)


def compare_models(
    model: Any,
    other: Any,
    data_dir: str | os.PathLike,
    split: str = "test",
    resolution: str = "low",
    by: Sequence[str] = ("family",),
    resamples: int = 2000,
) -> dict[str, dict[str, float]]:
    """Two models' raw errors on the same samples, per group ('all' first): their means (mm), the mean difference
    ``model - other`` with its 95% bootstrap interval over garment instances (``cluster_bootstrap`` by job), and the
    share of samples on which ``model`` is closer to the simulation. An interval that excludes 0 is a difference
    these samples resolve; one that spans it is not."""
    samples = DatasetStore(data_dir).samples(split, resolution)
    if not samples:
        raise ValueError(f"{data_dir}: no {split!r} samples to evaluate")
    errors = [
        np.array([euclidean_error_mm(p, s.target) for p, s in zip(_predict_all(m, samples), samples)])
        for m in (model, other)
    ]
    diff = errors[0] - errors[1]
    jobs = np.array([str(s.meta.get("job", s.meta["seq_id"])) for s in samples])
    members: dict[str, list[int]] = defaultdict(list)
    for i, s in enumerate(samples):
        for group in ["all", *sample_groups(s, by)]:
            members[group].append(i)
    out = {}
    for group in ["all", *sorted(g for g in members if g != "all")]:
        i = np.asarray(members[group])
        mean, low, high = cluster_bootstrap(diff[i], jobs[i], resamples)
        out[group] = {
            "frames": len(i),
            "model_mm": float(errors[0][i].mean()),
            "other_mm": float(errors[1][i].mean()),
            "diff_mm": mean,
            "diff_low_mm": low,
            "diff_high_mm": high,
            "better_share": float((diff[i] < 0).mean()),
        }
    return out


def format_comparison(table: dict[str, dict[str, float]], model: str, other: str) -> str:
    """A Markdown table of ``compare_models``."""
    lines = [
        f"| group | frames | {model} (mm) | {other} (mm) | difference (mm) | 95% interval | {model} closer |",
        "|---|---|---|---|---|---|---|",
    ]
    for group, r in table.items():
        lines.append(
            f"| {group} | {r['frames']} | {r['model_mm']:.2f} | {r['other_mm']:.2f} | {r['diff_mm']:+.2f} | "
            f"[{r['diff_low_mm']:+.2f}, {r['diff_high_mm']:+.2f}] | {100 * r['better_share']:.0f}% |"
        )
    return "\n".join(lines)


def _distance_and_fold(samples: list[Sample], verts: list[np.ndarray]) -> tuple[list[float], list[float]]:
    """Per sample, the garment ``verts``' mean distance to the target body (mm) and mean fold angle (deg)."""
    from garsim.physics.newton_sim import mean_fold_angle

    distance = [1000.0 * float(nearest_vertices(v, s.body_target)[1].mean()) for s, v in zip(samples, verts)]
    return distance, [mean_fold_angle(v, s.garment_faces) for s, v in zip(samples, verts)]


def paired_groups(data_dir: str | os.PathLike, split: str = "test", resolution: str = "low") -> list[list[Sample]]:
    """The split's complete paired-fabric groups (one template, body and pose), each in ``FABRICS`` order."""
    groups: dict[tuple[str, int], dict[str, Sample]] = defaultdict(dict)
    for rec in DatasetStore(data_dir).sequences(split):
        if rec.meta.get("paired"):
            for s in rec.samples(resolution):
                groups[(rec.meta["job"], s.meta["frame"])][s.fabric] = s
    return [[g[f] for f in FABRICS] for g in groups.values() if set(g) == set(FABRICS)]


def paired_fabric_agreement(
    model: Any,
    data_dir: str | os.PathLike,
    split: str = "test",
    resolution: str = "low",
    min_gap_mm: float = 2.0,
    min_gap_deg: float = 2.0,
    between_tol: float = 0.1,
) -> dict[str, Any]:
    """Fig. 7 on paired groups (one template, four fabrics, same body and pose): simulated vs predicted mean
    distance to the body (mm) and mean fold angle (deg) per fabric, the share of neighbouring fabric pairs
    (silk-cotton, cotton-denim, denim-leather) whose simulated values differ by more than the gap and whose
    predictions are ordered the same way, and the predicted / simulated spread (lightest to stiffest): over the
    groups whose simulated spread passes the gap, sum_g sign(s_g) p_g / sum_g |s_g| with s_g, p_g the simulated and
    predicted spreads (a ratio of means, so a group whose spread barely passes the gap does not weigh more than the
    rest; a predicted spread the wrong way counts against it).
    Also the share of the physical fabrics midway between neighbouring presets (``interpolate_fabric(a, b, 0.5)``)
    whose predicted distance and fold angle lie between the two presets' predictions (within ``between_tol`` mm or
    deg): the model issue's "values between two presets give results between theirs"."""
    complete = paired_groups(data_dir, split, resolution)
    rows, agree, pairs, spread, between = [], 0, 0, [], []
    midway = [interpolate_fabric(a, b, 0.5).values() for a, b in zip(FABRICS[:-1], FABRICS[1:])]
    for samples in complete:
        preds = _predict_all(model, samples)
        mids = [dataclasses.replace(s, fabric=CUSTOM_FABRIC, fabric_values=v) for s, v in zip(samples, midway)]
        sim_d, sim_a = _distance_and_fold(samples, [s.target for s in samples])
        pred_d, pred_a = _distance_and_fold(samples, preds)
        mid_d, mid_a = _distance_and_fold(samples, _predict_all(model, mids))
        for sim, pred, mid, gap in ((sim_d, pred_d, mid_d, min_gap_mm), (sim_a, pred_a, mid_a, min_gap_deg)):
            for i in range(len(FABRICS) - 1):
                if abs(sim[i + 1] - sim[i]) > gap:
                    pairs += 1
                    agree += int(np.sign(pred[i + 1] - pred[i]) == np.sign(sim[i + 1] - sim[i]))
                low, high = sorted((pred[i], pred[i + 1]))
                between.append(low - between_tol <= mid[i] <= high + between_tol)
        if abs(sim_d[-1] - sim_d[0]) > min_gap_mm:
            spread.append((pred_d[-1] - pred_d[0], sim_d[-1] - sim_d[0]))
        rows.append(
            {
                "garment": samples[0].garment_type,
                "name": samples[0].meta.get("name", ""),
                "sim_distance_mm": sim_d,
                "pred_distance_mm": pred_d,
                "sim_fold_deg": sim_a,
                "pred_fold_deg": pred_a,
                "midway_distance_mm": mid_d,
                "midway_fold_deg": mid_a,
            }
        )
    return {
        "groups": len(complete),
        "pairs_over_gap": pairs,
        "ordering_agreement": agree / pairs if pairs else None,
        "spread_ratio": _spread_ratio(spread),
        "midway_between": float(np.mean(between)) if between else None,
        "rows": rows,
    }


def _spread_ratio(spreads: list[tuple[float, float]]) -> float | None:
    """sum sign(s) p / sum |s| over (predicted p, simulated s) spreads; None without any."""
    if not spreads:
        return None
    pred, sim = np.array(spreads, dtype=np.float64).T
    return float(np.sum(np.sign(sim) * pred) / np.sum(np.abs(sim)))


TABLE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("euclidean_mm", "Euclidean error (mm)", ".2f"),
    ("normal_consistency", "normal consistency", ".4f"),
    ("smoothness", "smoothness", ".5f"),
    ("collision_pct", "collision DeePSD (%)", ".2f"),
    ("hood_collision_pct", "collision HOOD (%)", ".2f"),
    ("inside_pct", "inside (%)", ".2f"),
    ("edge_crossing_pct", "edges through body (%)", ".2f"),
    ("edge_length_error_mm", "edge-length error (mm)", ".2f"),
    ("correction_cosine", "correction cos.", ".2f"),
    ("correction_gain", "correction gain", ".2f"),
    ("jitter_mm", "jitter (mm/frame²)", ".3f"),
)
"""(metric key, column header, number format) of ``format_table``, in order."""


def format_table(results: dict[str, dict[str, dict[str, float]]]) -> str:
    """A Markdown table (rows: method x garment type) of every metric ("-": left out of that row; the jitter
    column only where some row has one)."""
    present = {k for per_type in results.values() for m in per_type.values() for k in m}
    cols = [c for c in TABLE_COLUMNS if c[0] != "jitter_mm" or "jitter_mm" in present]
    lines = [
        "| method | garment | frames | " + " | ".join(h for _, h, _ in cols) + " |",
        "|---|---|---|" + "---|" * len(cols),
    ]
    for method, per_type in results.items():
        for kind, m in per_type.items():
            cells = [format(m[k], f) if k in m else "-" for k, _, f in cols]
            lines.append(f"| {method} | {kind} | {m['frames']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_group_table(results: dict[str, dict[str, dict[str, float]]], method: str) -> str:
    """A Markdown table of one method's raw error beside the prior's per group (rows: 'all', then the groups in
    order): frames, prior and method error (mm), their ratio, and the method's inside and edges-through %."""
    prior, model = results["prior"], results[method]
    lines = [
        f"| group | frames | prior (mm) | {method} (mm) | ratio | inside (%) | edges through (%) |",
        "|---|---|---|---|---|---|---|",
    ]
    for group in ["all", *sorted(k for k in model if k != "all")]:
        p, m = prior[group]["euclidean_mm"], model[group]
        lines.append(
            f"| {group} | {m['frames']} | {p:.2f} | {m['euclidean_mm']:.2f} | {m['euclidean_mm'] / p:.3f} | "
            f"{m['inside_pct']:.2f} | {m['edge_crossing_pct']:.2f} |"
        )
    return "\n".join(lines)
