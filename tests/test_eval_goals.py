"""garsim.eval.goals: the model issue's bounds checked against hand-made results, and the report that states them."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from garsim.eval.experiments import evaluate_split
from garsim.eval.goals import Goal, format_goals, model_goals

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "fixtures" / "dataset_v2"


def _row(mm: float, inside: float = 0.0, through: float = 0.0) -> dict:
    return {"euclidean_mm": mm, "inside_pct": inside, "edge_crossing_pct": through}


def _results() -> dict:
    """A test split where the network is at 0.3x the prior overall, 0.5x on skirts and 0.75x on tops."""
    return {
        "test": {
            "garsim": {"all": _row(12.0, inside=1.0, through=2.0), "skirt": _row(20.0), "top": _row(15.0)},
            "prior": {"all": _row(40.0), "skirt": _row(40.0), "top": _row(20.0)},
        },
        "paired_fabrics": {"ordering_agreement": 0.95, "spread_ratio": 0.1},
    }


def _external(ratios: dict[str, float], inside: float = 0.0, through: float = 0.0) -> dict:
    summary = {k: {"ratio": r, "pred": {"inside_pct": inside, "edge_crossing_pct": through}} for k, r in ratios.items()}
    return {"summary": summary}


def _by_name(goals: list[Goal]) -> dict[str, Goal]:
    return {g.name: g for g in goals}


def test_goals_from_hand_made_results():
    bench = {"garsim": {"600": {"forward_cpu_ms": 5.0, "api_new_pose_cpu_ms": 30.0}, "2400": {"forward_cpu_ms": 17}}}
    goals = _by_name(
        model_goals(
            _results(),
            _external({"skirt": 0.7, "tshirt": 1.2, "all": 0.8}),
            _external({"all": 0.9}, inside=2.0, through=0.5),
            bench,
        )
    )
    overall = goals["test split: raw network / prior, all families"]
    assert overall.value == pytest.approx(0.3) and overall.met
    worst = goals["test split: worst family (top)"]  # 15 / 20 beats skirt's 20 / 40 as the worst
    assert worst.value == pytest.approx(0.75) and worst.met is False
    assert goals["test split: raw network, vertices inside the body"].met  # 1.0 <= 1.5
    assert goals["test split: raw network, edges through the body"].met is False  # 2.0 > 1.0
    assert goals["external set: API defaults / prior, all"].value == 0.8
    assert goals["external set: worst garment type (tshirt)"].met is False
    assert goals["external set: raw network, vertices inside the body"].met is False  # the raw file, not defaults
    assert goals["external set: raw network, edges through the body"].met
    assert goals["paired fabrics: ordering agreement"].met  # a minimum: 0.95 >= 0.9
    assert goals["paired fabrics: predicted / simulated spread"].met is False  # 0.1 < 0.6
    assert goals["forward, ~600 vertices"].met and goals["forward, ~2,400 vertices"].met
    assert goals["new-pose drape, ~600 vertices"].met is False  # 30 > 25 ms
    assert goals["ood split: raw network / prior, all families"].met is None  # no ood table: not measured


def test_collision_goals_at_the_simulated_resolution_carry_the_truths_own_figure():
    low = _results()
    low["test"]["ground truth"] = {"all": _row(0.0, inside=0.1, through=2.5)}
    full = {"test": {"garsim": {"all": _row(10.0, inside=0.2, through=0.4)}, "ground truth": {"all": _row(0.0)}}}
    goals = _by_name(model_goals(low, full=full))
    through_low = goals["test split: raw network, edges through the body"]
    assert through_low.met is False and through_low.truth == 2.5  # the decimated truth misses the bound itself
    through_full = goals["test split, full res.: raw network, edges through the body"]
    assert through_full.value == 0.4 and through_full.met and through_full.truth == 0.0
    assert goals["ood split, full res.: raw network, vertices inside the body"].met is None  # no ood table
    assert "| test split: raw network, edges through the body | <= 1% | 2% | 2.5% | **missed** |" in format_goals(
        list(goals.values())
    )


def test_robustness_goals_per_set_of_templates():
    def summary(stability: float, equivariance: float, rest: float) -> dict:
        all_ = {"stability_max_mm": stability, "equivariance_max_mm": equivariance, "rest_max_mm": rest}
        return {"summary": {"all": all_}}

    robustness = {
        "external": "/x/external-eval/data",
        "sets": {"tests/fixtures/dataset_v2": summary(0.1, 0.05, 1.3), "/x/external-eval/data": summary(0.7, 0.2, 4.0)},
    }
    goals = _by_name(model_goals({}, robustness=robustness))
    assert goals["dataset_v2: stability, largest change"].met and goals["dataset_v2: rest, worst mean displacement"].met
    assert goals["external set: stability, largest change"].met is False  # 0.7 > 0.5 mm
    assert goals["external set: equivariance, largest change"].met
    assert goals["external set: rest, worst mean displacement"].met is False  # 4 > 3 mm


def test_external_groups_with_failed_drapes_are_not_measured():
    """check.py scores only the drapes that ran: a type where some failed is not measured, nor is the overall ratio
    or the raw network's collisions when a drape of the raw run failed."""
    defaults = _external({"all": 0.55, "skirt": 0.5, "top": 0.9})
    defaults["summary"]["all"].update(n=31, predicted=20)
    defaults["summary"]["top"].update(n=5, predicted=0)
    defaults["summary"]["skirt"].update(n=8, predicted=8)
    raw = _external({"all": 0.6})
    raw["summary"]["all"].update(n=31, predicted=30)
    goals = _by_name(model_goals({}, defaults, raw))
    assert goals["external set: API defaults / prior, all"].met is None
    assert goals["external set: worst garment type (drapes failed: top)"].met is None
    assert goals["external set: raw network, vertices inside the body"].met is None
    whole = _external({"all": 0.55, "skirt": 0.5})
    for group in whole["summary"].values():
        group.update(n=8, predicted=8)
    assert _by_name(model_goals({}, whole, None))["external set: worst garment type (skirt)"].met


