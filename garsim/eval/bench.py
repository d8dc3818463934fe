"""End-to-end inference timing: meshes in memory -> predicted garment vertices, on one CPU thread.

What one timed call does (as ``GarSim`` drapes a garment in practice): the LBS prior
(``garment_prior``: nearest canonical body vertices, weight blending), the Sample, the graph
(``build_graph``: q, Eq. 2 inputs, garment kNN, edges) and the forward pass. Per-body work
(body KD-tree, yaw frame, body-mesh rings) is cached by content and reused across garments,
as when many garments are draped on one body; it is timed once as ``first_call`` (cold body).
The garment caches (nearest-vertex answers, garment kNN and edges) are cleared before every
timed call, so each call pays for its own garment (a new garment each time, not a replay).
``pose_seq_*`` times the other common case: the same garment on a sequence of new target
poses (garment caches warm; prior, graph inputs and forward pass recomputed every call).
``refine_*`` times the physical refinement (``garsim.refine``) the API runs after the network, on one
thread and a new body pose every call (its per-pose work included): ``refine_correct`` on the network's
raw prediction for each pose of that sequence, ``refine_valid`` on a drape that needs no correction
(the template on the canonical body, both moved by a different sub-millimetre offset every call).

Wall time on a shared machine includes waiting for other jobs; CPU time (``process_time``)
of this process is the steadier figure. Compare variants as ratios within one run.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from garsim.api import GarSim
from garsim.bodies.prior import garment_prior
from garsim.data.sample import Sample
from garsim.geometry.cache import clear_all
from garsim.model.runtime import GarSimRuntime

DEFAULT_POSE: dict[str, list[float]] = {"upperleg01.L": [-0.5, 0.0, 0.0], "upperleg01.R": [0.3, 0.0, 0.0]}
"""Target pose used by the benchmark (a step: one thigh forward, one back), on top of Anny's T-pose."""


def _timed(fn) -> tuple[Any, float, float]:
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, (time.perf_counter() - w0) * 1000.0, (time.process_time() - c0) * 1000.0


def forward(model, graph) -> np.ndarray:
    """One forward pass of either backend on its own input (``model.make_graph``): the numpy runtime or torch."""
    if isinstance(model, GarSimRuntime):
        return model(graph)
    import torch

    with torch.inference_mode():
        return model(graph).numpy()


@contextmanager
def _one_thread(model, threads: int):
    """Torch models in eval mode on ``threads`` threads for the block (numpy's threads: OMP_NUM_THREADS)."""
    if isinstance(model, GarSimRuntime):
        yield
        return
    import torch

    was_training, old_threads = model.training, torch.get_num_threads()
    model.eval()
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(old_threads)
        if was_training:
            model.train()


def drape_once(
    model, body, canonical, target, garment_vertices, garment_faces, pinned, fabric: str = "cotton", kind: str = "skirt"
) -> tuple[np.ndarray, dict[str, float]]:
    """One end-to-end prediction; returns the vertices and the CPU ms of prior, graph and forward."""
    c0 = time.process_time()
    prior = garment_prior(body, canonical, target, garment_vertices)
    c1 = time.process_time()
    sample = Sample(
        canonical.vertices, target.vertices, body.faces, garment_vertices, garment_faces, pinned, prior, fabric, kind
    )
    graph = model.make_graph(sample, model.config, loss_inputs=False)
    c2 = time.process_time()
    pred = forward(model, graph)
    c3 = time.process_time()
    return pred, {"prior_cpu_ms": (c1 - c0) * 1e3, "graph_cpu_ms": (c2 - c1) * 1e3, "forward_cpu_ms": (c3 - c2) * 1e3}


def bench_refine(
    body,
    canonical,
    targets: Sequence[Any],
    garment,
    predictions: Sequence[np.ndarray],
    fabric: str = "cotton",
    shift: float = 1e-4,
) -> dict[str, float]:
    """Median CPU ms of ``refine`` on a new body pose every call: the raw ``predictions`` on ``targets``
    (``refine_correct_cpu_ms``) and the resting template on the canonical body, both moved by k x ``shift``
    metres in call k (``refine_valid_cpu_ms``)."""
    from garsim.refine import refine

    args = (garment.vertices, garment.faces)
    correct, valid = [], []
    for k, (target, pred) in enumerate(zip(targets, predictions)):
        _, _, c = _timed(lambda: refine(pred, *args, target.vertices, body.faces, fabric, pinned=garment.pinned))
        correct.append(c)
        offset = np.array([shift * (k + 1), 0.0, 0.0], dtype=np.float32)  # a new obstacle pose, still valid
        moved = (garment.vertices + offset, *args)
        _, _, c = _timed(lambda: refine(*moved, canonical.vertices + offset, body.faces, fabric, pinned=garment.pinned))
        valid.append(c)
    return {"refine_correct_cpu_ms": float(np.median(correct)), "refine_valid_cpu_ms": float(np.median(valid))}


