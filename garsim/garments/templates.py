"""Parametric garment templates fitted to a canonical (T-pose) body: skirt, top, t-shirt, trousers, dress.

Every template is built from rings of vertices around the body: at each height (or, for sleeves,
each position along the arm) the body's cross-section is measured as a polar profile (the largest
radius of the relevant body part's vertices per angle) and the ring is placed at that radius plus
a looseness margin (plus a flare for skirts). Rings are joined as quad grids (two triangles per
quad), so the resolution knob (``target_vertices``) sets one edge length ``h`` for the whole
garment. Junctions stay edge-manifold by sharing vertices: straps and shoulder panels are grids
whose first and last rows are vertices of the torso's top ring, sleeves start on the armhole loop
(side arc of the torso ring + outer edge of the shoulder panel), and trouser legs split from the
waist tube at a crotch seam shared by both legs.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, ClassVar

import numpy as np

from garsim.garments.garment import Garment
from garsim.geometry.mesh import vertex_normals
from garsim.geometry.proximity import nearest_vertices

PART_TORSO, PART_HEAD, PART_ARM_L, PART_ARM_R, PART_LEG_L, PART_LEG_R = range(6)
_ARM_BONES = ("upperarm", "lowerarm", "wrist", "finger", "metacarpal", "hand", "thumb")
_LEG_BONES = ("upperleg", "lowerleg", "foot", "toe", "thigh", "calf", "shin")
_HEAD_BONES = ("head", "eye", "jaw", "tongue", "teeth", "ear")
_PROFILE_BINS = 720
MIN_TARGET_VERTICES, MAX_TARGET_VERTICES = 200, 30000


# ---------------------------------------------------------------------------------------------
# The body: vertices, faces and a body-part label per vertex, plus measured landmarks
# ---------------------------------------------------------------------------------------------
def body_parts(
    vertices: np.ndarray, skin_indices: np.ndarray, skin_weights: np.ndarray | None, bone_labels: list[str]
) -> np.ndarray:
    """(V,) body-part code per vertex (PART_*) from its dominant skinning bone; sides from the sign of x."""
    idx = np.asarray(skin_indices, dtype=np.int64)
    if skin_weights is None:
        dom = idx[:, 0]
    else:
        dom = idx[np.arange(len(idx)), np.argmax(np.asarray(skin_weights), axis=1)]
    names = np.char.lower(np.asarray(bone_labels, dtype=str))[dom]
    is_arm = np.zeros(len(names), dtype=bool)
    is_leg = np.zeros(len(names), dtype=bool)
    is_head = np.zeros(len(names), dtype=bool)
    for prefix in _ARM_BONES:
        is_arm |= np.char.startswith(names, prefix)
    for prefix in _LEG_BONES:
        is_leg |= np.char.startswith(names, prefix)
    for prefix in _HEAD_BONES:
        is_head |= np.char.startswith(names, prefix)
    left = np.asarray(vertices)[:, 0] >= 0.0  # +X is the body's left
    parts = np.full(len(names), PART_TORSO, dtype=np.int64)
    parts[is_head] = PART_HEAD
    parts[is_arm] = np.where(left[is_arm], PART_ARM_L, PART_ARM_R)
    parts[is_leg] = np.where(left[is_leg], PART_LEG_L, PART_LEG_R)
    return parts


def _surface_samples(
    vertices: np.ndarray, faces: np.ndarray, parts: np.ndarray, spacing: float = 0.008
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices plus barycentric grid points on long faces (~``spacing`` apart), with their body part."""
    pts, labels = [vertices], [parts]
    tri = vertices[faces]
    longest = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    levels = np.clip(np.ceil(longest / spacing), 1, 6).astype(np.int64)
    for lev in range(2, 7):
        sel = levels == lev
        if not sel.any():
            continue
        i, j = np.meshgrid(np.arange(lev + 1), np.arange(lev + 1), indexing="ij")
        keep = (i + j <= lev) & ~(((i == lev) | (j == lev)) | ((i == 0) & (j == 0)))
        bary = np.stack([i[keep], j[keep], lev - i[keep] - j[keep]], 1) / lev
        pts.append(np.einsum("bk,fkd->fbd", bary, tri[sel]).reshape(-1, 3))
        labels.append(np.repeat(parts[faces[sel, 0]], len(bary)))
    return np.concatenate(pts), np.concatenate(labels)


