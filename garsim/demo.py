"""The README's main job: drape every garment type on two body shapes in a sampled pose."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

DEMO_BODIES: dict[str, dict[str, float]] = {
    "slim": {"gender": 0.1, "weight": 0.3, "height": 0.6},
    "broad": {"gender": 0.9, "weight": 0.75, "muscle": 0.7, "height": 0.45},
}
DEMO_GARMENTS: dict[str, str] = {"skirt": "silk", "top": "cotton", "tshirt": "cotton", "trousers": "denim",
                                 "dress": "silk"}


@dataclass
class DemoConfig:
    out: Path
    seed: int = 0
    target_vertices: int = 800


def run_demo(config: DemoConfig) -> list[Path]:
    """Write target body + draped garments (OBJ) and front/side renders (PNG); returns the paths."""
    from garsim.api import GarSim
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.poses import PoseSampler
    from garsim.garments.templates import make_garment
    from garsim.geometry.io import save_mesh
    from garsim.geometry.render import render_grid, render_views

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    sim = GarSim.default()
    poses = PoseSampler(seed=config.seed).sample(len(DEMO_BODIES))
    written: list[Path] = []
    panels: list[list[tuple[np.ndarray, np.ndarray]]] = []
    titles: list[str] = []
    for (name, phenotype), pose in zip(DEMO_BODIES.items(), poses):
        body = AnnyBody(phenotype)
        canonical, target = body.canonical(), body.pose(pose)
        save_mesh(out / f"{name}_body.obj", target.vertices, body.faces)
        written.append(out / f"{name}_body.obj")
        for kind, fabric in DEMO_GARMENTS.items():
            garment = make_garment(kind, body, target_vertices=config.target_vertices)
            draped = sim.drape_on(body, canonical, target, garment, fabric)
            path = out / f"{name}_{kind}.obj"
            save_mesh(path, draped, garment.faces)
            written.append(path)
            png = out / f"{name}_{kind}.png"
            render_views(png, [(target.vertices, body.faces), (draped, garment.faces)],
                         title=f"{kind} ({fabric}) on {name} body - {sim.name}")
            written.append(png)
            panels.append([(target.vertices, body.faces), (draped, garment.faces)])
            titles.append(f"{kind} / {fabric} / {name}")
    grid = render_grid(out / "demo_grid.png", panels, ncols=len(DEMO_GARMENTS), titles=titles,
                       views=("front",), suptitle=f"garsim demo ({sim.name})")
    written.append(Path(grid))
    return written