def bench_inference(
    model,
    sizes: Sequence[int] = (600, 2400),
    repeats: int = 7,
    *,
    garment: str = "skirt",
    body=None,
    pose: Mapping[str, Sequence[float]] | None = None,
    fabric: str = "cotton",
    threads: int = 1,
    reference=None,
) -> dict[int, dict[str, float]]:
    """Median end-to-end ms (CPU and wall) per garment size on an Anny body, with ``threads`` torch threads.

    ``model`` is what ``GarSim`` drapes with (the numpy ``GarSimRuntime``, or a torch ``GraphModel``);
    ``reference`` (optional, e.g. the same weights in torch) adds its forward time as
    ``reference_forward_cpu_ms``, measured in the same run; garments are
    ``make_garment(garment, body, target_vertices=size)`` templates; ``body`` defaults to ``AnnyBody({})``.
    Returns ``{size: {"vertices", "wall_ms", "cpu_ms", "prior_cpu_ms", "graph_cpu_ms", "forward_cpu_ms",
    "pose_seq_cpu_ms", "pose_seq_wall_ms",
    "first_call_wall_ms", "api_cpu_ms", "repeats"}}`` (medians over ``repeats`` calls after one warm-up;
    ``first_call_wall_ms`` is the very first call, with the body's caches cold; ``pose_seq_*``
    the same garment on ``repeats`` different target poses; ``api_cpu_ms`` ``GarSim.drape`` on mesh pairs;
    ``sequence_fps_*`` frames per second of ``GarSim.drape_sequence`` over those poses (defaults, first frame apart);
    ``refine_correct_cpu_ms`` / ``refine_valid_cpu_ms`` from :func:`bench_refine` on those poses).
    """
    from garsim.bodies.anny import AnnyBody
    from garsim.garments.templates import make_garment

    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    if not sizes:
        raise ValueError("sizes must list at least one garment vertex count, e.g. (600, 2400)")
    body = body if body is not None else AnnyBody({})
    canonical = body.canonical()
    pose = pose or DEFAULT_POSE
    target = body.pose({**body.t_pose(), **{k: np.asarray(v, dtype=np.float64) for k, v in pose.items()}})
    sequence = [
        body.pose({**body.t_pose(), **{k: a * np.asarray(v, dtype=np.float64) for k, v in pose.items()}})
        for a in np.linspace(0.4, 1.2, repeats)
    ]
    garments = {int(n): make_garment(garment, body, target_vertices=int(n)) for n in sizes}

    results: dict[int, dict[str, float]] = {}
    with _one_thread(model, threads):
        for n, gar in garments.items():
            args = (model, body, canonical, target, gar.vertices, gar.faces, gar.pinned, fabric, garment)
            clear_all()  # cold body: KD-tree, yaw frame and rings are built inside this call
            (_, _), first_wall, _ = _timed(lambda: drape_once(*args))
            wall, cpu, parts = [], [], []
            for _ in range(repeats):
                clear_all("garment")  # each call pays for its own garment (search, kNN, edges)
                (pred, part), w, c = _timed(lambda: drape_once(*args))
                wall.append(w)
                cpu.append(c)
                parts.append(part)
            seq_wall, seq_cpu, seq_pred = [], [], []
            for tgt in sequence:  # same garment, new poses: garment caches stay warm
                seq_args = (model, body, canonical, tgt, *args[4:])
                (p, _), w, c = _timed(lambda: drape_once(*seq_args))
                seq_wall.append(w)
                seq_cpu.append(c)
                seq_pred.append(p)
            bench_refine(body, canonical, [target], gar, [pred], fabric, shift=-1e-4)  # warm-up: kernels, caches
            refine_ms = bench_refine(body, canonical, sequence, gar, seq_pred, fabric)
            # the public call as a client makes it: mesh pairs in (bone transforms recovered from the
            # meshes), the max_vertices path for dense garments, the collision push-out; body caches warm
            sim = GarSim(model)
            mesh_args = ((canonical.vertices, body.faces), (target.vertices, body.faces), (gar.vertices, gar.faces))
            sim.drape(*mesh_args, fabric=fabric)
            api_cpu = []
            for _ in range(repeats):
                clear_all("garment")
                _, _, c = _timed(lambda: sim.drape(*mesh_args, fabric=fabric))
                api_cpu.append(c)
            # a pose sequence through the public call (defaults: refine, temporal smoothing), after its first frame
            seq_meshes = [(t.vertices, body.faces) for t in sequence]
            sim.drape_sequence(mesh_args[0], seq_meshes[:1], mesh_args[2], fabric=fabric)
            _, seq_w, seq_c = _timed(lambda: sim.drape_sequence(mesh_args[0], seq_meshes, mesh_args[2], fabric=fabric))
            if pred.shape != gar.vertices.shape or not np.isfinite(pred).all():
                raise RuntimeError(
                    f"the model returned {pred.shape} (finite: {np.isfinite(pred).all()}) "
                    f"for a {gar.vertices.shape} garment"
                )
            results[n] = {
                "vertices": int(len(gar.vertices)),
                "wall_ms": float(np.median(wall)),
                "cpu_ms": float(np.median(cpu)),
                **{k: float(np.median([p[k] for p in parts])) for k in parts[0]},
                "pose_seq_cpu_ms": float(np.median(seq_cpu)),
                "pose_seq_wall_ms": float(np.median(seq_wall)),
                "first_call_wall_ms": float(first_wall),
                "api_cpu_ms": float(np.median(api_cpu)),
                "sequence_fps_cpu": 1000.0 * len(seq_meshes) / seq_c,
                "sequence_fps_wall": 1000.0 * len(seq_meshes) / seq_w,
                **refine_ms,
                "repeats": int(repeats),
            }
    if reference is not None:
        with _one_thread(reference, threads):
            for n, gar in garments.items():
                args = (reference, body, canonical, target, gar.vertices, gar.faces, gar.pinned, fabric, garment)
                drape_once(*args)  # warm-up
                ms = [drape_once(*args)[1]["forward_cpu_ms"] for _ in range(repeats)]
                results[n]["reference_forward_cpu_ms"] = float(np.median(ms))
    return results


