"""Mesh primitives of the ring-grid templates: slices, rings, grids, the strapped torso tube, straps, sleeves."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from garsim.garments.templates.landmarks import (
    _PROFILE_BINS,
    PART_ARM_L,
    PART_ARM_R,
    PART_HEAD,
    PART_TORSO,
    TemplateBody,
)


# ---------------------------------------------------------------------------------------------
# Geometry helpers
# ---------------------------------------------------------------------------------------------
def _polar_max(points2d: np.ndarray, center: np.ndarray, angles: np.ndarray, halfwidth: float) -> np.ndarray:
    """Largest radius of ``points2d`` around ``center`` within ``halfwidth`` of each query angle (0 if none)."""
    angles = np.asarray(angles, dtype=np.float64)
    if len(points2d) == 0:
        return np.zeros(len(angles))
    d = points2d - center
    r = np.hypot(d[:, 0], d[:, 1])
    a = np.arctan2(d[:, 1], d[:, 0])
    nb = _PROFILE_BINS
    bins = np.floor((a + np.pi) / (2 * np.pi) * nb).astype(np.int64) % nb
    rb = np.zeros(nb)
    np.maximum.at(rb, bins, r)
    k = max(1, int(math.ceil(halfwidth / (2 * np.pi / nb))))
    dil = rb.copy()
    for s in range(1, k + 1):
        dil = np.maximum(dil, np.maximum(np.roll(rb, s), np.roll(rb, -s)))
    qi = np.floor((np.mod(angles + np.pi, 2 * np.pi)) / (2 * np.pi) * nb).astype(np.int64) % nb
    return dil[qi]


def _fill_zeros_circular(r: np.ndarray) -> np.ndarray:
    """Replace zero radii (no body vertex at that angle) by circular interpolation of the others."""
    good = r > 0
    if good.all() or not good.any():
        return r
    n = len(r)
    idx = np.arange(n)
    gi = idx[good]
    ext_i = np.concatenate([gi - n, gi, gi + n])
    ext_r = np.tile(r[good], 3)
    return np.interp(idx, ext_i, ext_r)


def _grid_faces(a: np.ndarray, b: np.ndarray, closed: bool) -> np.ndarray:
    """Triangles between two equally long index rows ``a`` and ``b`` (quads split, diagonals alternating)."""
    a = np.asarray(a)
    b = np.asarray(b)
    if closed:
        a1, b1 = np.roll(a, -1), np.roll(b, -1)
    else:
        a, b, a1, b1 = a[:-1], b[:-1], a[1:], b[1:]
    even = (np.arange(len(a)) % 2) == 0
    t1 = np.where(even[:, None], np.stack([a, a1, b1], 1), np.stack([a, a1, b], 1))
    t2 = np.where(even[:, None], np.stack([a, b1, b], 1), np.stack([a1, b1, b], 1))
    return np.concatenate([t1, t2], axis=0)


class _Mesh:
    """Incremental vertex/face buffer."""

    def __init__(self) -> None:
        self.verts: list[np.ndarray] = []
        self.faces: list[np.ndarray] = []
        self.n = 0

    def add(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        shape = p.shape[:-1]
        flat = p.reshape(-1, 3)
        idx = np.arange(self.n, self.n + len(flat)).reshape(shape)
        self.verts.append(flat)
        self.n += len(flat)
        return idx

    def grid(self, rows: list[np.ndarray], closed: bool) -> None:
        for a, b in zip(rows[:-1], rows[1:]):
            self.faces.append(_grid_faces(a, b, closed))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate(self.verts), np.concatenate(self.faces).astype(np.int64)


def _levels(z_top: float, z_bottom: float, h: float) -> np.ndarray:
    """Ring heights from top to bottom with spacing close to ``h`` (at least 2 rings)."""
    n = max(2, int(round((z_top - z_bottom) / h)) + 1)
    return np.linspace(z_top, z_bottom, n)


def _slices(
    body: TemplateBody, zs: np.ndarray, mask: np.ndarray, angles: np.ndarray, h: float, halfwidth: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per-height slice centres (R, 2) and body polar radii (R, n) of the ``mask`` parts' surface points."""
    v = body.points[_point_mask(body, mask)]
    dz = max(0.6 * h, 0.012)
    centers = np.zeros((len(zs), 2))
    radii = np.zeros((len(zs), len(angles)))
    have = np.zeros(len(zs), dtype=bool)
    for i, z in enumerate(zs):
        sl = v[np.abs(v[:, 2] - z) < dz]
        if len(sl) < 3:
            continue
        have[i] = True
        centers[i] = 0.5 * (sl[:, :2].min(0) + sl[:, :2].max(0))
    if not have.any():
        raise ValueError("the body has no vertices at the garment's heights; check the body and parameters")
    for d in range(2):
        centers[:, d] = np.interp(zs, zs[have][::-1], centers[have, d][::-1])
    for i, z in enumerate(zs):
        sl = v[np.abs(v[:, 2] - z) < dz]
        radii[i] = _polar_max(sl[:, :2], centers[i], angles, halfwidth)
    empty = ~(radii > 0).any(axis=1)
    if empty.any() and (~empty).any():  # a ring without body points copies the nearest measured ring
        full = np.flatnonzero(~empty)
        nearest = full[np.abs(np.flatnonzero(empty)[:, None] - full[None]).argmin(axis=1)]
        radii[empty] = radii[nearest]
    return centers, radii


