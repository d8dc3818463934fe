"""Noise floor of the ground truth: one job per garment family (seed 1, training split, unpaired, under 900
vertices, two chained targets) settled after two motion paths (12 vs 24 frames to each target), run twice with
12 (determinism), and its second target reached straight from the canonical pose instead of through the first
(chained vs direct). Prints and writes the mean vertex distance (mm) between the settled states, beside the
prior's error against the truth. A path-dependent settled state (friction holds the cloth where the motion left it) is
an error no one-step model without the path can remove.

    .venv/bin/python examples/path_dependence.py docs/studies/path_dependence.json   # ~10 min CPU
"""

import argparse
import dataclasses
import json
import time

import numpy as np

from garsim.data.store import GarmentLevel
from garsim.physics.generate import GenerateConfig, JobSpec, plan_jobs, simulate_job


def mean_mm(a: np.ndarray, b: np.ndarray) -> float:
    """Mean vertex distance between two (N, 3) garments, in millimetres."""
    return float(1000 * np.linalg.norm(a - b, axis=1).mean())


def one_per_family(config: GenerateConfig, max_vertices: int = 900) -> list[JobSpec]:
    """The first unpaired training job of each family under ``max_vertices``."""
    picked: dict[str, JobSpec] = {}
    for job in plan_jobs(config):
        if job.split == "train" and not job.paired and job.vertices < max_vertices:
            picked.setdefault(job.family, job)
    return list(picked.values())


def settled(
    job: JobSpec, config: GenerateConfig, motion_frames: int, visit: list[int] | None = None
) -> GarmentLevel | None:
    """The job's full-resolution level with ``motion_frames`` to each target (of ``visit``), or None when
    rejected."""
    t = time.process_time()
    try:
        records, _ = simulate_job(job, dataclasses.replace(config, motion_frames=motion_frames), visit)
    except Exception as exc:  # noqa: BLE001 - a rejected template is reported, not fatal
        print(job.job_id, motion_frames, "rejected:", exc, flush=True)
        return None
    print(job.job_id, job.family, motion_frames, f"{time.process_time() - t:.0f} s", flush=True)
    return records[0].levels["full"] if records else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="JSON file to write")
    args = parser.parse_args()
    config = GenerateConfig(out="unused", seed=1, targets_per_job=2)
    rows = []
    for job in one_per_family(config):
        a, b, slow = (settled(job, config, frames) for frames in (12, 12, 24))
        direct = settled(job, config, 12, visit=[1])
        if a is None or b is None or slow is None or direct is None:
            continue
        k = min(len(a.targets), len(b.targets), len(slow.targets))
        rows.append(
            {
                "job": job.job_id,
                "family": job.family,
                "vertices": job.vertices,
                "prior_err_mm": [mean_mm(a.priors[i], a.targets[i]) for i in range(k)],
                "path_mm": [mean_mm(a.targets[i], slow.targets[i]) for i in range(k)],
                "repeat_mm": [mean_mm(a.targets[i], b.targets[i]) for i in range(k)],
                "chain_vs_direct_mm": mean_mm(a.targets[1], direct.targets[0])
                if k > 1 and len(direct.targets)
                else None,
                "direct_prior_err_mm": mean_mm(direct.priors[0], direct.targets[0]) if len(direct.targets) else None,
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    with open(args.out, "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