def bench_newton(
    sizes: Sequence[int] = (600, 2400),
    *,
    garment: str = "skirt",
    fabric: str = "cotton",
    motion_frames: int = 24,
    body=None,
    pose: Mapping[str, Sequence[float]] | None = None,
) -> dict[int, dict[str, float]]:
    """Seconds the Newton VBD simulation takes for what one GarSim call predicts: the settled
    template moved from the canonical to the same target pose as :func:`bench_inference`
    (``motion_frames`` frames, then held until it settles). The settle on the canonical body,
    which the model takes as input, is not timed.
    """
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.poses import pose_sequence
    from garsim.garments.templates import make_garment
    from garsim.geometry.skinning import dense_weights, lbs_prior, transfer_weights
    from garsim.physics.newton_sim import SimConfig, settle, simulate_poses

    body = body if body is not None else AnnyBody({})
    canonical = body.canonical()
    pose = {k: np.asarray(v, dtype=np.float64) for k, v in (pose or DEFAULT_POSE).items()}
    frames, transforms = pose_sequence(body, {**body.t_pose(), **pose}, motion_frames)
    body_w = dense_weights(body.skin_indices, body.skin_weights, len(body.bone_labels))
    results: dict[int, dict[str, float]] = {}
    for n in sizes:
        g = make_garment(garment, body, target_vertices=int(n))
        template, _ = settle(g, canonical.vertices, body.faces, fabric, SimConfig(max_settle_frames=30))
        pins = np.flatnonzero(g.pinned)
        w = transfer_weights(template[pins], canonical.vertices, body_w)
        pin_targets = np.stack([lbs_prior(template[pins], w, canonical.transforms, t) for t in transforms])
        (_, infos), wall, cpu = _timed(
            lambda: simulate_poses(template, g.faces, g.pinned, [frames], body.faces, [pin_targets], [fabric])
        )
        info = infos[-1]
        results[int(n)] = {
            "vertices": int(len(g.vertices)),
            "wall_ms": wall,
            "cpu_ms": cpu,
            "frames": int(info["motion_frames"] + info.get("hold_frames", 0)),
            "settled": bool(info.get("settled")),
        }
    return results


def format_bench(results: Mapping[int, Mapping[str, float]]) -> str:
    """One line per size: vertices, median CPU / wall ms, the prior / graph / forward split and refine."""
    lines = []
    for n, r in results.items():
        lines.append(
            f"{n:>6} (actual {r['vertices']} v): cpu {r['cpu_ms']:.1f} ms, wall {r['wall_ms']:.1f} ms "
            f"[prior {r['prior_cpu_ms']:.1f}, graph {r['graph_cpu_ms']:.1f}, forward {r['forward_cpu_ms']:.1f}"
            + (f", torch forward {r['reference_forward_cpu_ms']:.1f}" if "reference_forward_cpu_ms" in r else "")
            + "]; "
            f"same garment, new pose: cpu {r['pose_seq_cpu_ms']:.1f} ms; "
            f"first call (cold body) {r['first_call_wall_ms']:.0f} ms; "
            f"GarSim.drape on mesh pairs: cpu {r['api_cpu_ms']:.1f} ms; "
            f"drape_sequence {r['sequence_fps_cpu']:.0f} fps (cpu); "
            f"refine (new pose): correcting {r['refine_correct_cpu_ms']:.1f} ms, "
            f"valid {r['refine_valid_cpu_ms']:.1f} ms"
        )
    return "\n".join(lines)


__all__ = ["bench_inference", "bench_newton", "bench_refine", "drape_once", "format_bench", "forward", "DEFAULT_POSE"]