def _point_mask(body: TemplateBody, vertex_mask: np.ndarray) -> np.ndarray:
    """Surface-sample mask selecting the parts that ``vertex_mask`` selects (masks are part unions)."""
    wanted = np.unique(body.parts[vertex_mask])
    return np.isin(body.point_parts, wanted)


def _ring_points(centers: np.ndarray, radii: np.ndarray, angles: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """(R, n, 3) ring vertices from centres, radii per angle and heights."""
    x = centers[:, None, 0] + radii * np.cos(angles)[None]
    y = centers[:, None, 1] + radii * np.sin(angles)[None]
    z = np.broadcast_to(zs[:, None], x.shape)
    return np.stack([x, y, z], axis=-1)


def _smooth_rows(r: np.ndarray) -> np.ndarray:
    """Conservative vertical smoothing: max of each ring with its neighbours."""
    out = r.copy()
    out[1:] = np.maximum(out[1:], r[:-1])
    out[:-1] = np.maximum(out[:-1], r[1:])
    return out


def _uniform_angles(n: int, start: float = -np.pi / 2) -> np.ndarray:
    return start + 2 * np.pi * np.arange(n) / n


def _angle_at_x(
    center: np.ndarray, dense_angles: np.ndarray, dense_r: np.ndarray, x_target: float, lo: float, hi: float
) -> float:
    """Angle in [lo, hi] where the ring point's x equals ``x_target`` (closest sample, then linear)."""
    sel = (dense_angles >= lo) & (dense_angles <= hi)
    a = dense_angles[sel]
    x = center[0] + dense_r[sel] * np.cos(a)
    order = np.argsort(x)
    return float(np.interp(x_target, x[order], a[order]))


# ---------------------------------------------------------------------------------------------
# Torso tube with strap / shoulder-panel arcs
# ---------------------------------------------------------------------------------------------


def _arc_angles(breaks: list[float], counts: list[int]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Concatenate arcs [breaks[i], breaks[i+1]) with ``counts[i]`` segments; the last arc closes at 2pi."""
    out, ranges = [], []
    start = 0
    b = list(breaks) + [breaks[0] + 2 * np.pi]
    for i, c in enumerate(counts):
        out.append(np.linspace(b[i], b[i + 1], c + 1)[:-1])
        ranges.append(np.arange(start, start + c + 1))  # includes the next arc's first vertex
        start += c
    angles = np.concatenate(out)
    n = len(angles)
    ranges = [r % n for r in ranges]
    return np.mod(angles + np.pi, 2 * np.pi) - np.pi, ranges


def _torso_with_straps(
    body: TemplateBody, z_top: float, h: float, loose: float, x_in: float, x_out: float
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Top-ring angles with strap arcs between |x| = x_in and x_out, front and back, both sides."""
    torso = body.parts == PART_TORSO
    dense = np.linspace(-np.pi, np.pi, 721)[:-1]
    c, r = _slices(body, np.array([z_top]), torso, dense, h, np.radians(3))
    c = c[0]
    r = _fill_zeros_circular(r[0]) + loose
    half = np.pi / 2
    ring_hw = float(min((r * np.cos(dense)).max(), -(r * np.cos(dense)).min()))
    x_out = min(x_out, 0.85 * ring_hw)
    x_in = min(x_in, x_out - 0.5 * h, x_out - 0.015)
    a_fi = _angle_at_x(c, dense, r, c[0] + x_in, -half, 0.0)
    a_fo = _angle_at_x(c, dense, r, c[0] + x_out, -half, 0.0)
    b_fo = _angle_at_x(c, dense, r, c[0] + x_out, 0.0, half)
    b_fi = _angle_at_x(c, dense, r, c[0] + x_in, 0.0, half)
    d_fi = _angle_at_x(c, dense, r, c[0] - x_in, half, np.pi)
    d_fo = _angle_at_x(c, dense, r, c[0] - x_out, half, np.pi)
    c_fo = _angle_at_x(c, dense, r, c[0] - x_out, -np.pi, -half)
    c_fi = _angle_at_x(c, dense, r, c[0] - x_in, -np.pi, -half)
    breaks = [c_fo, c_fi, a_fi, a_fo, b_fo, b_fi, d_fi, d_fo]
    pts = np.stack(
        [c[0] + np.interp(breaks, dense, r) * np.cos(breaks), c[1] + np.interp(breaks, dense, r) * np.sin(breaks)], 1
    )

    def seg(i: int, j: int, minimum: int) -> int:
        # arc length along the dense profile between break angles
        lo, hi = breaks[i], breaks[j] if j else breaks[0] + 2 * np.pi
        if hi < lo:
            hi += 2 * np.pi
        aa = np.linspace(lo, hi, 64)
        rr = np.interp(np.mod(aa + np.pi, 2 * np.pi) - np.pi, dense, r, period=2 * np.pi)
        p = np.stack([rr * np.cos(aa), rr * np.sin(aa)], 1)
        length = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
        return max(minimum, int(round(length / h)))

    k = max(1, int(round(float(np.linalg.norm(pts[3] - pts[2])) / h)))
    n_mid_f = seg(1, 2, 2)
    n_side = seg(3, 4, 2)
    n_mid_b = seg(5, 6, 2)
    n_side = n_side + (n_side % 2)
    counts = [k, n_mid_f, k, n_side, k, n_mid_b, k, n_side]
    angles, ranges = _arc_angles(breaks, counts)
    info = {
        "strap": {"L": (ranges[2], ranges[4][::-1]), "R": (ranges[0][::-1], ranges[6])},
        "side": {"L": ranges[3], "R": ranges[7][::-1]},
    }
    del pts
    return angles, np.array(breaks), info


def _tube(
    body: TemplateBody,
    mesh: _Mesh,
    zs: np.ndarray,
    angles: np.ndarray,
    mask: np.ndarray,
    h: float,
    radius_fn: Any,
    first_ring: np.ndarray | None = None,
) -> np.ndarray:
    """Add a tube through heights ``zs`` (top first); ``radius_fn(zs, body_radii) -> radii``. Returns ring indices."""
    halfwidth = max(np.pi / len(angles), np.radians(4))
    centers, rb = _slices(body, zs, mask, angles, h, halfwidth)
    rb = np.stack([_fill_zeros_circular(row) for row in rb])
    radii = radius_fn(zs, centers, rb)
    centers = radius_fn.centers(zs, centers) if hasattr(radius_fn, "centers") else centers
    pts = _ring_points(centers, radii, angles, zs)
    rings = []
    start = 0
    if first_ring is not None:
        rings.append(first_ring)
        start = 1
    idx = mesh.add(pts[start:])
    rings.extend(list(idx))
    mesh.grid(rings, closed=True)
    return np.stack(rings)


# ---------------------------------------------------------------------------------------------
# Straps, shoulder panels and sleeves
# ---------------------------------------------------------------------------------------------
def _strap(
    body: TemplateBody, mesh: _Mesh, P: np.ndarray, front: np.ndarray, back: np.ndarray, h: float, loose: float
) -> np.ndarray:
    """Grid over the shoulder joining ring vertices ``front`` (row 0) to ``back`` (last row); returns (rows, k+1)."""
    z_min = float(min(P[front, 2].min(), P[back, 2].min())) - 0.02
    x_lo = float(min(P[front, 0].min(), P[back, 0].min())) - 0.05
    x_hi = float(max(P[front, 0].max(), P[back, 0].max())) + 0.05
    pts = body.points
    near = (body.point_parts != PART_HEAD) & (pts[:, 2] > z_min) & (pts[:, 0] > x_lo) & (pts[:, 0] < x_hi)
    v = pts[near]
    usable = np.ones(len(v), dtype=bool)
    phis = np.linspace(0.0, np.pi, 181)
    curves = []
    for f_i, b_i in zip(front, back):
        pf, pb = P[f_i], P[b_i]
        c = 0.5 * (pf + pb)
        u = pf - c
        ru = np.linalg.norm(u)
        u = u / ru
        w = np.array([0.0, 0.0, 1.0]) - u[2] * u
        w /= np.linalg.norm(w)
        nrm = np.cross(u, w)
        d = v - c
        slab = max(h, 0.012)
        sel = usable & (np.abs(d @ nrm) < slab) & (d @ w > -0.01)
        q = np.stack([d[sel] @ u, d[sel] @ w], 1)
        prof = _polar_max(q, np.zeros(2), phis, np.radians(4))
        base = ru + (np.linalg.norm(pb - c) - ru) * phis / np.pi
        rad = np.maximum(np.where(prof > 0, prof + loose, 0.0), base)
        curve = c + rad[:, None] * (np.cos(phis)[:, None] * u + np.sin(phis)[:, None] * w)
        curve[0], curve[-1] = pf, pb
        curves.append(curve)
    curves = np.stack(curves)  # (k+1, 181, 3)
    seglen = np.linalg.norm(np.diff(curves, axis=1), axis=2)
    cum = np.concatenate([np.zeros((len(curves), 1)), np.cumsum(seglen, axis=1)], axis=1)
    rows = max(3, int(round(cum[:, -1].max() / h)))
    t = np.linspace(0.0, 1.0, rows + 1)[1:-1]
    inner = np.zeros((len(t), len(curves), 3))
    for j in range(len(curves)):
        s = cum[j] / cum[j, -1]
        for d in range(3):
            inner[:, j, d] = np.interp(t, s, curves[j, :, d])
    idx = mesh.add(inner)
    grid = [np.asarray(front)] + list(idx) + [np.asarray(back)]
    mesh.grid(grid, closed=False)
    return np.stack(grid)


def _sleeve(
    body: TemplateBody,
    mesh: _Mesh,
    P: np.ndarray,
    loop: np.ndarray,
    side: str,
    h: float,
    sleeve_length: float,
    loose: float,
    z_floor: float,
) -> np.ndarray:
    """A sleeve tube along the arm axis starting at the armhole ``loop``; returns ring indices."""
    v = body.points
    if side == "L":
        axis, p0, arm = body.arm_axis_l, body.arm_point_l, PART_ARM_L
    else:
        axis, p0, arm = body.arm_axis_r, body.arm_point_r, PART_ARM_R
    e2 = np.array([0.0, 0.0, 1.0]) - axis[2] * axis
    e2 /= np.linalg.norm(e2)
    e1 = np.cross(e2, axis)
    L = P[loop]
    dl = L - p0
    s_loop = dl @ axis
    phi_loop = np.unwrap(np.arctan2(dl @ e2, dl @ e1))
    rho = np.hypot(dl @ e2, dl @ e1)
    # ring angles: half the loop's own angle, half uniform by the loop's arc length, so that loop
    # vertices seen along the arm axis at nearly one angle (the side arc) do not collapse on the sleeve
    seg = np.linalg.norm(np.diff(np.concatenate([L, L[:1]]), axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)[:-1]]) / seg.sum()
    span = 2 * np.pi * np.sign(phi_loop[-1] - phi_loop[0] if abs(phi_loop[-1] - phi_loop[0]) > 1e-6 else 1.0)
    phi = 0.5 * phi_loop + 0.5 * (phi_loop[0] + span * cum)
    s0 = s_loop.max() + 0.5 * h
    s_end = s0 + sleeve_length
    n_rings = max(2, int(round((s_end - s0) / h)) + 1)
    ss = np.linspace(s0, s_end, n_rings)
    d = v - p0
    sv = d @ axis
    usable = ((body.point_parts == arm) | (body.point_parts == PART_TORSO)) & (v[:, 2] > z_floor)
    q_all = np.stack([d @ e1, d @ e2], 1)
    halfwidth = max(np.pi / len(loop), np.radians(4))
    radii = []
    for s in ss:
        sel = usable & (np.abs(sv - s) < max(0.6 * h, 0.012))
        prof = _polar_max(q_all[sel], np.zeros(2), phi, halfwidth)
        radii.append(_fill_zeros_circular(prof) + loose)
    radii = np.stack(radii)
    radii = _smooth_rows(radii)
    # taper from the armhole to the sleeve opening, never closer than the body profile allows
    t = np.linspace(0.0, 1.0, n_rings)[:, None] ** 0.7
    end = radii[-1][None]
    blend = (1 - t) * rho[None] + t * end
    radii = np.maximum(radii, blend)
    pts = (
        p0
        + ss[:, None, None] * axis
        + radii[..., None] * (np.cos(phi)[None, :, None] * e1 + np.sin(phi)[None, :, None] * e2)
    )
    idx = mesh.add(pts)
    rings = [np.asarray(loop)] + list(idx)
    mesh.grid(rings, closed=True)
    return np.stack(rings)
