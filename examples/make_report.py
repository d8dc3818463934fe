"""Write docs/results.md (and its figures) from a trained model's measured results: the model issue's goals, met
or missed (``garsim.eval.goals``), the training curve, the test / ood tables of `garsim eval --refine --out`, the
paired-fabric agreement, the external check (API defaults and raw network, from check.py --json), the speed bench,
error maps of test samples (prior, prediction, ground truth), the stability, equivariance and rest checks
(examples/robustness.py --json) and an index of the studies in docs/studies/.

Run: .venv/bin/python examples/make_report.py --run ~/garsim-runs/v1 --data ~/garsim-data/v4test \
    --results docs/results.json --external-default docs/external_default.json \
    --external-raw docs/external_raw.json --bench docs/bench.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from garsim.api import GarSim
from garsim.data.store import DatasetStore
from garsim.eval.experiments import POSTPROCESS_OPTIMISES, format_group_table, format_table
from garsim.eval.goals import format_goals, model_goals, speed_goals
from garsim.eval.plots import plot_paired_fabrics, plot_training_curve
from garsim.eval.robustness import CHECKS
from garsim.geometry.render import render_grid


def _external_table(paths: list[Path], raw: Path | None) -> str:
    """check.py's summaries, one row per run and garment type; in the post-processed runs (all but ``raw``: the API
    defaults refine) the tests the refinement enforces are left out ("-")."""
    enforced = POSTPROCESS_OPTIMISES["refine"]
    lines = [
        "Runs other than the raw network's end in the API's refinement, which enforces the inside and edge tests: "
        "those columns are the raw network's alone.",
        "",
        "| run | garment | n | prior mm | pred mm | ratio | coll. % | inside % | edges through % |",
        "|" + "---|" * 9,
    ]
    for path in paths:
        summary = json.loads(path.read_text())["summary"]
        for kind, s in summary.items():
            p = s.get("pred", {})
            cells = [
                "-" if path != raw and key in enforced else f"{p.get(key, float('nan')):.2f}"
                for key in ("collision_pct", "inside_pct", "edge_crossing_pct")
            ]
            lines.append(
                f"| {path.stem} | {kind} | {s['n']} | {s['prior']['euclid_mm']:.1f} | "
                f"{p.get('euclid_mm', float('nan')):.1f} | {s.get('ratio', float('nan')):.2f} | {' | '.join(cells)} |"
            )
    return "\n".join(lines)


def _robustness_section(robustness: dict, path: str) -> str:
    """Per set of templates and garment type: the largest change under each check and the rest displacement."""
    model = robustness["model"]
    sources = " ".join(f"--data {s}" for s in robustness["sets"] if s != robustness.get("external"))
    external = f" --external {robustness['external']}" if robustness.get("external") else ""
    if robustness.get("wide_poses") is not None:
        sources += f" --wide-poses {robustness['wide_poses']}"
    checks = list(CHECKS)
    lines = [
        "## Stability, equivariance and rest (API defaults)",
        f"`OMP_NUM_THREADS=1 python examples/robustness.py --model {model} {sources}{external} --json {path}`: the "
        "largest change (mm) of any output vertex when the input is perturbed and the perturbation undone "
        "(`garsim.eval.robustness`), and the mean displacement (mm) of each template draped onto its own canonical "
        "body (worst and mean over the templates).",
        "",
        "| templates | garment | n | " + " | ".join(checks) + " | rest, worst | rest, mean |",
        "|" + "---|" * (len(checks) + 5),
    ]
    for source, measured in robustness["sets"].items():
        for group, s in measured["summary"].items():
            values = " | ".join(f"{s[c]:.3f}" for c in checks)
            lines.append(
                f"| {source} | {group} | {s['n']} | {values} | {s['rest_max_mm']:.2f} | {s['rest_mean_mm']:.2f} |"
            )
    return "\n".join(lines)


def _load(path: str | None) -> dict | None:
    return json.loads(Path(path).read_text()) if path else None


def studies_index(folder: Path) -> str:
    """One line per study report in ``folder``: its title (first heading) and file, README first."""
    files = sorted(folder.glob("*.md"), key=lambda f: (f.name != "README.md", f.name))
    lines = []
    for f in files:
        title = next((ln.lstrip("# ").strip() for ln in f.read_text().splitlines() if ln.startswith("#")), f.stem)
        lines.append(f"- [{title}]({folder.name}/{f.name})")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument(
        "--run", nargs="*", default=[], help="training run folder(s) (log.csv), stages in order; none: keep the curve"
    )
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--data", required=True)
    parser.add_argument("--results", required=True, help="JSON written by `garsim eval --refine --out`")
    parser.add_argument("--results-full", help="`garsim eval --resolution full --out` (collisions at full resolution)")
    parser.add_argument("--results-by", help="`garsim eval --by KEY... --out` (the error per construction, pose, ...)")
    parser.add_argument("--external-default", help="check.py --json with the API defaults")
    parser.add_argument("--external-raw", help="examples/external_check.py --raw --json (the raw network)")
    parser.add_argument("--external", nargs="*", default=[], help="further check.py --json files for the table")
    parser.add_argument("--bench", help="JSON written by `garsim bench --out`")
    parser.add_argument("--robustness", help="JSON written by examples/robustness.py (stability, equivariance, rest)")
    parser.add_argument("--docs", default="docs")
    args = parser.parse_args()
    docs = Path(args.docs)
    curve = docs / "training_curve.png"
    if args.run:
        plot_training_curve([Path(r) / "log.csv" for r in args.run], curve)
    results, bench, full = _load(args.results), _load(args.bench), _load(args.results_full)
    robustness = _load(args.robustness)
    sim = GarSim.load(args.model) if args.model else GarSim.pretrained()
    store = DatasetStore(args.data)
    by_family: dict[str, list] = {}
    for rec in store.sequences("test"):
        by_family.setdefault(rec.garment_type, []).append(rec)
    rng = np.random.default_rng(0)
    pick = [recs[rng.integers(len(recs))] for _, recs in sorted(by_family.items())]  # one of every family
    panels, titles, colors = [], [], []
    for rec in pick:
        s = rec.samples("low")[-1]
        pred = sim.model.predict(s)
        for name, verts in (("prior", s.prior), ("GarSim (raw)", pred), ("ground truth", s.target)):
            err = 1000 * np.linalg.norm(verts - s.target, axis=1)
            panels.append([(s.body_target, s.body_faces), (verts, s.garment_faces)])
            truth = name == "ground truth"  # drawn uncoloured, without an error
            colors.append([None, None if truth else err])
            titles.append(f"{rec.garment_type}/{rec.fabric} {name}" + ("" if truth else f": {err.mean():.0f} mm"))
    maps = render_grid(
        docs / "test_predictions.png",
        panels,
        ncols=3,
        titles=titles,
        views=("front",),
        colors=colors,
        suptitle="Test split, one sample of every family: error to Newton per vertex",
        vmin=0.0,
        vmax=100.0,
        colorbar_label="error to Newton (mm; 100 and above at the top)",
    )
    parts = [
        f"# GarSim results\n\nModel: `{results['model']}`; data: `{args.data}` ({results['resolution']} resolution).",
        f"Training curve: `{curve.name}`. Error maps of random test samples: `{maps.name}`.",
        "## Goals of the model issue (raw network unless stated)\n"
        + format_goals(
            model_goals(results, _load(args.external_default), _load(args.external_raw), bench, full, robustness)
        ),
    ]
    splits = [split for split in ("test", "ood") if split in results]
    model_arg = f" --model {args.model}" if args.model else ""
    command = f"garsim eval --data {args.data}{model_arg} --splits {' '.join(splits)} --refine --out {args.results}"
    for split in splits:
        parts.append(f"## {split} split\n`{command}`\n\n" + format_table(results[split]))
    full_command = f"garsim eval --data {args.data}{model_arg} --resolution full --out {args.results_full}"
    for split in [split for split in ("test", "ood") if split in (full or {})]:
        parts.append(f"## {split} split at the simulated resolution\n`{full_command}`\n\n" + format_table(full[split]))
    by = _load(args.results_by)
    for split in [split for split in ("test", "ood") if split in (by or {})]:
        by_command = f"garsim eval --data {args.data}{model_arg} --splits {split} --by {' '.join(by['by'])}"
        parts.append(
            f"## {split} split by {', '.join(by['by'])} (raw network)\n`{by_command} --out {args.results_by}`\n\n"
            + format_group_table(by[split], next(iter(by[split])))
        )
    fab = results.get("paired_fabrics")
    if fab:
        fab_png = plot_paired_fabrics(fab, docs / "paired_fabrics.png")
        parts.append(
            f"## Paired fabrics (test)\n{fab['groups']} groups; ordering agreement "
            f"{fab['ordering_agreement']:.2f} over {fab['pairs_over_gap']} neighbouring pairs whose simulated values "
            f"differ by more than 2 mm / 2 deg; predicted / simulated spread {fab['spread_ratio']:.3f}; a fabric "
            f"midway between neighbouring presets (physical values) predicted between them in "
            f"{fab['midway_between']:.1%} of the distance and fold checks. Per group: "
            f"`{fab_png.name}`."
        )
    if robustness:
        parts.append(_robustness_section(robustness, args.robustness))
    external = [Path(p) for p in (args.external_default, args.external_raw, *args.external) if p]
    if external:
        raw = Path(args.external_raw) if args.external_raw else None
        parts.append("## External check set (`../shared/external-eval/check.py`)\n" + _external_table(external, raw))
    if bench:
        parts.append(
            f"## Speed\n`OMP_NUM_THREADS=1 garsim bench --model garsim/weights --sizes 600 2400 10000 40000 "
            f"--garment skirt --repeats 9 --newton --newton-max 2400 --out {args.bench}` "
            "(table and plot: `bench.md`, `bench.png`): "
            + ", ".join(f"{g.name} {g.value:.1f} ms" for g in speed_goals(bench) if g.value is not None)
            + "."
        )
    studies_dir = docs / "studies"
    if studies_dir.is_dir():
        parts.append("## Studies (each headed by the command that made it)\n" + studies_index(studies_dir))
    out = docs / "results.md"
    out.write_text("\n\n".join(parts) + "\n")
    print(out)


if __name__ == "__main__":
    main()
