"""Where a generator job's CPU goes, before (every kernel launched from Python, Newton's full-size contact buffer)
and after (captured substep graphs replayed, the tight contact buffer: ``SimConfig.graphs``, ``tight_contacts``):
total CPU seconds, Warp kernel launches made from Python, the share spent inside them against the Python side of
launching them (argument packing, Newton's solver and collision glue, our own loop) and the costliest kernels; the
two runs' results must be bit-identical.

Run: .venv/bin/python examples/profile_generator.py --family tshirt --json docs/studies/generator_profile/tshirt.json
     .venv/bin/python examples/profile_generator.py --family skirt --paired
The job is the first of its family (and paired or not) that ``garsim data generate --seed 0`` plans; one untimed
run first loads or compiles the kernels. Figures are CPU seconds of this process (``time.process_time``).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

from garsim.atomic import atomic_write_bytes
from garsim.physics.generate import GenerateConfig, plan_jobs, simulate_job


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--family", required=True, help="skirt, top, tshirt, longsleeve, trousers or dress")
    parser.add_argument("--paired", action="store_true", help="a paired-fabric group (four copies in one model)")
    parser.add_argument("--min-vertices", type=int, default=0, help="the first such job of this many vertices or more")
    parser.add_argument("--seed", type=int, default=GenerateConfig.seed)
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args()

    import numpy as np
    import warp._src.context as warp_context

    with tempfile.TemporaryDirectory() as out:
        config = GenerateConfig(out=Path(out), seed=args.seed, num_train=60, num_test=0, num_ood=0)
        jobs = [
            j
            for j in plan_jobs(config)
            if j.family == args.family and j.paired == args.paired and j.vertices >= args.min_vertices
        ]
        if not jobs:
            raise SystemExit(
                f"no {'paired ' if args.paired else ''}{args.family} job of {args.min_vertices}+ vertices among the "
                "first 60 planned"
            )
        job = jobs[0]
        simulate_job(job, config)  # load / compile every kernel

        invoke = warp_context.invoke
        counter = {"launches": 0, "kernel_cpu": 0.0}
        per_kernel: Counter[str] = Counter()

        def timed_invoke(kernel, *a, **k):  # type: ignore[no-untyped-def]
            c = time.process_time()
            try:
                return invoke(kernel, *a, **k)
            finally:
                dt = time.process_time() - c
                counter["kernel_cpu"] += dt
                counter["launches"] += 1
                per_kernel[kernel.key] += dt

        runs, states = {}, {}
        variants = {  # the kernel breakdown needs launches from Python, so the tight buffer alone runs too
            "before": {"graphs": False, "tight_contacts": False},
            "tight_contacts_one_by_one": {"graphs": False, "tight_contacts": True},
            "after": {"graphs": True, "tight_contacts": True},
        }
        warp_context.invoke = timed_invoke
        try:
            for name, sim in variants.items():
                counter.update(launches=0, kernel_cpu=0.0)
                per_kernel.clear()
                c0 = time.process_time()
                records, rejections = simulate_job(job, replace(config, sim=sim))
                total = time.process_time() - c0
                settled = sum(int(sum(r.meta["settled"])) for r in records)
                states[name] = [r.levels["full"].targets for r in records]
                runs[name] = {"sim": sim, "cpu_seconds": round(total, 2)}
                runs[name]["cpu_seconds_per_settled_sample"] = round(total / max(settled, 1), 2)
                runs[name]["python_kernel_launches"] = counter["launches"]
                if not sim["graphs"]:
                    runs[name]["kernel_cpu_seconds"] = round(counter["kernel_cpu"], 2)
                    runs[name]["outside_kernels_share"] = round(1.0 - counter["kernel_cpu"] / total, 3)
                    runs[name]["python_us_per_launch"] = round(
                        1e6 * (total - counter["kernel_cpu"]) / max(counter["launches"], 1), 1
                    )
                    runs[name]["top_kernels_cpu_seconds"] = {k: round(t, 2) for k, t in per_kernel.most_common(8)}
        finally:
            warp_context.invoke = invoke
    reference = states["before"]
    identical = all(
        len(got) == len(reference) and all(np.array_equal(a, b) for a, b in zip(got, reference))
        for got in states.values()
    )
    result = {
        "job": job.job_id,
        "family": job.family,
        "construction": job.construction,
        "vertices": job.vertices,
        "copies": len(job.fabrics),
        "settled_samples": settled,
        "rejections": len(rejections),
        **runs,
        "cpu_ratio_before_over_after": round(runs["before"]["cpu_seconds"] / runs["after"]["cpu_seconds"], 2),
        "bit_identical": identical,
    }
    print(json.dumps(result, indent=1))
    if args.json:
        atomic_write_bytes(args.json, json.dumps(result, indent=1).encode())
    if not identical:
        raise SystemExit("graphs or the tight contact buffer changed the result: do not generate with them")


if __name__ == "__main__":
    main()
