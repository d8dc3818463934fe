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

Also: peak memory (``peak_memory_mb``: tracemalloc, numpy arrays and Python objects) of the forward pass and of a
whole ``GarSim.drape``; the cold first call as a user meets it, ``garsim drape`` on OBJ files in a fresh process
(``bench_cold_call``: wall time and the process's peak resident set); garments past the templates' 30,000-vertex
limit by subdivision (``bench_garment``); the machine (``machine_info``); ratios within one run against the paper's
0.1 s / 1.0 s and Newton (``bench_ratios``); a markdown table (``format_bench_markdown``; the log-log plot is
``garsim.eval.plots.plot_bench``).

Wall time on a shared machine includes waiting for other jobs; CPU time (``process_time``)
of this process is the steadier figure. Compare variants as ratios within one run.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from garsim.api import GarSim
from garsim.bodies.prior import garment_prior
from garsim.data.sample import Sample
from garsim.geometry.cache import clear_all
from garsim.model.runtime import GarSimRuntime

DEFAULT_POSE: dict[str, list[float]] = {"upperleg01.L": [-0.5, 0.0, 0.0], "upperleg01.R": [0.3, 0.0, 0.0]}
"""Target pose used by the benchmark (a step: one thigh forward, one back), on top of Anny's T-pose."""


def bench_garment(kind: str, body, target_vertices: int):
    """``make_garment(kind, body, target_vertices=n)``; past the templates' limit (``MAX_TARGET_VERTICES``,
    30,000) a template of about a quarter of ``n`` midpoint-subdivided (``garsim.garments.remesh.subdivide``)
    until it has at least ~``n`` vertices (pinned where both ends of the split edge are)."""
    from garsim.garments.garment import Garment
    from garsim.garments.remesh import subdivide, transfer_barycentric
    from garsim.garments.templates import MAX_TARGET_VERTICES, make_garment

    n, levels = int(target_vertices), 0
    while n > MAX_TARGET_VERTICES:
        n, levels = -(-n // 4), levels + 1
    g = make_garment(kind, body, target_vertices=n)
    for _ in range(levels):
        faces, mapping = subdivide(g.faces, len(g.vertices))
        pinned = transfer_barycentric(g.pinned.astype(np.float64), mapping) == 1.0
        g = Garment(transfer_barycentric(g.vertices, mapping), faces, pinned, g.kind, {**g.params, "subdivided": True})
    return g


def peak_memory_mb(fn) -> float:
    """MiB: the ``tracemalloc`` peak of ``fn()`` above what was traced when it started. It counts numpy's
    arrays (numpy reports its data buffers to tracemalloc) and Python objects, not memory that compiled
    libraries allocate themselves (scipy's KD-tree nodes, torch tensors, BLAS buffers)."""
    import tracemalloc

    started = not tracemalloc.is_tracing()
    if started:
        tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        fn()
        return (tracemalloc.get_traced_memory()[1] - base) / 2**20
    finally:
        if started:
            tracemalloc.stop()


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
    ``refine_correct_cpu_ms`` / ``refine_valid_cpu_ms`` from :func:`bench_refine` on those poses;
    ``api_wall_ms`` the wall time of those ``GarSim.drape`` calls; ``api_new_pose_cpu_ms`` / ``_wall_ms``
    ``GarSim.drape`` of the same garment on each pose of that sequence (garment caches warm);
    ``forward_peak_mb`` / ``drape_peak_mb`` the peak memory of the forward pass on a ready graph and of a
    whole ``GarSim.drape`` of a new garment, from :func:`peak_memory_mb`: tracemalloc, numpy's arrays and
    Python objects, not what compiled code allocates on its own (torch tensors, scipy's KD-trees), so for a
    torch ``model`` the forward's figure leaves out its tensors). Garments above 30,000 vertices are
    subdivided templates (:func:`bench_garment`).
    """
    from garsim.bodies.anny import AnnyBody

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
    garments = {int(n): bench_garment(garment, body, int(n)) for n in sizes}

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
            api_cpu, api_wall = [], []
            for _ in range(repeats):
                clear_all("garment")
                _, w, c = _timed(lambda: sim.drape(*mesh_args, fabric=fabric))
                api_cpu.append(c)
                api_wall.append(w)
            api_pose_cpu, api_pose_wall = [], []
            for tgt in sequence:  # the public call, same garment, new poses: garment caches stay warm
                pose_args = (mesh_args[0], (tgt.vertices, body.faces), mesh_args[2])
                _, w, c = _timed(lambda: sim.drape(*pose_args, fabric=fabric))
                api_pose_cpu.append(c)
                api_pose_wall.append(w)
            # peak memory (untimed calls: tracing slows Python down): the forward on a ready graph, and a
            # whole GarSim.drape of a new garment (its garment caches cleared first)
            prior = garment_prior(body, canonical, target, gar.vertices)
            sample = Sample(
                canonical.vertices,
                target.vertices,
                body.faces,
                gar.vertices,
                gar.faces,
                gar.pinned,
                prior,
                fabric,
                garment,
            )
            graph = model.make_graph(sample, model.config, loss_inputs=False)
            forward_peak = peak_memory_mb(lambda: forward(model, graph))
            clear_all("garment")
            drape_peak = peak_memory_mb(lambda: sim.drape(*mesh_args, fabric=fabric))
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
                "api_wall_ms": float(np.median(api_wall)),
                "api_new_pose_cpu_ms": float(np.median(api_pose_cpu)),
                "api_new_pose_wall_ms": float(np.median(api_pose_wall)),
                "forward_peak_mb": forward_peak,
                "drape_peak_mb": drape_peak,
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
    from garsim.geometry.skinning import dense_weights, lbs_prior, transfer_weights
    from garsim.physics.newton_sim import SimConfig, settle, simulate_poses

    body = body if body is not None else AnnyBody({})
    canonical = body.canonical()
    pose = {k: np.asarray(v, dtype=np.float64) for k, v in (pose or DEFAULT_POSE).items()}
    frames, transforms = pose_sequence(body, {**body.t_pose(), **pose}, motion_frames)
    body_w = dense_weights(body.skin_indices, body.skin_weights, len(body.bone_labels))
    results: dict[int, dict[str, float]] = {}
    for n in sizes:
        g = bench_garment(garment, body, int(n))
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


THREAD_VARS: tuple[str, ...] = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

PAPER_S: dict[int, float] = {600: 0.1, 2400: 1.0}
"""The paper's reported inference times (Sec. 5), seconds, by garment size (vertices)."""


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_info(threads: int = 1) -> dict[str, Any]:
    """The machine a benchmark ran on: CPU model, logical cores and those this process may use, the thread
    settings (``OMP_NUM_THREADS`` and co. as set, ``torch_threads``: the torch threads of the timed calls), memory,
    the load average when asked (other jobs share the cores), Python / numpy / platform versions and the UTC time."""
    import sys

    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count() or 0
    mem_gib = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                mem_gib = round(int(line.split()[1]) / 2**20, 1)
    except (OSError, ValueError, IndexError):
        pass
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return {
        "cpu": _cpu_model(),
        "logical_cores": os.cpu_count(),
        "usable_cores": usable,
        "memory_gib": mem_gib,
        "thread_env": {v: os.environ.get(v) for v in THREAD_VARS},
        "torch_threads": int(threads),
        "load_average": load,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
        "executable": sys.executable,
        "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


_COLD_CALL = """import sys
peak_file = sys.argv.pop(1)
code = 1
try:
    from garsim.cli import main

    code = main(sys.argv[1:])
finally:
    try:
        with open("/proc/self/status") as fh:
            kib = next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        import resource

        kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with open(peak_file, "w") as out:
        out.write(str(kib))
sys.exit(code)
"""
"""What the ``garsim`` console script runs (``sys.exit(main())``), plus the process's peak resident set on exit:
``VmHWM`` of /proc/self/status, the high-water mark of this program's own address space (``ru_maxrss`` from
``wait4`` or ``getrusage`` would also count the parent's resident set, copied into the child between fork and
exec)."""


def bench_cold_call(
    sizes: Sequence[int] = (600, 2400),
    *,
    garment: str = "skirt",
    body=None,
    pose: Mapping[str, Sequence[float]] | None = None,
    fabric: str = "cotton",
    timeout: float = 600.0,
) -> dict[int, dict[str, float]]:
    """The first call as a user meets it: ``garsim drape`` in a fresh process, once per size, on OBJ files
    (canonical and target body, garment, its pinned vertex indices) written to a temporary folder beforehand.

    ``cold_call_wall_ms``: wall time from starting the process to its exit (interpreter start, imports, the
    shipped model's load, reading the meshes, the drape with refinement, writing the draped OBJ; the
    ``garsim drape`` command has no ``--model``, so this is always the shipped model); ``cold_call_peak_rss_mb``:
    that process's peak resident set (``VmHWM`` on exit, see ``_COLD_CALL``: everything, interpreter and
    libraries included). The process runs ``python -c`` with what the ``garsim`` console script runs, and
    inherits this one's environment (``garsim drape`` sets one numpy thread unless ``OMP_NUM_THREADS`` says
    otherwise). Garments as :func:`bench_inference` (:func:`bench_garment`).
    """
    import subprocess
    import sys
    import tempfile

    from garsim.bodies.anny import AnnyBody
    from garsim.geometry.io import save_mesh

    body = body if body is not None else AnnyBody({})
    canonical = body.canonical()
    pose = pose or DEFAULT_POSE
    target = body.pose({**body.t_pose(), **{k: np.asarray(v, dtype=np.float64) for k, v in pose.items()}})
    results: dict[int, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(prefix="garsim-bench-") as tmp:
        d = Path(tmp)
        save_mesh(d / "canonical.obj", canonical.vertices, body.faces)
        save_mesh(d / "target.obj", target.vertices, body.faces)
        for n in sizes:
            g = bench_garment(garment, body, int(n))
            save_mesh(d / f"garment_{n}.obj", g.vertices, g.faces)
            np.savetxt(d / f"pinned_{n}.txt", np.flatnonzero(g.pinned), fmt="%d")
            out = d / f"draped_{n}.obj"
            cmd = [
                "drape",
                "--canonical",
                str(d / "canonical.obj"),
                "--target",
                str(d / "target.obj"),
                "--garment",
                str(d / f"garment_{n}.obj"),
                "--pinned",
                str(d / f"pinned_{n}.txt"),
                "--fabric",
                fabric,
                "--out",
                str(out),
            ]
            log, peak = d / f"log_{n}.txt", d / f"peak_{n}.txt"
            with open(log, "wb") as fh:
                w0 = time.perf_counter()
                try:
                    code = subprocess.run(
                        [sys.executable, "-c", _COLD_CALL, str(peak), *cmd],
                        stdout=fh,
                        stderr=subprocess.STDOUT,
                        stdin=subprocess.DEVNULL,
                        timeout=timeout,
                    ).returncode
                except subprocess.TimeoutExpired:
                    raise RuntimeError(f"garsim drape ({n} vertices) took over {timeout:.0f} s") from None
                wall = (time.perf_counter() - w0) * 1000.0
            if code != 0 or not out.is_file():
                tail = log.read_text(errors="replace").strip().splitlines()[-5:]
                raise RuntimeError(f"garsim drape ({n} vertices) failed with exit status {code}: " + " | ".join(tail))
            results[int(n)] = {
                "vertices": int(len(g.vertices)),
                "cold_call_wall_ms": wall,
                "cold_call_peak_rss_mb": int(peak.read_text()) / 1024.0,
            }
    return results


def bench_ratios(report: Mapping[str, Any]) -> dict[int, dict[str, float]]:
    """Ratios within one run, per size: ``paper_over_api`` (the paper's time at that size, :data:`PAPER_S`, over
    one ``GarSim.drape`` of a new garment, wall; > 1: faster than the paper), ``paper_over_network`` (the same
    over prior + graph + forward, wall), ``newton_over_api`` (Newton's simulation of the same drape over it),
    ``torch_over_numpy_forward`` (the same weights' forward in torch over the numpy runtime's, CPU),
    ``cold_over_api`` (the cold first call in a fresh process over a warm call)."""
    out: dict[int, dict[str, float]] = {}
    newton = report.get("newton") or {}
    cold = report.get("cold") or {}
    for n, r in report["garsim"].items():
        n = int(n)
        ratio: dict[str, float] = {}
        if n in PAPER_S:
            ratio["paper_s"] = PAPER_S[n]
            ratio["paper_over_api"] = 1000.0 * PAPER_S[n] / r["api_wall_ms"]
            ratio["paper_over_network"] = 1000.0 * PAPER_S[n] / r["wall_ms"]
        nw = newton.get(n, newton.get(str(n)))
        if nw:
            ratio["newton_over_api"] = nw["wall_ms"] / r["api_wall_ms"]
        if "reference_forward_cpu_ms" in r:
            ratio["torch_over_numpy_forward"] = r["reference_forward_cpu_ms"] / r["forward_cpu_ms"]
        c = cold.get(n, cold.get(str(n)))
        if c:
            ratio["cold_over_api"] = c["cold_call_wall_ms"] / r["api_wall_ms"]
        out[n] = ratio
    return out


def _cell(value: float | None, fmt: str = "{:.1f}") -> str:
    return "–" if value is None else fmt.format(value)


def format_bench_markdown(report: Mapping[str, Any], command: str | None = None) -> str:
    """The report as markdown: the command, the machine, a table of times and one of memory and ratios."""

    def get(section: str, n: int, key: str) -> float | None:
        part = report.get(section) or {}
        row = part.get(n, part.get(str(n))) or {}
        return row.get(key)

    lines = ["# garsim bench", ""]
    if command:
        lines += [f"`{command}`", ""]
    m = report.get("machine")
    if m:
        threads = ", ".join(f"{k}={v}" for k, v in m["thread_env"].items() if v is not None) or "no thread variable set"
        lines += [
            f"Machine: {m['cpu']}, {m['usable_cores']} of {m['logical_cores']} logical cores usable, "
            f"{m['memory_gib']} GiB; {threads}; torch threads {m['torch_threads']}; load average "
            f"{m['load_average']}; Python {m['python']}, numpy {m['numpy']}; {m['platform']}; {m['utc']}.",
            "",
        ]
    lines += [
        "In-process times are medians of CPU time (this process), ms; the cold call and Newton are wall time. "
        "Peak memory: tracemalloc (numpy arrays and Python objects) for the forward and GarSim.drape; the "
        "cold call's whole-process peak resident set.",
        "",
        "| vertices | forward | torch forward | prior + graph + forward | GarSim.drape, new garment "
        "| GarSim.drape, new pose | sequence (fps) | refine | cold call (s) | Newton (s) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n, r in report["garsim"].items():
        n = int(n)
        newton = get("newton", n, "wall_ms")
        cold = get("cold", n, "cold_call_wall_ms")
        lines.append(
            f"| {r['vertices']} | {_cell(r['forward_cpu_ms'])} | {_cell(r.get('reference_forward_cpu_ms'))} "
            f"| {_cell(r['cpu_ms'])} | {_cell(r['api_cpu_ms'])} | {_cell(r.get('api_new_pose_cpu_ms'))} "
            f"| {_cell(r['sequence_fps_cpu'], '{:.0f}')} | {_cell(r['refine_correct_cpu_ms'])} "
            f"| {_cell(None if cold is None else cold / 1000, '{:.2f}')} "
            f"| {_cell(None if newton is None else newton / 1000, '{:.1f}')} |"
        )
    ratios = report.get("ratios") or bench_ratios(report)
    lines += [
        "",
        "| vertices | forward peak (MiB) | GarSim.drape peak (MiB) | cold call RSS (MiB) | paper (s) "
        "| paper / GarSim.drape | Newton / GarSim.drape | torch / numpy forward | cold / warm call |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n, r in report["garsim"].items():
        q = ratios.get(int(n), ratios.get(str(n))) or {}
        lines.append(
            f"| {r['vertices']} | {_cell(r.get('forward_peak_mb'))} | {_cell(r.get('drape_peak_mb'))} "
            f"| {_cell(get('cold', int(n), 'cold_call_peak_rss_mb'), '{:.0f}')} "
            f"| {_cell(q.get('paper_s'))} | {_cell(q.get('paper_over_api'), '{:.1f}x')} "
            f"| {_cell(q.get('newton_over_api'), '{:.0f}x')} | {_cell(q.get('torch_over_numpy_forward'), '{:.1f}x')} "
            f"| {_cell(q.get('cold_over_api'), '{:.0f}x')} |"
        )
    return "\n".join(lines) + "\n"


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
            f"GarSim.drape on mesh pairs: cpu {r['api_cpu_ms']:.1f} ms"
            + (f", new pose {r['api_new_pose_cpu_ms']:.1f} ms" if "api_new_pose_cpu_ms" in r else "")
            + "; "
            + (
                f"peak memory: forward {r['forward_peak_mb']:.1f} MiB, drape {r['drape_peak_mb']:.1f} MiB; "
                if "drape_peak_mb" in r
                else ""
            )
            + f"drape_sequence {r['sequence_fps_cpu']:.0f} fps (cpu); "
            f"refine (new pose): correcting {r['refine_correct_cpu_ms']:.1f} ms, "
            f"valid {r['refine_valid_cpu_ms']:.1f} ms"
        )
    return "\n".join(lines)


__all__ = [
    "DEFAULT_POSE",
    "PAPER_S",
    "bench_cold_call",
    "bench_garment",
    "bench_inference",
    "bench_newton",
    "bench_ratios",
    "bench_refine",
    "drape_once",
    "format_bench",
    "format_bench_markdown",
    "forward",
    "machine_info",
    "peak_memory_mb",
]
