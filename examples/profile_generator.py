"""Where a generator job's CPU goes: total CPU seconds, Warp kernel launches, and the share spent inside the kernels
against the Python side of launching them (argument packing, Newton's solver and collision glue, our own loop).

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
from pathlib import Path

from garsim.atomic import atomic_write_bytes
from garsim.physics.generate import GenerateConfig, plan_jobs, simulate_job


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--family", required=True, help="skirt, top, tshirt, longsleeve, trousers or dress")
    parser.add_argument("--paired", action="store_true", help="a paired-fabric group (four copies in one model)")
    parser.add_argument("--seed", type=int, default=GenerateConfig.seed)
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args()

    import warp._src.context as warp_context

    with tempfile.TemporaryDirectory() as out:
        config = GenerateConfig(out=Path(out), seed=args.seed, num_train=60, num_test=0, num_ood=0)
        jobs = [j for j in plan_jobs(config) if j.family == args.family and j.paired == args.paired]
        if not jobs:
            raise SystemExit(f"no {'paired ' if args.paired else ''}{args.family} job among the first 60 planned")
        job = jobs[0]
        simulate_job(job, config)  # load / compile every kernel

        invoke = warp_context.invoke
        counter = {"launches": 0, "kernel_cpu": 0.0}

        def timed_invoke(*a, **k):  # type: ignore[no-untyped-def]
            c = time.process_time()
            try:
                return invoke(*a, **k)
            finally:
                counter["kernel_cpu"] += time.process_time() - c
                counter["launches"] += 1

        warp_context.invoke = timed_invoke
        try:
            c0 = time.process_time()
            records, rejections = simulate_job(job, config)
            total = time.process_time() - c0
        finally:
            warp_context.invoke = invoke
    settled = sum(int(sum(r.meta["settled"])) for r in records)
    result = {
        "job": job.job_id,
        "family": job.family,
        "construction": job.construction,
        "copies": len(job.fabrics),
        "settled_samples": settled,
        "rejections": len(rejections),
        "cpu_seconds": round(total, 2),
        "cpu_seconds_per_settled_sample": round(total / max(settled, 1), 2),
        "kernel_launches": counter["launches"],
        "kernel_cpu_seconds": round(counter["kernel_cpu"], 2),
        "outside_kernels_share": round(1.0 - counter["kernel_cpu"] / total, 3),
        "python_us_per_launch": round(1e6 * (total - counter["kernel_cpu"]) / max(counter["launches"], 1), 1),
    }
    print(json.dumps(result, indent=1))
    if args.json:
        atomic_write_bytes(args.json, json.dumps(result, indent=1).encode())


if __name__ == "__main__":
    main()
