"""How the API's input checks (``garsim.api.check_scene``, ``check_target``) sort good scenes from bad ones: every
template of the given sets as it comes (it must pass) and changed the ways a user's files go wrong (each must be
refused): the garment alone turned between Z-up and Y-up or scaled by 0.01 / 100 (another axis or unit than the
bodies), shrunk to 70% about the body's axis, moved 10 cm or 2 m sideways, on the target body instead of the
canonical one; the target body alone turned to Y-up or in mm / cm. Prints one row per case: how many scenes passed
(and of those how many with a warning: a garment 2-10% inside the canonical body) and the first words of the
refusals.

Run: OMP_NUM_THREADS=1 .venv/bin/python examples/input_checks.py --data tests/fixtures/dataset_v2 \
        --external ../shared/external-eval/data --json docs/studies/input_checks/fixture_external.json
"""

from __future__ import annotations

import argparse
import json
import logging
import re
from collections import Counter
from pathlib import Path

import numpy as np

from garsim.api import check_scene, check_target
from garsim.atomic import atomic_write_bytes
from garsim.eval.robustness import scenes_from_npz, scenes_from_store
from garsim.geometry.io import MeshError, y_up_to_z_up, z_up_to_y_up


def garment_cases(body: np.ndarray, target: np.ndarray, garment: np.ndarray) -> dict[str, tuple]:
    """case -> (canonical body, garment) as check_scene takes them."""
    axis = np.array([body[:, 0].mean(), body[:, 1].mean(), 0.0])
    return {
        "as given": (body, garment),
        "garment turned Z-up to Y-up": (body, z_up_to_y_up(garment)),
        "garment turned Y-up to Z-up": (body, y_up_to_z_up(garment)),
        "garment scaled 0.01": (body, garment * 0.01),
        "garment scaled 100": (body, garment * 100.0),
        "garment shrunk to 70%": (body, (garment - axis) * [0.7, 0.7, 1.0] + axis),
        "garment moved 10 cm": (body, garment + [0.1, 0.0, 0.0]),
        "garment moved 2 m": (body, garment + [2.0, 0.0, 0.0]),
        "garment on the target body": (target, garment),
    }


def target_cases(target: np.ndarray) -> dict[str, np.ndarray]:
    return {
        "target as given": target,
        "target turned Z-up to Y-up": z_up_to_y_up(target),
        "target in mm": target * 1000.0,
        "target in cm": target * 100.0,
    }


class _Warnings(logging.Handler):
    """Counts the warnings garsim.api logs (a garment partly inside the canonical body is draped with one)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.count += 1


WARNINGS = _Warnings()
logging.getLogger("garsim.api").addHandler(WARNINGS)
logging.getLogger("garsim.api").propagate = False


def verdict(check, *args) -> str:
    """'passed', 'passed with a warning', or the refusal's opening words with its figures as N."""
    before = WARNINGS.count
    try:
        check(*args)
    except MeshError as exc:
        return " ".join(re.sub(r"[-+]?\d[\d.e+]*", "N", str(exc)).split()[:8])
    return "passed" if WARNINGS.count == before else "passed with a warning"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", action="append", default=[], help="a garsim dataset folder (repeatable)")
    parser.add_argument("--external", default=None, help="a folder of external *.npz drapes and body_faces.npy")
    parser.add_argument(
        "--wide-poses", type=int, default=None, help="seed: --data's bodies in poses of the sampler's whole range"
    )
    parser.add_argument("--json", required=True)
    args = parser.parse_args()
    scenes = [s for d in args.data for s in scenes_from_store(d, wide_poses=args.wide_poses)]
    if args.external:
        scenes += scenes_from_npz(args.external)
    if not scenes:
        parser.error("give --data DIR and/or --external DIR")
    table: dict[str, Counter] = {}
    for s in scenes:
        (body, faces), target, garment = s.canonical, s.target[0], s.garment[0]
        for case, (b, g) in garment_cases(body, target, garment).items():
            table.setdefault(case, Counter())[verdict(check_scene, b, faces, g)] += 1
        for case, t in target_cases(target).items():
            table.setdefault(case, Counter())[verdict(check_target, body, t)] += 1
    rows = []
    for case, counts in table.items():
        refusals = {k: n for k, n in counts.items() if not k.startswith("passed")}
        warned = counts["passed with a warning"]
        row = {"case": case, "scenes": sum(counts.values()), "passed": counts["passed"] + warned, "warned": warned}
        rows.append({**row, "refused": refusals})
        print(f"{case:30s} {row['passed']:3d} of {row['scenes']} passed ({warned} with a warning); refused: {refusals}")
    report = {"data": args.data, "external": args.external, "wide_poses": args.wide_poses, "rows": rows}
    atomic_write_bytes(Path(args.json), (json.dumps(report, indent=1) + "\n").encode())


if __name__ == "__main__":
    main()
