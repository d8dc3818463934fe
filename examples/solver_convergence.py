"""How far the generator's settled drapes are from converged: one template per family settled on the canonical Anny
body at several VBD budgets (substeps x iterations per frame: the generator's ``SimConfig()``, older and larger
ones), the velocity damping per second held fixed (``damping ** (default substeps / substeps)`` per substep), so
that only the solver's convergence changes. Per family and budget: the mean distance of the garment to the body, the
mean and largest vertex distance to the last budget's drape, the mean and 99th-percentile edge stretch, and CPU
seconds; and the floor of those vertex distances: the last budget once more with gravity 0.1% stronger (a settled
drape's folds can land elsewhere under any perturbation).

Usage: python examples/solver_convergence.py [--vertices 1200] [--fabric cotton] [--budgets 10x4 40x4 40x8 80x8]
       [--families skirt dress] [--settle-speed 0.002 --max-settle-frames 300]
       [--out docs/studies/solver_convergence.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from garsim.bodies.anny import AnnyBody
from garsim.garments.templates import make_garment
from garsim.geometry.mesh import edge_lengths
from garsim.physics.newton_sim import SimConfig, mean_body_distance, settle

FAMILIES = ("skirt", "top", "tshirt", "trousers", "dress")
"""The template families (the long-sleeve top exists only in the implicit construction)."""


PERTURBATION = 1e-3
"""Relative change of gravity of the floor run."""


def budget_config(budget: str, gravity_scale: float = 1.0, **overrides: float) -> SimConfig:
    """``SimConfig`` of a 'SUBSTEPSxITERATIONS' budget, with the default's damping per second (``overrides``: other
    ``SimConfig`` fields, e.g. the settling criterion)."""
    substeps, iterations = (int(v) for v in budget.lower().split("x"))
    base = SimConfig()
    damping = base.damping ** (base.substeps / substeps)
    return SimConfig(
        substeps=substeps, iterations=iterations, damping=damping, gravity=base.gravity * gravity_scale, **overrides
    )


def main(
    vertices: int,
    fabric: str,
    budgets: list[str],
    out: Path,
    families: tuple[str, ...] = FAMILIES,
    criterion: dict | None = None,
) -> dict:
    """Settle one template per family at every budget; ``criterion``: ``SimConfig`` overrides of the settling test."""
    criterion = criterion or {}
    body = AnnyBody({})
    can = body.canonical()
    report: dict = {"vertices": vertices, "fabric": fabric, "budgets": budgets, "settle": criterion, "families": {}}
    for family in families:
        g = make_garment(family, body, target_vertices=vertices)
        rest = edge_lengths(g.vertices, g.faces)
        states, rows = {}, {}
        for budget in budgets:
            t0 = time.process_time()
            v, info = settle(g, can.vertices, body.faces, fabric, budget_config(budget, **criterion))
            ratio = edge_lengths(v, g.faces) / rest
            states[budget] = v.astype(np.float64)
            rows[budget] = {
                "body_distance_mm": 1000 * mean_body_distance(v, can.vertices),
                "stretch_mean": float(ratio.mean()),
                "stretch_p99": float(np.percentile(ratio, 99)),
                "frames": int(info["frames"]),
                "cpu_s": time.process_time() - t0,
            }
        ref = states[budgets[-1]]
        floor_cfg = budget_config(budgets[-1], 1 + PERTURBATION, **criterion)
        floor, _ = settle(g, can.vertices, body.faces, fabric, floor_cfg)
        floor_gap = np.linalg.norm(floor - ref, axis=1)
        for budget, row in rows.items():
            gap = np.linalg.norm(states[budget] - ref, axis=1)
            row.update(to_largest_mean_mm=1000 * float(gap.mean()), to_largest_max_mm=1000 * float(gap.max()))
            print(
                f"{family:9s} {len(g.vertices):5d} v {budget:>5s}: " + ", ".join(f"{k} {v:.4g}" for k, v in row.items())
            )
        report["families"][family] = {
            "vertices": int(len(g.vertices)),
            "budgets": rows,
            "floor_mean_mm": 1000 * float(floor_gap.mean()),
            "floor_max_mm": 1000 * float(floor_gap.max()),
        }
        print(f"{family:9s} floor (gravity x {1 + PERTURBATION}): {1000 * floor_gap.mean():.2f} mm mean")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1) + "\n")
    return report


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vertices", type=int, default=1200)
    p.add_argument("--fabric", default="cotton")
    p.add_argument(
        "--budgets",
        nargs="+",
        default=["10x4", "20x8", "40x4", "40x8", "80x8"],
        help="SUBSTEPSxITERATIONS; the last is the reference the others are measured against",
    )
    p.add_argument("--families", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    p.add_argument("--settle-speed", type=float, default=SimConfig.settle_speed, help="m/s: settled below this")
    p.add_argument("--max-settle-frames", type=int, default=SimConfig.max_settle_frames)
    p.add_argument("--out", type=Path, default=Path("docs/studies/solver_convergence.json"))
    args = p.parse_args()
    criterion = {"settle_speed": args.settle_speed, "max_settle_frames": args.max_settle_frames}
    main(args.vertices, args.fabric, args.budgets, args.out, tuple(args.families), criterion)
