"""One builder per template family (skirt, top, t-shirt, trousers, dress), each taking the edge length h."""

from __future__ import annotations

from typing import Any

import numpy as np

from garsim.garments.templates.landmarks import PART_LEG_L, PART_LEG_R, PART_TORSO, TemplateBody
from garsim.garments.templates.parameters import DressParams, SkirtParams, TopParams, TrousersParams, TShirtParams
from garsim.garments.templates.primitives import (
    _fill_zeros_circular,
    _levels,
    _Mesh,
    _ring_points,
    _sleeve,
    _slices,
    _smooth_rows,
    _strap,
    _torso_with_straps,
    _tube,
    _uniform_angles,
)


# ---------------------------------------------------------------------------------------------
# The five garments (each builder takes the edge length h)
# ---------------------------------------------------------------------------------------------
class _SkirtRadius:
    """r = running max of the body radius going down from the waist + looseness + flare below the hip."""

    def __init__(self, z_hip: float, loose: float, flare: float, z_cummax_from: float) -> None:
        self.z_hip, self.loose, self.flare, self.z_from = z_hip, loose, flare, z_cummax_from

    def centers(self, zs: np.ndarray, centers: np.ndarray) -> np.ndarray:
        out = centers.copy()
        below = zs < self.z_hip
        if below.any() and (~below).any():
            out[below] = centers[np.argmin(np.abs(zs - self.z_hip))]
        return out

    def __call__(self, zs: np.ndarray, centers: np.ndarray, rb: np.ndarray) -> np.ndarray:
        below = zs <= self.z_from
        r = rb.copy()
        if below.any():
            r[below] = np.maximum.accumulate(rb[below], axis=0)
        r = _smooth_rows(r)
        return r + self.loose + self.flare * np.maximum(0.0, self.z_hip - zs)[:, None]


def _build_skirt(body: TemplateBody, p: SkirtParams, h: float) -> tuple[_Mesh, np.ndarray]:
    z_top = body.z_waist + p.waist_height
    z_bot = z_top - p.length
    z_bot = max(z_bot, body.z_floor + 0.08)  # a long skirt on a short body ends above the feet
    mesh = _Mesh()
    zs = _levels(z_top, z_bot, h)
    circ = 2 * np.pi * 0.17
    n = max(8, int(round(circ / h)))
    n += n % 2
    mask = (body.parts == PART_TORSO) | (body.parts == PART_LEG_L) | (body.parts == PART_LEG_R)
    rings = _tube(
        body, mesh, zs, _uniform_angles(n), mask, h, _SkirtRadius(body.z_hip, p.looseness, p.flare, body.z_hip)
    )
    pinned = np.zeros(mesh.n, dtype=bool)
    pinned[rings[0]] = True
    return mesh, pinned


