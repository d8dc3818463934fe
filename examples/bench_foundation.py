"""Foundation timings measured in one run (ratios are what to compare on a shared machine):
Anny forward pass, template build, LBS prior for a ~2,500-vertex garment, inside test.

Run: .venv/bin/python examples/bench_foundation.py
"""

from __future__ import annotations

import time

import numpy as np
import torch

from garsim.bodies.anny import AnnyBody
from garsim.bodies.poses import PoseSampler
from garsim.bodies.prior import garment_prior
from garsim.garments.templates import make_garment
from garsim.geometry.inside import InsideTester


def median_ms(fn, repeats: int = 7) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(1000 * (time.perf_counter() - t0))
    return float(np.median(times))


def main() -> None:
    torch.set_num_threads(1)
    body = AnnyBody({})
    pose = PoseSampler(seed=0).sample(1)[0]
    canonical, target = body.canonical(), body.pose(pose)
    rows = {"Anny forward (one pose, 13,718 v)": median_ms(lambda: body.pose(pose))}
    for kind in ("skirt", "top", "tshirt", "trousers", "dress"):
        rows[f"template build: {kind}, 2,500 v"] = median_ms(
            lambda k=kind: make_garment(k, body, target_vertices=2500), 3
        )
    g = make_garment("skirt", body, target_vertices=2500)
    rows[f"LBS prior ({g.num_vertices} v skirt)"] = median_ms(
        lambda: garment_prior(body, canonical, target, g.vertices)
    )
    tester = InsideTester(target.vertices, body.faces)
    rows[f"inside test ({g.num_vertices} points)"] = median_ms(lambda: tester.inside(g.vertices))
    base = rows["Anny forward (one pose, 13,718 v)"]
    for name, ms in rows.items():
        print(f"{name:45s} {ms:8.1f} ms  ({ms / base:5.2f}x Anny forward)")


if __name__ == "__main__":
    main()
