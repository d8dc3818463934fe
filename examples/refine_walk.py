"""Issue 13's acceptance figures on the walk cycle of every garment family, through the public API.

Each family (the parametric templates; the long-sleeve top from the implicit construction, which has no
template) is draped on the default Anny body over ``motion("walk")`` by ``GarSim.pretrained()`` twice:
raw (``collision_margin=None``) and with the default post-process (``refine=True``). Over all frames:
edges whose template rest length is >= 5 mm and that have a free end (an edge between two pinned
vertices follows the skinning prior, which refine does not move): max and 99th percentile of the
stretch ratio and its mean; vertices inside the body (winding number) and edges whose segment meets the
body surface, of all and of the free ones (pinned vertices follow the skinning prior, inside the body
or not); and refine's own CPU time per frame (one thread, a new body pose every frame), of the first and of the
second of ``drape_sequence``'s passes (after the temporal smoothing, with the first's ``RefineMemo``). Issue 12's
sequence figures come from the same runs: frame-to-frame jitter (``eval.metrics.jitter_mm``) of the prior, the raw
network and the refined drape, and ``drape_sequence``'s frames per second with warm caches (wall clock,
one thread).

Usage: python examples/refine_walk.py [--model DIR] [--vertices 600 2400] [--frames 30] [--out docs/refine.json]
       [--against OLD_REFINE.py]   (its per-call times from the same run, on the same inputs)
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import time
from pathlib import Path

import numpy as np
import torch

import garsim.refine
from garsim.api import GarSim, SequenceConfig, smooth_corrections
from garsim.bodies.anny import AnnyBody
from garsim.bodies.poses import batched_matrices, motion, stack_poses
from garsim.demo import DEMO_GARMENTS, _build_garment
from garsim.eval.metrics import MIN_REST, constraint_figures, jitter_mm
from garsim.geometry.inside import obstacle


def load_refine(path: Path):
    """Another copy of garsim/refine.py, as a module (its ``refine`` takes its own ``RefineMemo``)."""
    spec = importlib.util.spec_from_file_location("other_refine", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def refine_ms(
    raw: np.ndarray, garment, targets: np.ndarray, faces: np.ndarray, fabric: str, prior: np.ndarray, impls: dict
) -> dict[str, tuple[float, float]]:
    """Median CPU ms of refine per frame, as ``drape_sequence`` calls it, of each implementation in ``impls`` (name
    -> a module with ``refine`` and ``RefineMemo``), interleaved frame by frame: the first pass (the raw frame on its
    own pose with the prior as its fallback), then the second (the first pass's frames with their correction
    smoothed over time, each frame with its first pass's ``RefineMemo`` where the implementation takes one). Before
    each timed call the obstacle is moved to another pose, so that every call refits it as in a sequence."""
    kw = {"pinned": garment.pinned}
    tpl, gf = garment.vertices, garment.faces
    memos = {name: [impls[name].RefineMemo() for _ in raw] for name in impls}
    first = {name: [] for name in impls}
    times = {name: ([], []) for name in impls}

    def timed(name: str, x: np.ndarray, t: int, which: int) -> np.ndarray:
        extra = {"memo": memos[name][t]} if "memo" in inspect.signature(impls[name].refine).parameters else {}
        obstacle(targets[t - 1], faces)  # another pose: this call refits the obstacle, as in a sequence
        t0 = time.process_time()
        out = impls[name].refine(x, tpl, gf, targets[t], faces, fabric, fallback=prior[t], **kw, **extra)
        times[name][which].append(1e3 * (time.process_time() - t0))
        return out

    for name in impls:  # warm-up (kernels, per-garment caches)
        impls[name].refine(raw[0], tpl, gf, targets[0], faces, fabric, fallback=prior[0], **kw)
    for t, x in enumerate(raw):
        for name in impls:
            first[name].append(timed(name, x, t, 0))
    again = {}
    for name in impls:
        again[name] = smooth_corrections(np.stack(first[name]), prior, SequenceConfig.smoothing)
        again[name][:, garment.pinned] = prior[:, garment.pinned]
    for t in range(len(raw)):
        for name in impls:
            timed(name, again[name][t], t, 1)
    return {name: (float(np.median(a)), float(np.median(b))) for name, (a, b) in times.items()}


def timed_sequence(sim: GarSim, canonical, targets: np.ndarray, mesh, **kw) -> tuple[np.ndarray, float]:
    """``sim.drape_sequence`` over all ``targets`` -> (frames, frames per second with warm caches, wall clock).

    The first frame is draped once beforehand to warm the caches and kernels; the whole sequence is then one call,
    so its temporal smoothing sees every frame (draping frame 0 apart would leave it unsmoothed)."""
    sim.drape_sequence(canonical, targets[:1], mesh, **kw)
    t0 = time.perf_counter()
    frames = sim.drape_sequence(canonical, targets, mesh, **kw)
    return frames, len(targets) / (time.perf_counter() - t0)


def main(vertices: list[int], frames: int, out: Path, model: str | None = None, against: Path | None = None) -> dict:
    torch.set_num_threads(1)
    against = {"against": load_refine(against)} if against else {}
    body = AnnyBody({})
    canonical = (body.canonical().vertices, body.faces)
    targets = body.pose_batch(batched_matrices(stack_poses(motion("walk", frames))))[0]
    load = (lambda **kw: GarSim.load(model, **kw)) if model else GarSim.pretrained
    raw_sim, sim, prior = load(collision_margin=None), load(), GarSim.prior_only()
    report: dict = {"motion": "walk", "frames": frames, "min_rest_m": MIN_REST, "model": model or "shipped"}
    report["families"] = {}
    for kind, (fabric, construction) in DEMO_GARMENTS.items():
        for n in vertices:
            g = _build_garment(kind, construction, body, n)
            mesh = (g.vertices, g.faces)
            kw = {"fabric": fabric, "pinned": g.pinned}
            raw, raw_fps = timed_sequence(raw_sim, canonical, targets, mesh, **kw)
            refined, fps = timed_sequence(sim, canonical, targets, mesh, **kw)
            skinned = prior.drape_sequence(canonical, targets, mesh, **kw)
            ms = refine_ms(raw, g, targets, body.faces, fabric, skinned, {"refine": garsim.refine, **against})
            first_ms, second_ms = ms["refine"]
            entry = {
                "vertices": int(len(g.vertices)),
                "fabric": fabric,
                "construction": construction,
                "raw": constraint_figures(raw, g.vertices, g.faces, g.pinned, targets, body.faces),
                "refined": constraint_figures(refined, g.vertices, g.faces, g.pinned, targets, body.faces),
                "refine_cpu_ms_per_frame": first_ms,
                "refine_second_pass_cpu_ms_per_frame": second_ms,
                **({"against_cpu_ms_per_frame": ms["against"]} if against else {}),
                "moved_mm_mean": 1000.0 * float(np.linalg.norm(refined - raw, axis=2).mean()),
                "jitter_mm": {"prior": jitter_mm(skinned), "raw": jitter_mm(raw), "refined": jitter_mm(refined)},
                "sequence_fps": {"raw": raw_fps, "refined": fps},
            }
            report["families"][f"{kind}@{n}"] = entry
            a, b = entry["raw"], entry["refined"]
            print(
                f"{kind:10s} {entry['vertices']:5d} v: max {a['max_stretch']:.2f} -> {b['max_stretch']:.2f}, "
                f"p99 {a['p99_stretch']:.3f} -> {b['p99_stretch']:.3f}, mean {a['mean_stretch']:.3f} -> "
                f"{b['mean_stretch']:.3f}, inside {a['inside_pct']:.2f} -> {b['inside_pct']:.2f} % "
                f"(free {b['inside_free_pct']:.2f}), through {a['edges_through_pct']:.2f} -> "
                f"{b['edges_through_pct']:.2f} % (free {b['edges_through_free_pct']:.2f}), "
                f"refine {first_ms:.1f} + {second_ms:.1f} ms/frame"
                + (f" (against {ms['against'][0]:.1f} + {ms['against'][1]:.1f})" if against else "")
                + ", jitter prior/raw/refined "
                f"{'/'.join(f'{v:.2f}' for v in entry['jitter_mm'].values())} mm/frame², {fps:.0f} fps",
                flush=True,
            )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1) + "\n")
    return report


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vertices", type=int, nargs="+", default=[600, 2400])
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--out", type=Path, default=Path("docs/refine.json"))
    p.add_argument("--model", help="a trained model folder (default: the shipped model)")
    p.add_argument(
        "--against",
        type=Path,
        help="another garsim/refine.py (e.g. git show HEAD:garsim/refine.py > /tmp/old_refine.py): its two passes are "
        "timed in the same run, frame by frame with this one's (against_cpu_ms_per_frame: first, second)",
    )
    args = p.parse_args()
    main(args.vertices, args.frames, args.out, args.model, args.against)
