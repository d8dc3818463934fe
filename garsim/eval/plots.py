"""Figures of results: the training curve and bar charts, written as PNGs (matplotlib, headless)."""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from pathlib import Path

from garsim.atomic import atomic_write


def _figure():
    from matplotlib.figure import Figure

    return Figure(figsize=(10, 4), dpi=120)


def plot_training_curve(log_csv: str | os.PathLike | Sequence[str | os.PathLike], out_png: str | os.PathLike) -> Path:
    """Training loss and validation error (model vs LBS prior, mm) per epoch from a trainer's log.csv.

    Several logs (a run fine-tuned from another with ``--init``) are drawn as consecutive stages on
    one epoch axis, with a line where each later stage starts.
    """
    logs = [log_csv] if isinstance(log_csv, (str, os.PathLike)) else list(log_csv)
    rows: list[dict[str, str]] = []
    starts: list[int] = []
    for path in logs:
        with open(path, newline="") as fh:
            stage = list(csv.DictReader(fh))
        if not stage:
            raise ValueError(f"{path} has no epochs yet")
        starts.append(len(rows))
        rows.extend(stage)
    epoch = list(range(1, len(rows) + 1))
    fig = _figure()
    ax1, ax2 = fig.subplots(1, 2)
    ax1.plot(epoch, [float(r["train_loss"]) for r in rows], marker="o", ms=3)
    ax1.set(xlabel="epoch", ylabel="training loss (Eq. 7)", yscale="log", title="training loss")
    ax2.plot(epoch, [float(r["val_err_mm"]) for r in rows], marker="o", ms=3, label="GarSim")
    ax2.plot(epoch, [float(r["val_prior_mm"]) for r in rows], ls="--", label="LBS prior")
    collision = [e for e, r in zip(epoch, rows) if int(float(r["collision"]))]
    if collision:
        ax2.axvline(collision[0], color="grey", lw=0.8, label="collision loss on")
    for k, first in enumerate(starts[1:], start=2):
        for ax in (ax1, ax2):
            ax.axvline(first + 0.5, color="black", ls=":", lw=0.8, label=f"stage {k}" if ax is ax2 else None)
    ax2.set(xlabel="epoch", ylabel="mean Euclidean error (mm)", title="validation error (each stage its own set)")
    ax2.legend()
    fig.tight_layout()
    return atomic_write(out_png, lambda tmp: fig.savefig(tmp, format="png"))


def plot_bars(values: dict[str, dict[str, float]], ylabel: str, title: str, out_png: str | os.PathLike) -> Path:
    """Grouped bars: ``values[group][series]`` (e.g. fabric -> {GarSim, ground truth})."""
    groups = list(values)
    series = sorted({s for v in values.values() for s in v})
    fig = _figure()
    ax = fig.subplots()
    width = 0.8 / max(len(series), 1)
    for i, s in enumerate(series):
        xs = [g + (i - (len(series) - 1) / 2) * width for g in range(len(groups))]
        ax.bar(xs, [values[g].get(s, float("nan")) for g in groups], width, label=s)
    ax.set_xticks(range(len(groups)), groups)
    ax.set(ylabel=ylabel, title=title)
    ax.legend()
    fig.tight_layout()
    return atomic_write(out_png, lambda tmp: fig.savefig(tmp, format="png"))


