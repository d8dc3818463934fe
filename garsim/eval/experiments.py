"""The paper's experiments on a generated dataset: accuracy per garment type against the LBS prior (Table 3)
with the API's post-processes and refinement beside the raw network, and fabric awareness on paired groups
(Fig. 7: one template in four fabrics, simulated vs predicted).
"""

from __future__ import annotations

import os
from collections import defaultdict
from typing import Any

import numpy as np

from garsim.api import postprocess
from garsim.data.sample import FABRICS, Sample
from garsim.data.store import DatasetStore
from garsim.eval.metrics import garment_metrics
from garsim.geometry.proximity import nearest_vertices


def _predict_all(model: Any, samples: list[Sample], batch: int = 16) -> list[np.ndarray]:
    if model is None:
        return [s.prior for s in samples]
    out: list[np.ndarray] = []
    for i in range(0, len(samples), batch):
        out.extend(model.predict(samples[i : i + batch]))
    return out


def evaluate_split(
    model: Any,
    data_dir: str | os.PathLike,
    split: str = "test",
    resolution: str = "low",
    collision_margin: float | None = 0.002,
    refine: bool = False,
) -> dict[str, dict[str, dict[str, float]]]:
    """Mean metrics per garment type (and 'all') for the model and for the prior baseline.

    Returns {method: {garment_type: {metric: value, "frames": n}}} with methods "garsim" (raw network
    output), "garsim+push" (with the API's collision post-process, when ``collision_margin``), "prior",
    and "ground truth" (the simulation itself: the reference for normal consistency, smoothness and
    the collision count, which flags some simulated cloth too on a coarse body mesh); with ``refine`` also
    "garsim+refine" and "prior+refine" (``garsim.refine`` after the network / after the prior alone).
    """
    samples = DatasetStore(data_dir).samples(split, resolution)
    if not samples:
        raise ValueError(f"{data_dir}: no {split!r} samples to evaluate")
    results: dict[str, dict[str, dict[str, float]]] = {}
    predictions = {"prior": _predict_all(None, samples), "ground truth": [s.target for s in samples]}
    if model is not None:
        predictions["garsim"] = _predict_all(model, samples)
        if collision_margin is not None:
            predictions["garsim+push"] = [
                postprocess(p, s, collision_margin, refine=False) for p, s in zip(predictions["garsim"], samples)
            ]
        if refine:
            predictions["garsim+refine"] = [postprocess(p, s) for p, s in zip(predictions["garsim"], samples)]
    if refine:
        predictions["prior+refine"] = [postprocess(p, s) for p, s in zip(predictions["prior"], samples)]
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


def paired_fabric_agreement(
    model: Any,
    data_dir: str | os.PathLike,
    split: str = "test",
    resolution: str = "low",
    min_gap_mm: float = 2.0,
    min_gap_deg: float = 2.0,
) -> dict[str, Any]:
    """Fig. 7 on paired groups (one template, four fabrics, same body and pose): simulated vs predicted mean
    distance to the body (mm) and mean fold angle (deg) per fabric, the share of neighbouring fabric pairs
    (silk-cotton, cotton-denim, denim-leather) whose simulated values differ by more than the gap and whose
    predictions are ordered the same way, and the predicted / simulated spread (lightest to stiffest)."""
    from garsim.physics.newton_sim import mean_fold_angle

    store = DatasetStore(data_dir)
    groups: dict[tuple[str, int], dict[str, Sample]] = defaultdict(dict)
    for rec in store.sequences(split):
        if rec.meta.get("paired"):
            for s in rec.samples(resolution):
                groups[(rec.meta["job"], s.meta["frame"])][s.fabric] = s
    complete = [g for g in groups.values() if set(g) == set(FABRICS)]
    rows, agree, pairs, spread = [], 0, 0, []
    for g in complete:
        samples = [g[f] for f in FABRICS]
        preds = _predict_all(model, samples)
        sim_d = [1000.0 * float(nearest_vertices(s.target, s.body_target)[1].mean()) for s in samples]
        pred_d = [1000.0 * float(nearest_vertices(p, s.body_target)[1].mean()) for s, p in zip(samples, preds)]
        sim_a = [mean_fold_angle(s.target, s.garment_faces) for s in samples]
        pred_a = [mean_fold_angle(p, s.garment_faces) for s, p in zip(samples, preds)]
        for sim, pred, gap in ((sim_d, pred_d, min_gap_mm), (sim_a, pred_a, min_gap_deg)):
            for i in range(len(FABRICS) - 1):
                if abs(sim[i + 1] - sim[i]) > gap:
                    pairs += 1
                    agree += int(np.sign(pred[i + 1] - pred[i]) == np.sign(sim[i + 1] - sim[i]))
        if abs(sim_d[-1] - sim_d[0]) > min_gap_mm:
            spread.append((pred_d[-1] - pred_d[0]) / (sim_d[-1] - sim_d[0]))
        rows.append(
            {
                "garment": samples[0].garment_type,
                "name": samples[0].meta.get("name", ""),
                "sim_distance_mm": sim_d,
                "pred_distance_mm": pred_d,
                "sim_fold_deg": sim_a,
                "pred_fold_deg": pred_a,
            }
        )
    return {
        "groups": len(complete),
        "pairs_over_gap": pairs,
        "ordering_agreement": agree / pairs if pairs else None,
        "spread_ratio": float(np.mean(spread)) if spread else None,
        "rows": rows,
    }


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