class TemplateBody:
    """A canonical body prepared for template fitting: vertices, faces, part labels and landmarks."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, parts: np.ndarray) -> None:
        v = np.asarray(vertices, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 100 or not np.isfinite(v).all():
            raise ValueError(f"body vertices must be a finite (V>=100, 3) array, got {v.shape}")
        parts = np.asarray(parts, dtype=np.int64)
        if parts.shape != (len(v),):
            raise ValueError(f"body parts {parts.shape} must have one label per vertex ({len(v)})")
        for code, name in ((PART_TORSO, "torso"), (PART_ARM_L, "left arm"), (PART_LEG_L, "left leg")):
            if not np.any(parts == code):
                raise ValueError(f"no {name} vertices found: check skin_indices/bone_labels of the body")
        self.vertices = v
        self.faces = np.asarray(faces, dtype=np.int64)
        self.parts = parts
        self.normals = vertex_normals(v, self.faces).astype(np.float64)
        self.points, self.point_parts = _surface_samples(v, self.faces, parts)
        self._measure()

    @classmethod
    def from_skinning(
        cls,
        vertices: np.ndarray,
        faces: np.ndarray,
        skin_indices: np.ndarray,
        skin_weights: np.ndarray | None,
        bone_labels: list[str],
    ) -> TemplateBody:
        """Body parts from the dominant skinning bone of each vertex (Anny/MakeHuman bone names)."""
        return cls(vertices, faces, body_parts(vertices, skin_indices, skin_weights, bone_labels))

    @classmethod
    def from_anny(cls, body: Any) -> TemplateBody:
        """The canonical T-pose of an :class:`~garsim.bodies.anny.AnnyBody`."""
        return cls.from_skinning(
            body.canonical().vertices, body.faces, body.skin_indices, body.skin_weights, body.bone_labels
        )

    # -- landmarks ------------------------------------------------------------------------
    def _measure(self) -> None:
        v, p = self.vertices, self.parts
        torso = p == PART_TORSO
        legs = (p == PART_LEG_L) | (p == PART_LEG_R)
        self.x_mid = float(np.median(v[torso, 0]))
        # crotch: the lowest torso/leg vertex on the mid-plane (legs do not cross it below the crotch)
        mid = (torso | legs) & (np.abs(v[:, 0] - self.x_mid) < 0.012)
        self.z_crotch = float(v[mid, 2].min())
        self.z_armpit = float(min(v[p == PART_ARM_L, 2].min(), v[p == PART_ARM_R, 2].min()))
        self.z_shoulder = float(v[torso & (np.abs(v[:, 0] - self.x_mid) > 0.06), 2].max())
        self.z_floor = float(v[:, 2].min())
        self.z_ankle = float(v[legs, 2].min()) + 0.16
        # natural waist: the lowest height where the torso is within 1.5 cm of its narrowest width
        zs = np.linspace(self.z_crotch + 0.12, self.z_armpit - 0.08, 48)
        widths = np.array([self._width(z, torso | legs) for z in zs])
        near_min = widths <= widths.min() + 0.015
        self.z_waist = float(min(zs[int(np.argmax(near_min))], self.z_crotch + 0.6 * (self.z_armpit - self.z_crotch)))
        # hip: the widest torso height between the crotch and the waist
        zh = np.linspace(self.z_crotch + 0.05, self.z_waist, 30)
        wh = np.array([self._width(z, torso | legs) for z in zh])
        self.z_hip = float(zh[int(np.argmax(wh))])
        self.chest_halfwidth = 0.5 * self._width(self.z_armpit - 0.05, torso)
        above = torso & (v[:, 2] > self.z_armpit)
        self.shoulder_x = float(np.abs(v[above, 0] - self.x_mid).max())
        neck = torso & (v[:, 2] > self.z_shoulder + 0.02)
        self.neck_halfwidth = float(np.abs(v[neck, 0] - self.x_mid).max()) if neck.any() else 0.05
        self.arm_axis_l, self.arm_point_l = self._arm_axis(PART_ARM_L, 1.0)
        self.arm_axis_r, self.arm_point_r = self._arm_axis(PART_ARM_R, -1.0)

    def _arm_axis(self, part: int, sign: float) -> tuple[np.ndarray, np.ndarray]:
        """Principal axis (pointing away from the body) and centroid of the upper and lower arm (hand excluded)."""
        a = self.vertices[self.parts == part]
        reach = np.abs(a[:, 0] - self.x_mid)
        a = a[reach < reach.min() + 0.65 * (reach.max() - reach.min())]
        axis = np.linalg.svd(a - a.mean(0), full_matrices=False)[2][0]
        return axis * sign * np.sign(axis[0]), a.mean(0)

    def _width(self, z: float, mask: np.ndarray, dz: float = 0.01) -> float:
        sel = mask & (np.abs(self.vertices[:, 2] - z) < dz)
        if not sel.any():
            return 0.0
        x = self.vertices[sel, 0]
        return float(x.max() - x.min())

    def landmarks(self) -> dict[str, float]:
        """Measured heights (m): crotch, hip, waist, armpit, shoulder, floor; chest half-width."""
        return {
            "z_crotch": self.z_crotch,
            "z_hip": self.z_hip,
            "z_waist": self.z_waist,
            "z_armpit": self.z_armpit,
            "z_shoulder": self.z_shoulder,
            "z_floor": self.z_floor,
            "chest_halfwidth": self.chest_halfwidth,
            "shoulder_x": self.shoulder_x,
            "neck_halfwidth": self.neck_halfwidth,
        }


# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------
@dataclass
class _Params:
    """Base: every field is a float with a valid range and a sampling range in ``RANGES`` (valid lo, hi, sampling lo, hi)."""

    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {}

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            lo, hi = type(self).RANGES[f.name][:2]
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{type(self).__name__}.{f.name} must be a finite number, got {value!r}")
            if not lo <= value <= hi:
                raise ValueError(
                    f"{type(self).__name__}.{f.name}={value} is out of range; use a value in [{lo}, {hi}] (metres)"
                )
            setattr(self, f.name, float(value))

    def as_dict(self) -> dict[str, float]:
        return {k: v for k, v in asdict(self).items() if not k.startswith("_")}


@dataclass
class SkirtParams(_Params):
    """Skirt: ``length`` from the waistband down, ``flare`` = radius gained per metre below the hip."""

    length: float = 0.45
    flare: float = 0.3
    waist_height: float = 0.0  # waistband offset from the natural waist (negative = low rise)
    looseness: float = 0.015
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.15, 1.1, 0.22, 0.8),
        "flare": (0.0, 1.2, 0.05, 0.7),
        "waist_height": (-0.15, 0.08, -0.08, 0.04),
        "looseness": (0.008, 0.08, 0.01, 0.03),
    }


@dataclass
class TopParams(_Params):
    """Tank top: tube from below the armpits down by ``length``, two straps over the shoulders."""

    length: float = 0.35
    looseness: float = 0.02
    strap_width: float = 0.035
    armpit_clearance: float = 0.045
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.15, 0.8, 0.22, 0.42),  # sampled: hem between the waist and the hips
        "looseness": (0.01, 0.08, 0.015, 0.04),
        "strap_width": (0.015, 0.06, 0.025, 0.05),
        "armpit_clearance": (0.03, 0.1, 0.04, 0.06),
    }


@dataclass
class TShirtParams(_Params):
    """T-shirt: torso tube of ``length`` below the armpits, shoulder panels, short sleeves along the arms."""

    length: float = 0.45
    looseness: float = 0.025
    sleeve_length: float = 0.16
    sleeve_looseness: float = 0.03
    neck_width: float = 0.09  # half-width of the neck opening
    armpit_clearance: float = 0.045
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.15, 0.8, 0.32, 0.55),
        "looseness": (0.012, 0.08, 0.018, 0.04),
        "sleeve_length": (0.06, 0.3, 0.1, 0.22),
        "sleeve_looseness": (0.015, 0.08, 0.02, 0.045),
        "neck_width": (0.06, 0.13, 0.08, 0.11),
        "armpit_clearance": (0.03, 0.1, 0.04, 0.06),
    }


@dataclass
class TrousersParams(_Params):
    """Trousers: waist tube from the waistband to the crotch, two leg tubes of total ``length``."""

    length: float = 0.9
    waist_height: float = 0.0
    looseness: float = 0.02
    leg_opening: float = 0.07  # minimum radius of the leg tubes (straight vs. slim legs)
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.25, 1.2, 0.32, 0.95),  # shorts (mid-thigh) to ankle
        "waist_height": (-0.12, 0.08, -0.06, 0.04),
        "looseness": (0.01, 0.06, 0.015, 0.035),
        "leg_opening": (0.0, 0.15, 0.05, 0.1),
    }


@dataclass
class DressParams(_Params):
    """Strap dress: bodice from below the armpits, skirt flaring below the hip; ``length`` from the armpits."""

    length: float = 0.85
    flare: float = 0.3
    looseness: float = 0.02
    strap_width: float = 0.035
    armpit_clearance: float = 0.045
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.45, 1.5, 0.65, 1.1),
        "flare": (0.0, 1.2, 0.05, 0.6),
        "looseness": (0.01, 0.08, 0.015, 0.035),
        "strap_width": (0.015, 0.06, 0.025, 0.05),
        "armpit_clearance": (0.03, 0.1, 0.04, 0.06),
    }


PARAMS: dict[str, type[_Params]] = {
    "skirt": SkirtParams,
    "top": TopParams,
    "tshirt": TShirtParams,
    "trousers": TrousersParams,
    "dress": DressParams,
}


def garment_params(kind: str, params: dict[str, float] | None = None) -> _Params:
    """The validated parameter dataclass of ``kind`` (defaults for missing keys)."""
    if kind not in PARAMS:
        raise ValueError(f"unknown garment kind {kind!r}; choose one of {tuple(PARAMS)}")
    cls = PARAMS[kind]
    params = dict(params or {})
    valid = {f.name for f in fields(cls) if not f.name.startswith("_")}
    unknown = set(params) - valid
    if unknown:
        raise ValueError(f"unknown {kind} parameters {sorted(unknown)}; valid: {sorted(valid)}")
    return cls(**params)


OOD_REACH = 0.6
"""The out-of-distribution region of a parameter reaches this fraction of the way from its sampling
range to its valid limit, on both sides."""


def sample_garment_params(kind: str, rng: np.random.Generator, region: str = "train") -> dict[str, float]:
    """Random parameters of ``kind``: uniform in each field's sampling range (``region="train"``), or
    (``"ood"``) every field just outside it, between the sampling range and the valid limits, on a random side."""
    if kind not in PARAMS:
        raise ValueError(f"unknown garment kind {kind!r}; choose one of {tuple(PARAMS)}")
    if region not in ("train", "ood"):
        raise ValueError(f"region must be 'train' or 'ood', got {region!r}")
    ranges = PARAMS[kind].RANGES
    if region == "train":
        return {name: float(rng.uniform(r[2], r[3])) for name, r in ranges.items()}
    out = {}
    for name, (v_lo, v_hi, s_lo, s_hi) in ranges.items():
        below, above = s_lo - v_lo, v_hi - s_hi
        if above > 0 and (below <= 0 or rng.uniform() < 0.5):
            out[name] = float(s_hi + rng.uniform(0.05, OOD_REACH) * above)
        elif below > 0:
            out[name] = float(s_lo - rng.uniform(0.05, OOD_REACH) * below)
        else:
            out[name] = float(rng.uniform(s_lo, s_hi))
    return out


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
    pts = np.stack([c[0] + np.interp(breaks, dense, r) * np.cos(breaks), c[1] + np.interp(breaks, dense, r) * np.sin(breaks)], 1)

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
    pts = p0 + ss[:, None, None] * axis + radii[..., None] * (
        np.cos(phi)[None, :, None] * e1 + np.sin(phi)[None, :, None] * e2
    )
    idx = mesh.add(pts)
    rings = [np.asarray(loop)] + list(idx)
    mesh.grid(rings, closed=True)
    return np.stack(rings)


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


class _BodyRadius:
    """r = body radius + looseness (vertically smoothed by a running max)."""

    def __init__(self, loose: float, minimum: float = 0.0) -> None:
        self.loose, self.minimum = loose, minimum

    def __call__(self, zs: np.ndarray, centers: np.ndarray, rb: np.ndarray) -> np.ndarray:
        return np.maximum(_smooth_rows(rb) + self.loose, self.minimum)


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
    rings = _tube(body, mesh, zs, _uniform_angles(n), mask, h, _SkirtRadius(body.z_hip, p.looseness, p.flare, body.z_hip))
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
    rings, _, _ = _strapped_torso(body, mesh, h, z_top, z_bot, x_in, x_out, _BodyRadius(p.looseness),
                                       p.looseness)
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
    rings, panels, info = _strapped_torso(body, mesh, h, z_top, z_bot, x_in, x_out, _BodyRadius(p.looseness), p.looseness)
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


# ---------------------------------------------------------------------------------------------
# Finishing: orientation, clearance, public entry points
# ---------------------------------------------------------------------------------------------
def _consistent_winding(faces: np.ndarray) -> np.ndarray:
    """Flip faces so that every interior edge is traversed in opposite directions by its two faces."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order, connected_components, shortest_path

    f = np.asarray(faces, dtype=np.int64)
    nf = len(f)
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    fid = np.tile(np.arange(nf), 3)
    forward = d[:, 0] < d[:, 1]
    key = np.minimum(d[:, 0], d[:, 1]) * (f.max() + 1) + np.maximum(d[:, 0], d[:, 1])
    order = np.argsort(key, kind="stable")
    key, fid, forward = key[order], fid[order], forward[order]
    pair = np.flatnonzero(key[1:] == key[:-1])
    a, b = fid[pair], fid[pair + 1]
    same = forward[pair] == forward[pair + 1]  # same direction: one of the two faces must flip
    w = np.where(same, 2, 1)
    g = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([a, b]), np.concatenate([b, a]))), shape=(nf, nf)).tocsr()
    ncomp, labels = connected_components(g, directed=False)
    flip = np.zeros(nf, dtype=bool)
    for c in range(ncomp):
        root = int(np.flatnonzero(labels == c)[0])
        bfs, pred = breadth_first_order(g, root, directed=False, return_predecessors=True)
        dist = shortest_path(g, directed=False, unweighted=True, indices=root)
        depth = np.where(np.isfinite(dist), dist, 0).astype(np.int64)
        rel = np.asarray(g[bfs[1:], pred[bfs[1:]]]).ravel() == 2
        relative = np.zeros(nf, dtype=bool)
        relative[bfs[1:]] = rel
        nodes = bfs[1:]
        for level in range(1, int(depth[nodes].max(initial=0)) + 1):
            at = nodes[depth[nodes] == level]
            flip[at] = flip[pred[at]] ^ relative[at]
    out = f.copy()
    out[flip] = out[flip][:, ::-1]
    return out