def plot_paired_fabrics(fab: dict, out_png: str | os.PathLike) -> Path:
    """Fig. 7 analog from ``paired_fabric_agreement``: per paired group, the simulated (solid) and predicted
    (dashed, the midway physical fabrics as open circles) mean distance to the body and fold angle, silk to
    leather, each drawn as the change from its own silk value so that groups of different garments share an axis;
    one colour per garment family (one legend entry each, however many groups)."""
    from garsim.data.sample import FABRICS

    fig = _figure()
    axes = fig.subplots(1, 2)
    x = list(range(len(FABRICS)))
    mid_x = [i + 0.5 for i in x[:-1]]
    families = sorted({row["garment"] for row in fab["rows"]})
    colors = [f"C{families.index(row['garment']) % 10}" for row in fab["rows"]]
    panels = (("distance_mm", "mm", "distance to the body"), ("fold_deg", "deg", "mean fold angle"))
    for ax, (key, unit, what) in zip(axes, panels):
        labelled: set[str] = set()  # a legend entry for each family's first group only
        for row, color in zip(fab["rows"], colors):
            sim, pred = row[f"sim_{key}"], row[f"pred_{key}"]
            label = "_nolegend_" if row["garment"] in labelled else row["garment"]
            labelled.add(row["garment"])
            ax.plot(x, [v - sim[0] for v in sim], color=color, marker="o", ms=3, label=label)
            ax.plot(x, [v - pred[0] for v in pred], color=color, ls="--", marker="o", ms=3)
            if f"midway_{key}" in row:
                ax.plot(
                    mid_x, [v - pred[0] for v in row[f"midway_{key}"]], color=color, ls="none", marker="o", mfc="none"
                )
        ax.set(ylabel=f"change from silk ({unit})", title=what)
        ax.set_xticks(x, list(FABRICS))
        ax.grid(True, lw=0.3, alpha=0.5)
    axes[0].legend(fontsize=7)
    agreement, spread = fab.get("ordering_agreement"), fab.get("spread_ratio")
    if agreement is not None and spread is not None:
        fig.suptitle(
            f"{fab['groups']} paired groups, simulated (solid) vs predicted (dashed; open: midway physical values): "
            f"ordering agreement {agreement:.2f}, spread {spread:.2f}",
            fontsize=10,
        )
    fig.tight_layout()
    return atomic_write(out_png, lambda tmp: fig.savefig(tmp, format="png"))


def plot_bench(report: dict, out_png: str | os.PathLike) -> Path:
    """Log-log garment vertices vs ms from a ``garsim bench`` report: the network forward, one ``GarSim.drape``
    of a new garment and of a new pose, the refinement, a frame of ``drape_sequence`` (CPU medians), the cold
    first call in a fresh process and Newton's simulation when present (wall), and the paper's reported times."""

    def row(section: str, n: object) -> dict:
        part = report.get(section) or {}
        return part.get(n) or part.get(str(n)) or part.get(int(n)) or {}

    garsim = report["garsim"]
    sizes = list(garsim)
    verts = [garsim[n]["vertices"] for n in sizes]
    series = {
        "network forward": [garsim[n]["forward_cpu_ms"] for n in sizes],
        "GarSim.drape, new garment": [garsim[n]["api_cpu_ms"] for n in sizes],
        "GarSim.drape, new pose": [garsim[n].get("api_new_pose_cpu_ms") for n in sizes],
        "refine": [garsim[n]["refine_correct_cpu_ms"] for n in sizes],
        "sequence frame": [1000.0 / garsim[n]["sequence_fps_cpu"] for n in sizes],
        "cold call, fresh process (wall)": [row("cold", n).get("cold_call_wall_ms") for n in sizes],
        "Newton simulation (wall)": [row("newton", n).get("wall_ms") for n in sizes],
    }
    fig = _figure()
    ax = fig.subplots()
    for label, ys in series.items():
        points = [(x, y) for x, y in zip(verts, ys) if y is not None and y > 0]
        if points:
            xs, vals = zip(*points)
            ax.plot(xs, vals, marker="o", ms=4, label=label, ls="--" if "wall" in label else "-")
    from garsim.eval.bench import PAPER_S  # the paper's reported inference times (Sec. 5), s

    ax.plot(list(PAPER_S), [1000.0 * s for s in PAPER_S.values()], "k*", ms=10, ls="none", label="paper (reported)")
    ax.set(xscale="log", yscale="log", xlabel="garment vertices", ylabel="ms (CPU; cold call and Newton: wall)")
    machine = report.get("machine") or {}
    threads = (machine.get("thread_env") or {}).get("OMP_NUM_THREADS")
    ax.set_title(f"garsim bench: {machine.get('cpu', '')}, OMP_NUM_THREADS={threads}".strip())
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # outside: the lines span the axes
    fig.tight_layout()
    return atomic_write(out_png, lambda tmp: fig.savefig(tmp, format="png"))
