"""The paper's experiments on a generated dataset: accuracy per garment type against the LBS
prior (Table 3), fabric awareness (Fig. 7), and generalisation to unseen garment types.
"""

from __future__ import annotations

import dataclasses
import os
from collections import defaultdict
from typing import Any

import numpy as np

from garsim.data.sample import FABRICS, Sample
from garsim.data.store import DatasetStore
from garsim.eval.metrics import garment_metrics
from garsim.geometry.mesh import vertex_normals
from garsim.geometry.proximity import nearest_vertices, push_outside


def _predict_all(model: Any, samples: list[Sample], batch: int = 16) -> list[np.ndarray]:
    if model is None:
        return [s.prior for s in samples]
    out: list[np.ndarray] = []
    for i in range(0, len(samples), batch):
        out.extend(model.predict(samples[i : i + batch]))
    return out


def _pushed(preds: list[np.ndarray], samples: list[Sample], margin: float) -> list[np.ndarray]:
    """The API's collision post-process applied to raw predictions."""
    return [
        push_outside(p, s.body_target, vertex_normals(s.body_target, s.body_faces), margin)
        for p, s in zip(preds, samples)
    ]


def evaluate_split(
    model: Any,
    data_dir: str | os.PathLike,
    split: str = "test",
    resolution: str = "low",
    collision_margin: float | None = 0.002,
) -> dict[str, dict[str, dict[str, float]]]:
    """Mean metrics per garment type (and 'all') for the model and for the prior baseline.

    Returns {method: {garment_type: {metric: value, "frames": n}}} with methods "garsim" (raw network
    output), "garsim+push" (with the API's collision post-process, when ``collision_margin``), "prior",
    and "ground truth" (the simulation itself: the reference for normal consistency, smoothness and
    the collision count, which flags some simulated cloth too on a coarse body mesh).
    """
    samples = DatasetStore(data_dir).samples(split, resolution)
    if not samples:
        raise ValueError(f"{data_dir}: no {split!r} samples to evaluate")
    results: dict[str, dict[str, dict[str, float]]] = {}
    predictions = {"prior": _predict_all(None, samples), "ground truth": [s.target for s in samples]}
    if model is not None:
        predictions["garsim"] = _predict_all(model, samples)
        if collision_margin is not None:
            predictions["garsim+push"] = _pushed(predictions["garsim"], samples, collision_margin)
    for name in sorted(predictions, key=lambda k: (k in ("prior", "ground truth"), k)):
        preds = predictions[name]
        rows: dict[str, list[dict[str, float]]] = defaultdict(list)
        for s, p in zip(samples, preds):
            row = garment_metrics(p, s.target, s.garment_faces, s.body_target, s.body_faces).as_dict()
            rows[s.garment_type].append(row)
            rows["all"].append(row)
        results[name] = {
            kind: {**{k: float(np.mean([r[k] for r in rs])) for k in rs[0]}, "frames": len(rs)}
            for kind, rs in sorted(rows.items())
        }
    return results


def fabric_awareness(
    model: Any,
    data_dir: str | os.PathLike,
    split: str = "test",
    garment_type: str = "skirt",
    resolution: str = "low",
    max_samples: int = 200,
) -> dict[str, float]:
    """Fig. 7: predict the same test garments in every fabric; mean garment-to-body distance (mm).

    Only the final (settled) frame of each sequence is used, as the paper compares drapes.
    """
    store = DatasetStore(data_dir)
    samples = [rec.samples(resolution)[-1] for rec in store.sequences(split) if rec.garment_type == garment_type]
    samples = samples[:max_samples]
    if not samples:
        raise ValueError(f"{data_dir}: no {garment_type} in the {split!r} split")
    out = {}
    for fabric in FABRICS:
        variants = [dataclasses.replace(s, fabric=fabric) for s in samples]
        preds = _predict_all(model, variants)
        dist = [nearest_vertices(p, s.body_target)[1].mean() for s, p in zip(variants, preds)]
        out[fabric] = 1000.0 * float(np.mean(dist))
    return out


def ground_truth_fabric_distances(
    data_dir: str | os.PathLike, split: str = "test", garment_type: str = "skirt", resolution: str = "low"
) -> dict[str, float]:
    """Mean garment-to-body distance (mm) of the simulated final frames per fabric (the reference)."""
    store = DatasetStore(data_dir)
    dist: dict[str, list[float]] = defaultdict(list)
    for rec in store.sequences(split):
        if rec.garment_type == garment_type:
            s = rec.samples(resolution)[-1]
            dist[s.fabric].append(float(nearest_vertices(s.target, s.body_target)[1].mean()))
    return {f: 1000.0 * float(np.mean(dist[f])) for f in FABRICS if dist[f]}


def format_table(results: dict[str, dict[str, dict[str, float]]]) -> str:
    """A Markdown table (rows: method x garment type) of the four metrics."""
    lines = [
        "| method | garment | frames | Euclidean error (mm) | normal consistency | smoothness | collision (%) |",
        "|---|---|---|---|---|---|---|",
    ]
    for method, per_type in results.items():
        for kind, m in per_type.items():
            lines.append(
                f"| {method} | {kind} | {m['frames']} | {m['euclidean_mm']:.2f} | "
                f"{m['normal_consistency']:.4f} | {m['smoothness']:.5f} | {m['collision_pct']:.2f} |"
            )
    return "\n".join(lines)
