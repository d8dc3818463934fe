"""Time garsim.refine on one thread, optionally against another implementation of it, in one run.

The inputs are those of ``garsim bench`` (garsim.eval.bench): the shipped model's raw drape of a
template on the default Anny body in the benchmark's step poses (correcting case), and the template
on the canonical body moved by a different sub-millimetre offset every call (valid case); every call
sees a new body pose, so the per-pose work is included. Process time, medians over the poses.

Usage: python examples/refine_check.py [--garments skirt tshirt trousers] [--sizes 600 2400]
       [--against OLD_REFINE.py]   (e.g. git show HEAD:garsim/refine.py > /tmp/old_refine.py)
"""

from __future__ import annotations

import argparse
import importlib.util
import time
from pathlib import Path

import numpy as np

from garsim.api import GarSim
from garsim.bodies.anny import AnnyBody
from garsim.eval.bench import DEFAULT_POSE, drape_once
from garsim.garments.templates import make_garment
from garsim.refine import refine


def load_refine(path: Path):
    """The ``refine`` function of another copy of garsim/refine.py."""
    spec = importlib.util.spec_from_file_location("other_refine", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.refine


def median_ms(fn, cases: list[tuple]) -> float:
    fn(*cases[0][0], **cases[0][1])  # warm-up (kernels, per-garment caches); its pose is reused by no timed call
    times = []
    for args, kwargs in cases[1:]:
        t0 = time.process_time()
        fn(*args, **kwargs)
        times.append(1e3 * (time.process_time() - t0))
    return float(np.median(times))


def cases_for(kind: str, size: int, body, model, poses: int = 8) -> dict[str, list[tuple]]:
    """(args, kwargs) of refine for each pose: the raw network drape and the offset resting template."""
    canonical = body.canonical()
    g = make_garment(kind, body, target_vertices=size)
    correct, valid = [], []
    for k, a in enumerate(np.linspace(0.4, 1.2, poses)):
        target = body.pose({**body.t_pose(), **{b: a * np.asarray(v) for b, v in DEFAULT_POSE.items()}})
        pred, _ = drape_once(model, body, canonical, target, g.vertices, g.faces, g.pinned, "cotton", kind)
        kwargs = {"fabric": "cotton", "pinned": g.pinned}
        correct.append(((pred, g.vertices, g.faces, target.vertices, body.faces), kwargs))
        offset = np.array([1e-4 * (k + 1), 0.0, 0.0], dtype=np.float32)
        valid.append(((g.vertices + offset, g.vertices, g.faces, canonical.vertices + offset, body.faces), kwargs))
    return {"vertices": len(g.vertices), "correct": correct, "valid": valid}


def main(garments: list[str], sizes: list[int], against: Path | None) -> None:
    body = AnnyBody({})
    model = GarSim.pretrained().model  # the numpy runtime: one thread with OMP_NUM_THREADS=1
    other = load_refine(against) if against else None
    for kind in garments:
        for size in sizes:
            cases = cases_for(kind, size, body, model)
            line = f"{kind:9s} {cases['vertices']:5d} v:"
            for name in ("valid", "correct"):
                ms = median_ms(refine, cases[name])
                line += f"  {name} {ms:6.1f} ms"
                if other is not None:
                    ms_other = median_ms(other, cases[name])
                    line += f" (other {ms_other:6.1f} ms, {ms_other / ms:5.1f}x)"
            print(line, flush=True)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--garments", nargs="+", default=["skirt", "tshirt", "trousers"])
    p.add_argument("--sizes", type=int, nargs="+", default=[600, 2400])
    p.add_argument("--against", type=Path, default=None, help="another garsim/refine.py to time on the same inputs")
    args = p.parse_args()
    main(args.garments, args.sizes, args.against)
