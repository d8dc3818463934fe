"""Render the five garment templates on two body shapes (canonical T-pose) -> docs/templates.png.

Run: .venv/bin/python examples/render_templates.py [--out docs/templates.png] [--vertices 2500]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from garsim.bodies.anny import AnnyBody
from garsim.demo import DEMO_BODIES
from garsim.garments.templates import make_garment
from garsim.geometry.render import render_grid

KINDS = ("skirt", "top", "tshirt", "trousers", "dress")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="docs/templates.png")
    parser.add_argument("--vertices", type=int, default=2500)
    args = parser.parse_args()
    panels, titles = [], []
    for name, phenotype in DEMO_BODIES.items():
        body = AnnyBody(phenotype)
        c = body.canonical()
        for kind in KINDS:
            g = make_garment(kind, body, target_vertices=args.vertices)
            panels.append([(c.vertices, body.faces), (g.vertices, g.faces)])
            titles.append(f"{kind} on {name} body ({g.num_vertices} v, {int(g.pinned.sum())} pinned)")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    print(
        render_grid(
            args.out,
            panels,
            ncols=len(KINDS),
            titles=titles,
            views=("front", "side"),
            suptitle="garsim templates on two Anny bodies (canonical T-pose)",
        )
    )


if __name__ == "__main__":
    main()
