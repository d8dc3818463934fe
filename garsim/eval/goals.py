"""The model issue's acceptance bounds, checked against measured results: which goals a model meets and which it
misses, stated plainly in the results report.

Inputs are the JSON files the project already writes: ``garsim eval --refine --out`` (test / ood tables and the
paired-fabric agreement; at the low resolution and, for the collision bounds, again at the simulated one), the
external check's ``--json`` (API defaults and ``--raw``), and ``garsim bench --out``. A goal whose input is missing is
reported as not measured, never as met. Collision goals carry the simulator's own figure on the same meshes: the
~4x decimated ground truth has edges through the body where the simulated mesh has almost none (long edges chord
across concave parts of the body), so the edge bound is also checked at the simulated resolution.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

Results = Mapping[str, Any]


@dataclass(frozen=True)
class Goal:
    """One acceptance bound and its measured value (``None``: not measured)."""

    name: str
    bound: float
    value: float | None
    at_least: bool = False  # the bound is a minimum (agreement, spread), not a maximum
    unit: str = "x"
    truth: float | None = None  # the ground truth's own value on the same meshes, where it has one

    @property
    def met(self) -> bool | None:
        if self.value is None:
            return None
        return self.value >= self.bound if self.at_least else self.value <= self.bound


def _ratio(table: Results, method: str, family: str) -> float | None:
    """``method``'s mean Euclidean error over the prior's on ``family`` of an eval table."""
    try:
        pred, prior = table[method][family]["euclidean_mm"], table["prior"][family]["euclidean_mm"]
    except KeyError:
        return None
    return pred / prior if prior > 0 else None


def _worst(values: Mapping[str, float | None]) -> tuple[str, float | None]:
    """The key with the largest value (and it), ignoring unmeasured ones."""
    known = {k: v for k, v in values.items() if v is not None}
    if not known:
        return "-", None
    key = max(known, key=known.__getitem__)
    return key, known[key]


def split_goals(results: Results, split: str, overall: float, family: float | None) -> list[Goal]:
    """Accuracy of the raw network on one split of ``garsim eval`` (ratio to the prior), and its collisions."""
    table = results.get(split)
    overall_goal = f"{split} split: raw network / prior, all families"
    if table is None:
        return [Goal(overall_goal, overall, None)]
    goals = [Goal(overall_goal, overall, _ratio(table, "garsim", "all"))]
    if family is not None:  # the garment types (a table grouped otherwise has keys like "fabric=silk")
        families = {f: _ratio(table, "garsim", f) for f in table.get("prior", {}) if f != "all" and "=" not in f}
        worst, value = _worst(families)
        goals.append(Goal(f"{split} split: worst family ({worst})", family, value))
    return goals + collision_goals(table, f"{split} split")


def collision_goals(table: Results | None, label: str) -> list[Goal]:
    """The raw network's vertices inside the body and edges through it on an eval table, beside the truth's."""
    raw = (table or {}).get("garsim", {}).get("all", {})
    truth = (table or {}).get("ground truth", {}).get("all", {})
    return [
        Goal(f"{label}: raw network, {what}", bound, raw.get(key), unit="%", truth=truth.get(key))
        for what, bound, key in (
            ("vertices inside the body", 1.5, "inside_pct"),
            ("edges through the body", 1.0, "edge_crossing_pct"),
        )
    ]


def _complete(group: Results) -> bool:
    """Whether every drape of a group of the external check was predicted (check.py scores only those that were)."""
    return group.get("predicted", group.get("n")) == group.get("n")


def external_goals(defaults: Results | None, raw: Results | None) -> list[Goal]:
    """The external check set: API defaults overall and per garment type, and the raw network's collisions; a
    group in which some drape failed is not measured."""
    summary = (defaults or {}).get("summary", {})
    types = {k: s.get("ratio") if _complete(s) else None for k, s in summary.items() if k != "all"}
    worst, value = _worst(types)
    failed = sorted(k for k, s in summary.items() if k != "all" and not _complete(s))
    if failed:
        worst, value = "drapes failed: " + ", ".join(failed), None
    all_ = summary.get("all", {})
    raw_group = (raw or {}).get("summary", {}).get("all", {})
    raw_all = raw_group.get("pred", {}) if _complete(raw_group) else {}
    return [
        Goal("external set: API defaults / prior, all", 0.6, all_.get("ratio") if _complete(all_) else None),
        Goal(f"external set: worst garment type ({worst})", 0.85, value),
        Goal("external set: raw network, vertices inside the body", 1.5, raw_all.get("inside_pct"), unit="%"),
        Goal("external set: raw network, edges through the body", 1.0, raw_all.get("edge_crossing_pct"), unit="%"),
    ]


def fabric_goals(results: Results) -> list[Goal]:
    """Paired fabric groups of the test split: ordering agreement and predicted / simulated spread."""
    fab = results.get("paired_fabrics") or {}
    return [
        Goal("paired fabrics: ordering agreement", 0.9, fab.get("ordering_agreement"), at_least=True, unit=""),
        Goal("paired fabrics: predicted / simulated spread", 0.6, fab.get("spread_ratio"), at_least=True, unit=""),
        Goal(
            "paired fabrics: midway fabrics predicted between the presets",
            1.0,
            fab.get("midway_between"),
            at_least=True,
            unit="",
        ),
    ]


def speed_goals(bench: Results | None) -> list[Goal]:
    """``garsim bench``: the network forward at 600 and 2,400 vertices and a new-pose drape at 600 (one thread)."""
    rows = (bench or {}).get("garsim", {})

    def ms(size: str, key: str) -> float | None:
        return rows.get(size, {}).get(key)

    return [
        Goal("forward, ~600 vertices", 12.0, ms("600", "forward_cpu_ms"), unit=" ms"),
        Goal("forward, ~2,400 vertices", 35.0, ms("2400", "forward_cpu_ms"), unit=" ms"),
        Goal("new-pose drape, ~600 vertices", 25.0, ms("600", "api_new_pose_cpu_ms"), unit=" ms"),
    ]


def robustness_goals(robustness: Results | None) -> list[Goal]:
    """``examples/robustness.py --json``: per set of templates, the largest change of any output vertex under the
    stability checks (noise, file round trip, permutations) and the equivariance checks (turns, a 10 m move), and
    the worst template's mean displacement at rest (target body = canonical body), through the API's defaults."""
    sets = (robustness or {}).get("sets")
    if not sets:
        return [
            Goal(f"templates: {what}", bound, None, unit=" mm")
            for what, bound in (("stability", 0.5), ("equivariance", 0.5), ("rest", 3.0))
        ]
    goals = []
    for source, measured in sets.items():
        label = "external set" if source == robustness.get("external") else source.rstrip("/").rsplit("/", 1)[-1]
        summary = measured["summary"]["all"]
        goals += [
            Goal(f"{label}: stability, largest change", 0.5, summary["stability_max_mm"], unit=" mm"),
            Goal(f"{label}: equivariance, largest change", 0.5, summary["equivariance_max_mm"], unit=" mm"),
            Goal(f"{label}: rest, worst mean displacement", 3.0, summary["rest_max_mm"], unit=" mm"),
        ]
    return goals


def model_goals(
    results: Results,
    external_default: Results | None = None,
    external_raw: Results | None = None,
    bench: Results | None = None,
    full: Results | None = None,
    robustness: Results | None = None,
) -> list[Goal]:
    """Every measurable bound of the model issue's acceptance list, in its order; ``full``: ``garsim eval
    --resolution full`` results, for the collision bounds at the simulated resolution; ``robustness``:
    ``examples/robustness.py --json``."""
    return [
        *robustness_goals(robustness),
        *split_goals(results, "test", overall=0.4, family=0.6),
        *split_goals(results, "ood", overall=0.6, family=None),
        *(
            g
            for split in ("test", "ood")
            for g in collision_goals((full or {}).get(split), f"{split} split, full res.")
        ),
        *external_goals(external_default, external_raw),
        *fabric_goals(results),
        *speed_goals(bench),
    ]


def format_goals(goals: list[Goal]) -> str:
    """A markdown table: goal, bound, measured, the ground truth's own value, met / missed / not measured."""
    lines = ["| goal | bound | measured | ground truth | |", "|---|---|---|---|---|"]
    for g in goals:
        bound = f"{'>=' if g.at_least else '<='} {g.bound:g}{g.unit}"
        value, truth = ("-" if v is None else f"{v:.3g}{g.unit}" for v in (g.value, g.truth))
        verdict = {None: "not measured", True: "met", False: "**missed**"}[g.met]
        lines.append(f"| {g.name} | {bound} | {value} | {truth} | {verdict} |")
    met = sum(g.met is True for g in goals)
    missed = sum(g.met is False for g in goals)
    return "\n".join(lines) + f"\n\n{met} met, {missed} missed, {len(goals) - met - missed} not measured."