def test_the_worst_family_is_a_garment_type_whatever_else_the_table_groups():
    results = _results()
    for method in ("garsim", "prior"):
        results["test"][method]["fabric=silk"] = _row(30.0 if method == "garsim" else 31.0)
    assert "test split: worst family (top)" in _by_name(model_goals(results))


def test_missing_inputs_are_not_measured_never_met():
    goals = model_goals({})
    assert goals and all(g.value is None and g.met is None for g in goals)
    table = format_goals(goals)
    assert "| met |" not in table and table.endswith(f"0 met, 0 missed, {len(goals)} not measured.")


def test_format_goals_marks_each_verdict():
    table = format_goals(
        [Goal("a", 0.4, 0.3), Goal("b", 0.6, 0.7), Goal("c", 0.9, 0.95, at_least=True, unit=""), Goal("d", 1, None)]
    )
    lines = table.splitlines()
    assert lines[2] == "| a | <= 0.4x | 0.3x | - | met |"
    assert lines[3] == "| b | <= 0.6x | 0.7x | - | **missed** |"
    assert lines[4] == "| c | >= 0.9 | 0.95 | - | met |"
    assert lines[5] == "| d | <= 1x | - | - | not measured |"
    assert lines[-1] == "2 met, 1 missed, 1 not measured."


def test_studies_index_lists_every_report_readme_first(tmp_path):
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        from make_report import studies_index
    finally:
        sys.path.pop(0)
    folder = tmp_path / "studies"
    folder.mkdir()
    (folder / "b.md").write_text("intro\n# Second study\ntext\n")
    (folder / "README.md").write_text("# Index\n")
    (folder / "a.md").write_text("no heading\n")
    assert studies_index(folder).splitlines() == [
        "- [Index](studies/README.md)",
        "- [a](studies/a.md)",
        "- [Second study](studies/b.md)",
    ]


def test_make_report_writes_goals_from_the_committed_results(tmp_path):
    """The report script end to end on the fixture dataset and the committed result files."""
    docs = tmp_path / "docs"
    (docs / "studies").mkdir(parents=True)
    (docs / "studies" / "x.md").write_text("# A study\n")
    cmd = [sys.executable, str(ROOT / "examples" / "make_report.py"), "--data", str(ROOT / "tests/fixtures/dataset_v2")]
    cmd += ["--results", str(ROOT / "docs/results.json"), "--docs", str(docs)]
    cmd += ["--results-full", str(ROOT / "docs/results_full.json")]
    cmd += ["--external-default", str(ROOT / "docs/external_default.json"), "--bench", str(ROOT / "docs/bench.json")]
    cmd += ["--robustness", str(ROOT / "docs/robustness.json")]
    by = {"by": ["canonical_pose"], "test": evaluate_split(None, FIXTURE, "test", by=("canonical_pose",))}
    (tmp_path / "by.json").write_text(json.dumps(by))
    cmd += ["--results-by", str(tmp_path / "by.json")]
    subprocess.run(cmd, check=True, cwd=ROOT, capture_output=True)
    report = (docs / "results.md").read_text()
    assert "## Goals of the model issue" in report and "**missed**" in report
    assert "## test split at the simulated resolution" in report and "test split, full res.:" in report
    assert "- [A study](studies/x.md)" in report and (docs / "test_predictions.png").exists()
    assert "## test split by canonical_pose (raw network)" in report and "| canonical_pose=" in report
    assert "## Stability, equivariance and rest" in report and "external set: rest, worst mean displacement" in report