def _orient_outward(vertices: np.ndarray, faces: np.ndarray, body: TemplateBody) -> np.ndarray:
    """Consistently wind ``faces`` and flip them so normals point away from the body."""
    f = _consistent_winding(faces)
    vn = vertex_normals(vertices, f)
    idx, _ = nearest_vertices(vertices, body.vertices)
    away = vertices - body.vertices[idx]
    if np.einsum("ij,ij->i", vn, away).mean() < 0:
        f = f[:, ::-1].copy()
    return f


def _push_out(vertices: np.ndarray, body: TemplateBody, clearance: float, inside_fn: Any) -> tuple[np.ndarray, int]:
    """Move vertices closer than ``clearance`` to the body (nearest-vertex normal offset) or inside it outward."""
    v = vertices.copy()
    moved = np.zeros(len(v), dtype=bool)
    for _ in range(4):
        idx, _ = nearest_vertices(v, body.vertices)
        n = body.normals[idx]
        off = np.einsum("ij,ij->i", v - body.vertices[idx], n)
        bad = off < 0.5 * clearance
        if inside_fn is not None:
            bad |= inside_fn(v)
        if not bad.any():
            break
        moved |= bad
        v[bad] += (clearance - off[bad])[:, None] * n[bad]
    return v, int(moved.sum())


