"""The template body: body-part labels from skinning, cross-section profiles and measured landmarks."""

from __future__ import annotations

from typing import Any

import numpy as np

from garsim.geometry.mesh import vertex_normals

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
