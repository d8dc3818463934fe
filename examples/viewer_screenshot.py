"""docs/viewer.png: `garsim view` showing a dress draped by the shipped model on the demo's slim body, mid-walk.

The drape is the demo's animation (the dress over the first frames of the walk cycle, with its prior, so the page
colours the model's correction |prediction - prior|); the viewer is served on localhost and captured by headless
Chromium with software WebGL (``garsim.view.screenshot``; ``apt-get install chromium``, nothing is downloaded).

    .venv/bin/python examples/viewer_screenshot.py [--out docs/viewer.png] [--frames 6] [--vertices 800]
"""

from __future__ import annotations

import argparse
import socket
import tempfile
from pathlib import Path


def make_scene(path: Path, frames: int, vertices: int) -> Path:
    """The demo's walk animation of the dress on the slim body: prediction, prior and body per frame -> an .npz."""
    from garsim.api import GarSim
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.poses import batched_matrices, motion, stack_poses
    from garsim.demo import ANIMATED, DEMO_BODIES, DEMO_GARMENTS, _build_garment
    from garsim.view import ViewData

    body_name, kind, motion_name = ANIMATED
    fabric, construction = DEMO_GARMENTS[kind]
    body = AnnyBody(DEMO_BODIES[body_name])
    garment = _build_garment(kind, construction, body, vertices)
    canonical = (body.canonical().vertices, body.faces)
    targets = body.pose_batch(batched_matrices(stack_poses(motion(motion_name, frames))))[0]
    mesh = (garment.vertices, garment.faces)
    draped = GarSim.default().drape_sequence(canonical, targets, mesh, fabric=fabric)
    prior = GarSim.prior_only().drape_sequence(canonical, targets, mesh, fabric=fabric)
    return ViewData(draped, garment.faces, targets, body.faces, prior, fps=24.0, name=path.name).save_npz(path)


def main() -> None:
    from garsim.view import screenshot, serve

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="docs/viewer.png", help="PNG to write")
    parser.add_argument("--frames", type=int, default=6, help="frames of the walk cycle draped")
    parser.add_argument("--vertices", type=int, default=800, help="garment resolution")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scene = make_scene(Path(tmp) / "walk_dress.npz", args.frames, args.vertices)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        viewer = serve(scene, port=port, block=False)
        try:
            print(screenshot(viewer.url, args.out))
        finally:
            viewer.stop()


if __name__ == "__main__":
    main()
