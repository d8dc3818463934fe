"""The README's main job: drape every garment family on two body shapes in everyday poses, and animate one.

Writes into ``out``: ``<body>_body.obj`` (the posed body), ``<body>_<garment>.obj`` (each drape),
``demo.png`` (a grid of every drape), and the animation of one garment over the ``walk`` motion as
``walk_<garment>.glb`` / ``.usdc`` / ``.gif`` plus ``walk_<garment>.npz`` (prediction and prior, for
``garsim view``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

DEMO_BODIES: dict[str, dict[str, float]] = {
    "slim": {"gender": 0.1, "weight": 0.3, "height": 0.6},
    "broad": {"gender": 0.9, "weight": 0.75, "muscle": 0.7, "height": 0.45},
}
# garment -> (fabric, construction): the parametric templates for skirts and trousers; the implicit (offset-surface)
# construction for the upper body, whose necklines and straps sit where a garment's do (the parametric t-shirt's
# neckline reaches the armpit line) and for the long-sleeve top, which has no template
DEMO_GARMENTS: dict[str, tuple[str, str]] = {
    "skirt": ("silk", "template"),
    "top": ("cotton", "implicit"),
    "tshirt": ("cotton", "implicit"),
    "longsleeve": ("cotton", "implicit"),
    "trousers": ("denim", "template"),
    "dress": ("silk", "implicit"),
}
ANIMATED: tuple[str, str, str] = ("slim", "dress", "walk")  # body, garment, motion of the animation


@dataclass
class DemoConfig:
    out: Path
    seed: int = 0
    target_vertices: int = 800
    frames: int = 24  # frames of the animation
    fps: float = 24.0


def load_sim(log: Callable[[str], Any] = print) -> Any:
    """The shipped model, or the skinning prior (with a note on stderr) when it is missing or does not load."""
    from garsim.api import GarSim

    try:
        sim = GarSim.pretrained()
    except Exception as exc:  # noqa: BLE001 - weights absent, being rewritten, or incompatible: fall back
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(
            f"garsim demo: the shipped model could not be loaded ({first}); using the skinning prior", file=sys.stderr
        )
        sim = GarSim.prior_only()
    log(f"drape model: {sim.name}")
    return sim


def _build_garment(kind: str, construction: str, body: Any, vertices: int) -> Any:
    if construction == "implicit":
        from garsim.garments.implicit import make_implicit_garment

        return make_implicit_garment(
            kind,
            body.canonical().vertices,
            body.faces,
            body.skin_indices,
            body.skin_weights,
            body.bone_labels,
            target_vertices=vertices,
        )
    from garsim.garments.templates import make_garment

    return make_garment(kind, body, target_vertices=vertices)


def run_demo(config: DemoConfig, log: Callable[[str], Any] = print) -> list[Path]:
    """Drape, render and export (see the module doc); prints progress and per-drape times, returns the paths."""
    from garsim.api import GarSim, SequenceConfig
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.poses import EVERYDAY_LIMITS, PoseSampler, batched_matrices, motion, stack_poses
    from garsim.export import export_animation
    from garsim.geometry.io import save_mesh
    from garsim.geometry.render import render_grid
    from garsim.view import ViewData

    if config.frames < 2:
        raise ValueError(f"the animation needs at least 2 frames, got --frames {config.frames}")
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    sim = load_sim(log)
    written: list[Path] = []
    panels: list[list[tuple[np.ndarray, np.ndarray]]] = []
    titles: list[str] = []
    garments: dict[tuple[str, str], Any] = {}
    bodies: dict[str, Any] = {}
    drape_ms: list[float] = []
    for i, (name, phenotype) in enumerate(DEMO_BODIES.items()):
        body = AnnyBody(phenotype)
        bodies[name] = body
        # one everyday pose per body (fixed seed), checked for limb collisions on this body
        pose = PoseSampler(EVERYDAY_LIMITS, seed=config.seed + i, body=body).sample(1)[0]
        canonical, target = body.canonical(), body.pose(pose)
        body_path = save_mesh(out / f"{name}_body.obj", target.vertices, body.faces)
        written.append(Path(body_path))
        for kind, (fabric, construction) in DEMO_GARMENTS.items():
            t0 = time.perf_counter()
            garment = _build_garment(kind, construction, body, config.target_vertices)
            t1 = time.perf_counter()
            draped = sim.drape_on(body, canonical, target, garment, fabric)
            t2 = time.perf_counter()
            drape_ms.append(1000 * (t2 - t1))
            path = Path(save_mesh(out / f"{name}_{kind}.obj", draped, garment.faces))
            written.append(path)
            garments[(name, kind)] = garment
            panels.append([(target.vertices, body.faces), (draped, garment.faces)])
            titles.append(f"{kind} / {fabric} / {name}")
            log(
                f"{name:5s} {kind:10s} {fabric:6s} {construction:8s} {len(garment.vertices):5d} v  "
                f"built {t1 - t0:5.2f} s  draped {1000 * (t2 - t1):6.1f} ms"
            )
    log(f"{len(drape_ms)} drapes: {np.mean(drape_ms):.1f} ms per drape on average ({sim.name})")

    t0 = time.perf_counter()
    grid = render_grid(
        out / "demo.png",
        panels,
        ncols=len(DEMO_GARMENTS),
        titles=titles,
        views=("front",),
        size=320,
        suptitle=f"garsim demo ({sim.name}, {config.target_vertices} vertices)",
    )
    written.append(Path(grid))
    log(f"rendered {len(panels)} panels in {time.perf_counter() - t0:.1f} s")

    # the animation: one garment over a motion of the library, drape per frame
    body_name, kind, motion_name = ANIMATED
    body, garment = bodies[body_name], garments[(body_name, kind)]
    fabric = DEMO_GARMENTS[kind][0]
    canonical = (body.canonical().vertices, body.faces)
    targets = body.pose_batch(batched_matrices(stack_poses(motion(motion_name, config.frames))))[0]
    t0 = time.perf_counter()
    frames = sim.drape_sequence(canonical, targets, (garment.vertices, garment.faces), fabric=fabric)
    secs = time.perf_counter() - t0
    log(
        f"{motion_name}: {kind} on {body_name} body, {config.frames} frames in {secs:.2f} s "
        f"({1000 * secs / config.frames:.1f} ms per frame)"
    )
    prior = GarSim.prior_only().drape_sequence(canonical, targets, (garment.vertices, garment.faces), fabric=fabric)
    stem = out / f"{motion_name}_{kind}"
    t0 = time.perf_counter()
    metadata = sim.sequence_metadata(fabric, SequenceConfig.smoothing)
    for ext in (".glb", ".usdc", ".gif"):
        written += export_animation(
            stem.with_suffix(ext),
            frames,
            garment.faces,
            metadata=metadata,
            body_frames=targets,
            body_faces=body.faces,
            fps=config.fps,
        )
    view = ViewData(frames, garment.faces, targets, body.faces, prior, fps=config.fps, name=stem.name)
    npz = view.save_npz(stem.with_suffix(".npz"))
    written.append(npz)
    log(
        f"exported the animation (GLB, USDC, GIF, NPZ) in {time.perf_counter() - t0:.1f} s; "
        f"view it with: garsim view {npz}"
    )
    log(f"demo done in {time.perf_counter() - t_start:.1f} s")
    return written
