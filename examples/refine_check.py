"""Time garsim.refine on the Anny body: a skirt as built (valid) and moved 1.5 cm toward the body axis.

Usage: python examples/refine_check.py [600 2400 ...]   (process time, one thread; per-body work cached)
"""

from __future__ import annotations

import sys
import time

import numpy as np

from garsim.bodies.anny import AnnyBody
from garsim.garments.templates import make_garment
from garsim.geometry.inside import InsideTester
from garsim.geometry.mesh import unique_edges
from garsim.refine import obstacle, refine


def _ms(args: tuple, kwargs: dict, repeat: int = 5) -> float:
    t0 = time.process_time()
    for _ in range(repeat):
        refine(*args, **kwargs)
    return 1e3 * (time.process_time() - t0) / repeat


def main(sizes: list[int]) -> None:
    body = AnnyBody()
    bv, bf = np.asarray(body.canonical().vertices), np.asarray(body.faces)
    t0 = time.process_time()
    obstacle(bv, bf)
    print(f"per-body preparation (once per body, cached): {1e3 * (time.process_time() - t0):.0f} ms")
    tester = InsideTester(bv, bf)
    for n in sizes:
        g = make_garment("skirt", body, target_vertices=n)
        tpl = g.vertices.astype(np.float64)
        radial = tpl[:, :2] - tpl[:, :2].mean(0)
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        x = tpl.copy()
        x[:, :2] -= 0.015 * radial
        out = refine(x, tpl, g.faces, bv, bf, pinned=g.pinned)
        e = unique_edges(g.faces)
        rest = np.linalg.norm(tpl[e[:, 1]] - tpl[e[:, 0]], axis=1)
        stretch = np.linalg.norm(out[e[:, 1]] - out[e[:, 0]], axis=1) / rest
        t_valid = _ms((tpl, tpl, g.faces, bv, bf), {"pinned": g.pinned})
        t_moved = _ms((x, tpl, g.faces, bv, bf), {"pinned": g.pinned})
        print(
            f"{len(tpl)} v: valid {t_valid:.1f} ms, moved-in {t_moved:.1f} ms; inside before "
            f"{tester.inside(x).mean():.3%} after {tester.inside(out).mean():.3%}; "
            f"p99 stretch {np.percentile(stretch, 99):.3f}; moved {(np.abs(out - x).max(1) > 0).sum()} vertices"
        )


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [600, 2400])