def _inside_fn(body: TemplateBody) -> Any:
    try:
        from garsim.geometry.inside import InsideTester
    except ImportError:  # pragma: no cover - the inside module is part of the package
        return None
    tester = InsideTester(body.vertices.astype(np.float32), body.faces)
    return tester.inside


def _as_template_body(body: Any) -> TemplateBody:
    if isinstance(body, TemplateBody):
        return body
    if hasattr(body, "canonical") and hasattr(body, "skin_indices"):
        return TemplateBody.from_anny(body)
    raise TypeError(f"body must be a TemplateBody or an AnnyBody, got {type(body).__name__}")


def make_garment(
    kind: str, body: Any, params: dict[str, float] | None = None, target_vertices: int = 2500
) -> Garment:
    """Build a ``kind`` template fitted to ``body`` (AnnyBody or TemplateBody) with ~``target_vertices`` vertices."""
    p = garment_params(kind, params)
    if not isinstance(target_vertices, (int, np.integer)) or not (
        MIN_TARGET_VERTICES <= target_vertices <= MAX_TARGET_VERTICES
    ):
        raise ValueError(
            f"target_vertices={target_vertices!r} must be an integer in [{MIN_TARGET_VERTICES}, {MAX_TARGET_VERTICES}]"
        )
    tb = _as_template_body(body)
    builder = _BUILDERS[kind]
    h = 0.03
    mesh, pinned = builder(tb, p, h)
    for _ in range(3):
        ratio = mesh.n / target_vertices
        if abs(ratio - 1.0) < 0.08:
            break
        h = h * math.sqrt(ratio)
        mesh, pinned = builder(tb, p, h)
    vertices, faces = mesh.arrays()
    inside = _inside_fn(tb)
    clearance = min(0.006, 0.5 * getattr(p, "looseness", 0.01))
    vertices, moved = _push_out(vertices, tb, clearance, inside)
    faces = _orient_outward(vertices, faces, tb)
    info = p.as_dict()
    info["edge_length"] = float(h)
    info["pushed_out"] = moved
    return Garment(vertices.astype(np.float32), faces, pinned, kind, info)


def make_garment_from_arrays(
    kind: str,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    skin_indices: np.ndarray,
    skin_weights: np.ndarray | None,
    bone_labels: list[str],
    params: dict[str, float] | None = None,
    target_vertices: int = 2500,
) -> Garment:
    """:func:`make_garment` for any canonical body given as arrays plus its skinning bones."""
    tb = TemplateBody.from_skinning(body_vertices, body_faces, skin_indices, skin_weights, bone_labels)
    return make_garment(kind, tb, params, target_vertices)