def _build_trousers(body: TemplateBody, p: TrousersParams, h: float) -> tuple[_Mesh, np.ndarray]:
    z_top = body.z_waist + p.waist_height
    z_split = body.z_crotch - 0.03
    z_bot = z_top - p.length
    # body-dependent limits: trousers end above the ankle and at least 5 cm below the crotch
    z_bot = min(max(z_bot, body.z_ankle), z_split - 0.05)
    mesh = _Mesh()
    torso_legs = (body.parts == PART_TORSO) | (body.parts == PART_LEG_L) | (body.parts == PART_LEG_R)
    n = max(8, int(round(2 * np.pi * 0.17 / h)))
    n += n % 2
    angles = _uniform_angles(n)  # vertex 0 at the front (-Y), n/2 at the back
    zs = _levels(z_top, z_split, h)
    waist = _tube(body, mesh, zs, angles, torso_legs, h, _SkirtRadius(body.z_hip, p.looseness, 0.0, body.z_hip))
    V, _ = mesh.arrays()
    last = waist[-1]
    front, back = V[last[0]], V[last[n // 2]]
    depth = float(np.linalg.norm(back - front))
    m = max(1, int(round(depth / h)) - 1)
    t = np.linspace(0.0, 1.0, m + 2)[1:-1]
    seam_pts = front + t[:, None] * (back - front)
    seam_pts[:, 0] = body.x_mid
    seam_pts[:, 2] -= 0.01 * np.sin(np.pi * t)
    seam = mesh.add(seam_pts)  # front -> back
    pinned = np.zeros(0, dtype=bool)
    left_loop = np.concatenate([last[: n // 2 + 1], seam[::-1]])
    right_loop = np.concatenate([last[n // 2 :], last[:1], seam])
    zl = _levels(z_split, z_bot, h)
    for side, loop, part in (("L", left_loop, PART_LEG_L), ("R", right_loop, PART_LEG_R)):
        V, _ = mesh.arrays()
        leg = body.parts == part
        vl = body.vertices[leg]
        sl = vl[np.abs(vl[:, 2] - (z_split - 0.05)) < 0.02]
        c = 0.5 * (sl[:, :2].min(0) + sl[:, :2].max(0))
        d = V[loop, :2] - c
        ang = np.arctan2(d[:, 1], d[:, 0])
        zs_leg = zl[1:]
        halfwidth = max(np.pi / len(loop), np.radians(4))
        centers, rb = _slices(body, zs_leg, leg, ang, h, halfwidth)
        rb = np.stack([_fill_zeros_circular(row) for row in rb])
        radii = np.maximum(_smooth_rows(rb) + p.looseness, p.leg_opening)
        pts = _ring_points(centers, radii, ang, zs_leg)
        # never cross the mid-plane towards the other leg: stay between the inner thigh and the middle
        inner = np.array([_inner_x(body, leg, z, side) for z in zs_leg])
        if side == "L":
            pts[..., 0] = np.maximum(pts[..., 0], (body.x_mid + inner[:, None]) / 2)
        else:
            pts[..., 0] = np.minimum(pts[..., 0], (body.x_mid + inner[:, None]) / 2)
        idx = mesh.add(pts)
        mesh.grid([loop] + list(idx), closed=True)
    pinned = np.zeros(mesh.n, dtype=bool)
    pinned[waist[0]] = True
    return mesh, pinned


def _inner_x(body: TemplateBody, leg: np.ndarray, z: float, side: str) -> float:
    vl = body.vertices[leg]
    sl = vl[np.abs(vl[:, 2] - z) < 0.03]
    if len(sl) == 0:
        return body.x_mid
    return float(sl[:, 0].min() if side == "L" else sl[:, 0].max())


def _strapped_torso(
    body: TemplateBody,
    mesh: _Mesh,
    h: float,
    z_top: float,
    z_bot: float,
    x_in: float,
    x_out: float,
    radius_fn: Any,
    loose: float,
) -> tuple[np.ndarray, dict, dict]:
    """Torso tube from ``z_top`` down with shoulder straps between |x| = x_in..x_out; returns rings, straps, info."""
    angles, _, info = _torso_with_straps(body, z_top, h, loose, x_in, x_out)
    zs = _levels(z_top, z_bot, h)
    torso = body.parts == PART_TORSO
    if z_bot < body.z_crotch:
        torso = torso | (body.parts == PART_LEG_L) | (body.parts == PART_LEG_R)
    rings = _tube(body, mesh, zs, angles, torso, h, radius_fn)
    V, _ = mesh.arrays()
    top = rings[0]
    straps = {}
    for side in ("L", "R"):
        f, b = info["strap"][side]
        straps[side] = _strap(body, mesh, V, top[f], top[b], h, loose)
    return rings, straps, info


def _band_pins(n: int, ring: np.ndarray) -> np.ndarray:
    """Pins of a strapped bodice: its top ring, an elastic band that holds it up.

    Pinning the strap middles instead fails in simulation: the straps stand off the shoulders, so
    their skinning weights come partly from the upper arm and the pinned targets stretch the straps
    up to 2x when the arms move (and straps alone, at a few VBD iterations, let the bodice slide)."""
    pinned = np.zeros(n, dtype=bool)
    pinned[np.asarray(ring, dtype=np.int64).ravel()] = True
    return pinned


def _strap_pins(n: int, straps: dict, lo: float = 0.3, hi: float = 0.7) -> np.ndarray:
    pinned = np.zeros(n, dtype=bool)
    for grid in straps.values():
        r = len(grid)
        sel = np.arange(r)
        keep = (sel >= lo * (r - 1)) & (sel <= hi * (r - 1))
        pinned[grid[keep].ravel()] = True
    return pinned


def _build_top(body: TemplateBody, p: TopParams, h: float) -> tuple[_Mesh, np.ndarray]:
    z_top = body.z_armpit - p.armpit_clearance
    z_bot = z_top - p.length
    mesh = _Mesh()
    xs = 0.5 * (body.neck_halfwidth + body.shoulder_x)
    x_in, x_out = xs - p.strap_width / 2, xs + p.strap_width / 2
    radius = _SkirtRadius(body.z_hip, p.looseness, 0.0, body.z_waist)  # no narrowing below the waist
    rings, _, _ = _strapped_torso(body, mesh, h, z_top, z_bot, x_in, x_out, radius, p.looseness)
    return mesh, _band_pins(mesh.n, rings[0])


def _build_dress(body: TemplateBody, p: DressParams, h: float) -> tuple[_Mesh, np.ndarray]:
    z_top = body.z_armpit - p.armpit_clearance
    z_bot = z_top - p.length
    z_bot = max(z_bot, body.z_floor + 0.08)  # a long dress on a short body ends above the feet
    mesh = _Mesh()
    xs = 0.5 * (body.neck_halfwidth + body.shoulder_x)
    x_in, x_out = xs - p.strap_width / 2, xs + p.strap_width / 2
    radius = _SkirtRadius(body.z_hip, p.looseness, p.flare, body.z_waist)
    rings, _, _ = _strapped_torso(body, mesh, h, z_top, z_bot, x_in, x_out, radius, p.looseness)
    return mesh, _band_pins(mesh.n, rings[0])


def _build_tshirt(body: TemplateBody, p: TShirtParams, h: float) -> tuple[_Mesh, np.ndarray]:
    z_top = body.z_armpit - p.armpit_clearance
    z_bot = z_top - p.length
    mesh = _Mesh()
    x_in = p.neck_width
    x_out = max(x_in + 0.03, body.shoulder_x - 0.02)
    # Below the waist the torso keeps the running maximum of the body's radius (as skirts and dresses do): a
    # tube that followed the body's waist-hip-thigh profile (into the gap between the legs) had to stretch
    # over the hips and thighs as soon as it slid a centimetre under its own weight (1.5x hem edges at settle).
    radius = _SkirtRadius(body.z_hip, p.looseness, 0.0, body.z_waist)
    rings, panels, info = _strapped_torso(body, mesh, h, z_top, z_bot, x_in, x_out, radius, p.looseness)
    top = rings[0]
    V, _ = mesh.arrays()
    for side in ("L", "R"):
        side_arc = top[info["side"][side]]  # front corner -> back corner
        panel = panels[side]  # rows front -> back, columns inner -> outer
        outer = panel[1:-1, -1][::-1]  # back -> front, corners excluded
        loop = np.concatenate([side_arc, outer])
        if side == "R":
            loop = loop[::-1]
        _sleeve(body, mesh, V, loop, side, h, p.sleeve_length, p.sleeve_looseness, z_top - 0.01)
        V, _ = mesh.arrays()
    return mesh, _strap_pins(mesh.n, panels, 0.35, 0.65)


_BUILDERS = {
    "skirt": _build_skirt,
    "top": _build_top,
    "tshirt": _build_tshirt,
    "trousers": _build_trousers,
    "dress": _build_dress,
}
