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
