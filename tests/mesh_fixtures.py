"""Hand-made meshes for tests: open tubes whose border loops are known, OBJ text with UV seams."""

from __future__ import annotations

import numpy as np
import trimesh


def open_cylinder(
    radius: float = 1.0,
    z0: float = 0.0,
    z1: float = 1.0,
    rings: int = 6,
    sections: int = 16,
    centre: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """A tube open at both ends, outward-facing: ``rings`` rings of ``sections`` vertices from z0 (ring 0, the bottom
    border) to z1 (the last ring, the top border) -> (float32 (rings * sections, 3) vertices, int64 faces)."""
    a = 2 * np.pi * np.arange(sections) / sections
    z = np.linspace(z0, z1, rings)
    v = np.stack(
        [
            np.tile(centre[0] + radius * np.cos(a), rings),
            np.tile(centre[1] + radius * np.sin(a), rings),
            np.repeat(z, sections),
        ],
        axis=1,
    )
    i = np.arange(rings - 1)[:, None] * sections
    j = np.arange(sections)[None, :]
    a0, a1 = (i + j).ravel(), (i + (j + 1) % sections).ravel()
    b0, b1 = a0 + sections, a1 + sections
    f = np.concatenate([np.stack([a0, a1, b1], 1), np.stack([a0, b1, b0], 1)])
    return v.astype(np.float32), f.astype(np.int64)


def sleeve(radius: float = 0.045, length: float = 0.3, nu: int = 32, nv: int = 21) -> tuple[np.ndarray, np.ndarray]:
    """A sleeve: an :func:`open_cylinder` of ``radius`` turned to lie along the y axis (centred on the origin), ``nu``
    vertices around and ``nv`` along, outward faces -> (float64 vertices, int64 faces)."""
    v, f = open_cylinder(radius, -length / 2, length / 2, rings=nv, sections=nu)
    return v[:, [0, 2, 1]].astype(np.float64), f[:, ::-1].copy()  # swapping y and z mirrors: turn the faces back


def loop_rows(sections: int, ring: int) -> np.ndarray:
    """The vertex indices of ring ``ring`` of :func:`open_cylinder`."""
    return np.arange(ring * sections, (ring + 1) * sections)


def seamed_obj_text(v: np.ndarray, f: np.ndarray, normals: bool = True) -> tuple[str, np.ndarray, np.ndarray]:
    """OBJ text of (v, f) with UV seams (every 3rd face has its own vt entries, so there are more vt than v) and,
    optionally, split normals (v/vt/vn, a separate vn for the faces of the upper half) -> (text, vt, vt faces)."""
    rng = np.random.default_rng(1)
    vt = list(np.round(rng.random((len(v), 2)), 6))
    tf = f.copy()
    for i in range(0, len(f), 3):
        tf[i] = [len(vt), len(vt) + 1, len(vt) + 2]
        vt += list(np.round(rng.random((3, 2)), 6))
    vt = np.array(vt)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in v.tolist()] + [f"vt {a!r} {b!r}" for a, b in vt.tolist()]
    if normals:
        lines += ["vn 0 0 1", "vn 0 0 -1"]
        nf = np.where(v[f][:, :, 2].mean(axis=1, keepdims=True) > 0, 0, 1) * np.ones((1, 3), dtype=int)
        lines += [" ".join(["f"] + [f"{a + 1}/{t + 1}/{n + 1}" for a, t, n in zip(*c)]) for c in zip(f, tf, nf)]
    else:
        lines += [" ".join(["f"] + [f"{a + 1}/{t + 1}" for a, t in zip(*c)]) for c in zip(f, tf)]
    return "\n".join(lines) + "\n", vt, tf


def obj_lists(path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """An independent OBJ reader: (v, vt, the 'f' lines' corner tokens)."""
    v, vt, f = [], [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            v.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "vt":
            vt.append([float(x) for x in parts[1:3]])
        elif parts and parts[0] == "f":
            f.append(parts[1:])
    return np.array(v), np.array(vt), f


def plane_grid(half: float = 0.2, n: int = 21) -> tuple[np.ndarray, np.ndarray]:
    """A flat square grid in z = 0 (normal +Z), n x n vertices from -half to half: a body surface known by hand."""
    xs = np.linspace(-half, half, n)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    v = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    idx = np.arange(gx.size).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    return v, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def ridge_prism(tilt_deg: float = 10.0, half: float = 0.1, length: float = 0.4) -> tuple[np.ndarray, np.ndarray, float]:
    """A convex prism along y whose two roof faces, each tilted ``tilt_deg`` off horizontal, meet at a ridge on x = 0
    (180 - 2 tilt degrees between them, as between two facets of a limb) over a floor z = 0 of width 2 ``half`` ->
    (float64 vertices, int64 outward faces, the ridge's height)."""
    h = half * np.tan(np.radians(tilt_deg))
    v = [[x, y, z] for y in (-length / 2, length / 2) for x, z in ((-half, 0.0), (half, 0.0), (0.0, h))]
    prism = trimesh.convex.convex_hull(v)  # 8 triangles, outward
    return np.asarray(prism.vertices, dtype=np.float64), np.asarray(prism.faces, dtype=np.int64), float(h)
