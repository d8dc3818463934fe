"""The model issue's stability, equivariance and rest checks through the public API (``garsim.eval.robustness``),
on the templates of a garsim dataset folder and on the external check set's, written as JSON for the results
report (``garsim.eval.goals.robustness_goals``).

Run: OMP_NUM_THREADS=1 .venv/bin/python examples/robustness.py --model garsim/weights \
        --data tests/fixtures/dataset_v2 --external ../shared/external-eval/data --noise-draws 3 \
        --json docs/robustness.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from garsim.api import GarSim
from garsim.atomic import atomic_write_bytes
from garsim.eval.robustness import measure, scenes_from_jobs, scenes_from_npz, scenes_from_store


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--data", action="append", default=[], help="a garsim dataset folder (repeatable)")
    parser.add_argument("--split", default=None, help="only this split of --data (default: all)")
    parser.add_argument("--per-type", type=int, default=None, help="at most this many sequences per garment type")
    parser.add_argument(
        "--wide-poses", type=int, default=None, help="seed: --data's bodies in poses of the sampler's whole range"
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="N garments as the generator plans them (--seed), built, not simulated, "
        "in poses of the sampler's whole range (seeds from --wide-poses, default 0): no dataset needed",
    )
    parser.add_argument("--external", default=None, help="a folder of external *.npz drapes and body_faces.npy")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--noise-draws", type=int, default=1, help="the noise check's largest change over this many draws"
    )
    parser.add_argument("--json", required=True)
    args = parser.parse_args()
    if not args.data and not args.external and not args.jobs:
        parser.error("give --data DIR, --jobs N and/or --external DIR")
    sim = GarSim.load(args.model) if args.model else GarSim.pretrained()
    sources = [
        (str(d), lambda d=d: scenes_from_store(d, args.split, per_type=args.per_type, wide_poses=args.wide_poses))
        for d in args.data
    ]
    if args.jobs:
        sources.append((f"jobs:{args.jobs}", lambda: scenes_from_jobs(args.jobs, args.seed, args.wide_poses or 0)))
    if args.external:
        sources.append((str(args.external), lambda: scenes_from_npz(args.external)))
    sets = {}
    for source, scenes in sources:
        start = time.perf_counter()
        figures = measure(sim, scenes(), seed=args.seed, noise_draws=args.noise_draws)
        sets[source] = {**figures, "seconds": time.perf_counter() - start}
        all_ = sets[source]["summary"]["all"]
        print(
            f"{source}: {all_['n']} scenes, stability {all_['stability_max_mm']:.3f} mm, equivariance "
            f"{all_['equivariance_max_mm']:.3f} mm, rest {all_['rest_max_mm']:.2f} mm at most"
        )
    report = {"model": args.model or "garsim/weights", "external": args.external, "wide_poses": args.wide_poses}
    report["noise_draws"] = args.noise_draws
    report["sets"] = sets
    atomic_write_bytes(Path(args.json), (json.dumps(report, indent=1) + "\n").encode())


if __name__ == "__main__":
    main()
