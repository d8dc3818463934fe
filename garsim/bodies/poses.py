"""Pose library for Anny: a random pose sampler with joint limits, slerp sequences, a walk cycle.

Poses are dicts ``bone name -> axis-angle`` in Anny's ``local-ref`` parameterisation: each
rotation is expressed in world-aligned axes (X: the body's right -> left, Y: front -> back, the
body faces -Y, Z: up) at the bone's head, and is composed after the parent's rotation (a child's
world rotation is ``G_child = G_parent @ R_child``). Poses are absolute: the canonical T-pose is
``AnnyBody.t_pose()`` (upper arms rotated 40 deg about Y from Anny's rest A-pose), and the shoulder
angles below are measured from it.

Sign conventions (verified by posing Anny and watching where vertices go, see the tests):

* hip flexion brings the knee forward (-Y): ``Rx(-flexion)``; abduction moves the knee away from
  the body's midline; external rotation turns the toes outwards.
* knee flexion moves the foot backwards (+Y), about the lower-leg bone's hinge (X) axis.
* spine flexion bends forwards (+X rotation moves the head to -Y), spread evenly over spine01..05;
  lateral bend > 0 leans to the body's left (+X); twist > 0 turns the chest anticlockwise seen
  from above (+Z).
* shoulder elevation > 0 raises the arm above the T-pose, < 0 lowers it towards the hips;
  shoulder flexion > 0 swings the arm forwards (-Y); twist rotates about the arm's long axis.
* elbow flexion > 0 folds the forearm towards the upper arm about the forearm bone's hinge (X)
  axis, measured from Anny's rest bend (~43 deg).

The right side mirrors the left (axis-angle ``(x, y, z) -> (x, -y, -z)``).
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import roma
import torch
from scipy.spatial import cKDTree

from garsim.bodies.anny import T_POSE_ARM_DEGREES, AnnyBody

log = logging.getLogger(__name__)

SPINE_BONES: tuple[str, ...] = ("spine05", "spine04", "spine03", "spine02", "spine01")
"""Spine bones from the pelvis up; spine angles are split evenly over them."""

POSED_BONES: tuple[str, ...] = (
    "upperleg01.L", "upperleg01.R", "lowerleg01.L", "lowerleg01.R", *SPINE_BONES,
    "upperarm01.L", "upperarm01.R", "lowerarm01.L", "lowerarm01.R", "neck01",
)  # fmt: skip
"""Every bone a sampled or walk pose sets."""

# Hinge axes (rest-pose world coordinates) of the left knee and elbow: the X column of Anny's rest
# bone frames for the default phenotype. ``hinge_axes(body)`` reads them from a given body instead.
DEFAULT_KNEE_AXIS_L = (0.995, -0.011, 0.102)
DEFAULT_ELBOW_AXIS_L = (-0.750, -0.068, -0.658)

_MIRROR = np.array([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class JointLimits:
    """Per degree of freedom (low, high) ranges in degrees; sides share limits (mirrored)."""

    hip_flexion: tuple[float, float] = (-15.0, 85.0)
    hip_abduction: tuple[float, float] = (-8.0, 40.0)
    hip_rotation: tuple[float, float] = (-30.0, 30.0)
    knee_flexion: tuple[float, float] = (0.0, 110.0)
    spine_flexion: tuple[float, float] = (-15.0, 40.0)
    spine_lateral: tuple[float, float] = (-20.0, 20.0)
    spine_twist: tuple[float, float] = (-30.0, 30.0)
    shoulder_elevation: tuple[float, float] = (-80.0, 40.0)
    shoulder_flexion: tuple[float, float] = (-30.0, 90.0)
    shoulder_twist: tuple[float, float] = (-45.0, 45.0)
    elbow_flexion: tuple[float, float] = (-35.0, 100.0)
    neck_flexion: tuple[float, float] = (-20.0, 30.0)
    neck_lateral: tuple[float, float] = (-20.0, 20.0)
    neck_twist: tuple[float, float] = (-40.0, 40.0)

    def __post_init__(self) -> None:
        for f in fields(self):
            lo, hi = getattr(self, f.name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi and max(abs(lo), abs(hi)) <= 180.0):
                raise ValueError(
                    f"joint limit {f.name}=({lo}, {hi}) must be finite degrees with low <= high, |.| <= 180"
                )


ARMS_DOWN = -60.0
"""Shoulder elevation (degrees below the T-pose) of the motion library's arms-down poses (walk, standing). Lower
arms overlap the torso: on the default Anny body, 5.6% of the upper arm's surface (offset 4 mm outwards) is inside
the body at -75 and 3.0% at -70 (1.3% at -60, none at -55), a self-intersection that leaves a sleeve no room."""

EVERYDAY_LIMITS = JointLimits(
    hip_flexion=(-10.0, 40.0),
    hip_abduction=(-5.0, 12.0),
    hip_rotation=(-15.0, 15.0),
    knee_flexion=(0.0, 45.0),
    spine_flexion=(-8.0, 20.0),
    spine_lateral=(-8.0, 8.0),
    spine_twist=(-15.0, 15.0),
    shoulder_elevation=(-75.0, 25.0),
    shoulder_flexion=(-20.0, 50.0),
    shoulder_twist=(-20.0, 20.0),
    elbow_flexion=(0.0, 70.0),
    neck_flexion=(-10.0, 20.0),
    neck_lateral=(-10.0, 10.0),
    neck_twist=(-20.0, 20.0),
)
"""Everyday poses (standing, stepping, arms down to raised, mild bending): the ranges users' poses mostly fall in."""


SIDED_DOFS: tuple[str, ...] = (
    "hip_flexion", "hip_abduction", "hip_rotation", "knee_flexion",
    "shoulder_elevation", "shoulder_flexion", "shoulder_twist", "elbow_flexion",
)  # fmt: skip
"""Degrees of freedom sampled independently for the left (``_L``) and right (``_R``) side."""

CENTRAL_DOFS: tuple[str, ...] = (
    "spine_flexion",
    "spine_lateral",
    "spine_twist",
    "neck_flexion",
    "neck_lateral",
    "neck_twist",
)


def angle_names() -> tuple[str, ...]:
    """Names of the sampled joint angles, e.g. ``hip_flexion_L`` and ``spine_twist``."""
    return tuple(f"{d}_{s}" for d in SIDED_DOFS for s in "LR") + CENTRAL_DOFS


def limit_of(limits: JointLimits, angle_name: str) -> tuple[float, float]:
    """The (low, high) range in degrees of one angle name (``hip_flexion_L`` -> ``limits.hip_flexion``)."""
    return getattr(limits, re.sub(r"_[LR]$", "", angle_name))


@dataclass(frozen=True)
class HingeAxes:
    """Rest-pose world axes of the left knee and elbow hinges (unit vectors; the right side mirrors)."""

    knee_l: tuple[float, float, float] = DEFAULT_KNEE_AXIS_L
    elbow_l: tuple[float, float, float] = DEFAULT_ELBOW_AXIS_L


def hinge_axes(body: AnnyBody) -> HingeAxes:
    """The knee/elbow hinge axes of ``body``: the X column of Anny's rest bone frames (phenotype-dependent)."""
    rest = body.rest_bone_poses

    def axis(name: str) -> tuple[float, float, float]:
        a = rest[body.bone_index(name), :3, 0]
        return tuple(float(x) for x in a / np.linalg.norm(a))

    return HingeAxes(knee_l=axis("lowerleg01.L"), elbow_l=axis("lowerarm01.L"))


# -- angles <-> poses ----------------------------------------------------------------------------
def sample_joint_angles(rng: np.random.Generator, n: int, limits: JointLimits | None = None) -> dict[str, np.ndarray]:
    """``n`` sets of joint angles in degrees, uniform within ``limits``: name -> (n,) array."""
    limits = limits or JointLimits()
    return {name: rng.uniform(*limit_of(limits, name), size=n) for name in angle_names()}


def stack_angles(angle_sets: Sequence[Mapping[str, float]]) -> dict[str, np.ndarray]:
    """A list of joint-angle dicts (degrees) -> name -> (n,) arrays; missing angles are 0."""
    names = sorted({k for a in angle_sets for k in a})
    return {k: np.array([float(a.get(k, 0.0)) for a in angle_sets]) for k in names}


def _rot(axis: Sequence[float], degrees: np.ndarray) -> torch.Tensor:
    """(n, 3, 3) rotations about a fixed unit ``axis`` by ``degrees`` (n,)."""
    a = torch.as_tensor(np.asarray(axis, dtype=np.float64))
    a = a / torch.linalg.norm(a)
    angles = torch.as_tensor(np.radians(np.asarray(degrees, dtype=np.float64)))
    return roma.rotvec_to_rotmat(angles[:, None] * a[None, :])


def _compose(*mats: torch.Tensor) -> np.ndarray:
    """Product of (n, 3, 3) rotations (leftmost applied last) -> (n, 3) axis-angle."""
    return roma.rotmat_to_rotvec(roma.rotmat_composition(list(mats)) if len(mats) > 1 else mats[0]).numpy()


X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def angles_to_pose(angles: Mapping[str, np.ndarray | float], axes: HingeAxes | None = None) -> dict[str, np.ndarray]:
    """Joint angles in degrees (name -> (n,) or scalar; missing angles are 0) -> pose dict of (n, 3) axis-angles."""
    axes = axes or HingeAxes()
    unknown = set(angles) - set(angle_names())
    if unknown:
        raise ValueError(f"unknown joint angles {sorted(unknown)}; valid names: {angle_names()}")
    arrays = {k: np.atleast_1d(np.asarray(v, dtype=np.float64)) for k, v in angles.items()}
    n = max((len(v) for v in arrays.values()), default=1)
    get = {name: np.broadcast_to(arrays.get(name, np.zeros(1)), (n,)) for name in angle_names()}
    pose: dict[str, np.ndarray] = {}
    t_pose_deg = np.full(n, T_POSE_ARM_DEGREES)
    for side in "LR":
        mirror = _MIRROR if side == "R" else np.ones(3)

        def left(rotvec: np.ndarray) -> np.ndarray:
            return rotvec * mirror  # a left-side rotation vector, mirrored to the right side

        a = lambda dof: get[f"{dof}_{side}"]  # noqa: E731
        hip = _compose(_rot(X, -a("hip_flexion")), _rot(Y, -a("hip_abduction")), _rot(Z, a("hip_rotation")))
        knee = _compose(_rot(axes.knee_l, a("knee_flexion")))
        arm = _compose(
            _rot(Z, -a("shoulder_flexion")), _rot(Y, -a("shoulder_elevation")), _rot(X, a("shoulder_twist")),
            _rot(Y, -t_pose_deg),
        )  # fmt: skip
        elbow = _compose(_rot(axes.elbow_l, a("elbow_flexion")))
        pose[f"upperleg01.{side}"] = left(hip)
        pose[f"lowerleg01.{side}"] = left(knee)
        pose[f"upperarm01.{side}"] = left(arm)
        pose[f"lowerarm01.{side}"] = left(elbow)
    k = len(SPINE_BONES)
    spine = _compose(
        _rot(X, get["spine_flexion"] / k), _rot(Y, get["spine_lateral"] / k), _rot(Z, get["spine_twist"] / k)
    )
    for bone in SPINE_BONES:
        pose[bone] = spine.copy()
    pose["neck01"] = _compose(_rot(X, get["neck_flexion"]), _rot(Y, get["neck_lateral"]), _rot(Z, get["neck_twist"]))
    return pose


def sample_pose(
    rng: np.random.Generator, limits: JointLimits | None = None, axes: HingeAxes | None = None
) -> dict[str, np.ndarray]:
    """One random pose within ``limits`` (bone -> (3,) axis-angle), without the collision check."""
    pose = angles_to_pose(sample_joint_angles(rng, 1, limits), axes)
    return {k: v[0] for k, v in pose.items()}


def batched_matrices(pose: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Batched axis-angles (bone -> (n, 3)) -> homogeneous (n, 4, 4) rotations.

    ``AnnyBody.pose_batch`` reads a (3, 3) array as one rotation matrix, so a batch of exactly three
    axis-angles would be misread; matrices are unambiguous for any batch size.
    """
    out = {}
    for bone, r in pose.items():
        rv = torch.as_tensor(np.asarray(r, dtype=np.float64).reshape(-1, 3))
        h = torch.eye(4, dtype=torch.float64).repeat(len(rv), 1, 1)
        h[:, :3, :3] = roma.rotvec_to_rotmat(rv)
        out[bone] = h.numpy()
    return out


def unbatch(pose: Mapping[str, np.ndarray], i: int) -> dict[str, np.ndarray]:
    """Pose ``i`` of a batched pose dict (bone -> (n, 3))."""
    return {k: np.asarray(v)[i] for k, v in pose.items()}


# -- limb-through-body test ----------------------------------------------------------------------
_LIMB_PATTERNS = {
    "arm": r"^(upperarm|lowerarm|wrist|finger|metacarpal)",
    "leg": r"^(upperleg|lowerleg|foot|toe)",
}
PART_PAIRS: tuple[tuple[str, str], ...] = (
    ("arm.L", "torso"), ("arm.R", "torso"), ("leg.L", "torso"), ("leg.R", "torso"),
    ("leg.L", "leg.R"), ("leg.R", "leg.L"),
    ("arm.L", "leg.L"), ("arm.L", "leg.R"), ("arm.R", "leg.L"), ("arm.R", "leg.R"),
)  # fmt: skip
"""(points, surface) pairs tested: limbs against the torso, the legs against each other, arms against legs."""


def body_part(bone: str) -> str:
    """Body part of a bone: ``arm.L``/``arm.R``/``leg.L``/``leg.R``, ``eye`` (inner geometry) or ``torso``."""
    if bone.startswith("eye"):
        return "eye"
    for limb, pattern in _LIMB_PATTERNS.items():
        if re.match(pattern, bone) and bone[-2:] in (".L", ".R"):
            return f"{limb}{bone[-2:]}"
    return "torso"


@dataclass(frozen=True)
class CollisionConfig:
    """Limb-through-body test: depth threshold, query radius, and the junction band left out."""

    depth: float = 0.01
    """A vertex with (x - b) . n < -depth (metres) is inside the surface (nearest vertex b, normal n)."""
    radius: float = 0.04
    """Only points within this distance of their nearest surface vertex count: far from an open part's
    seam the nearest-vertex normal says nothing. A limb that passes through a surface crosses it, so
    its shallow vertices (depth .. radius) are always caught."""
    junction: float = 0.04
    """Limb vertices within this distance of the other part in the canonical pose (the shoulder, hip
    and inner-thigh skin, where linear blend skinning folds) are not tested against that part."""


class LimbCollisionChecker:
    """Finds poses whose limbs pass through the torso, the other leg, or a leg (arms), vectorised."""

    def __init__(self, body: AnnyBody, config: CollisionConfig | None = None) -> None:
        self.config = config or CollisionConfig()
        w, idx = body.skin_weights, body.skin_indices
        dominant = idx[np.arange(len(w)), w.argmax(axis=1)]
        bone_part = np.array([body_part(b) for b in body.bone_labels])
        self.part = bone_part[dominant]
        self.faces = body.faces
        # Incident faces of every vertex, padded with -1, for normals at a few vertices at a time.
        f = body.faces
        vert = f.ravel()
        order = np.argsort(vert, kind="stable")
        degree = np.bincount(vert, minlength=body.num_vertices)
        start = np.concatenate([[0], np.cumsum(degree)[:-1]])
        slot = np.arange(len(vert)) - np.repeat(start, degree)
        self._ring = np.full((body.num_vertices, degree.max()), -1, dtype=np.int64)
        self._ring[vert[order], slot] = order // 3
        self._surface = {p: np.flatnonzero(self.part == p) for p in {b for _, b in PART_PAIRS}}
        canonical = body.canonical().vertices.astype(np.float64)
        self._tested: dict[tuple[str, str], np.ndarray] = {}
        for a, b in PART_PAIRS:
            pts = np.flatnonzero(self.part == a)
            dist, _ = cKDTree(canonical[self.part == b]).query(canonical[pts])
            self._tested[(a, b)] = pts[dist >= self.config.junction]

    def vertex_normals(self, vertices: np.ndarray, which: np.ndarray | None = None) -> np.ndarray:
        """Area-weighted unit normals of body vertices (V, 3) at vertex ids ``which`` (default: all)."""
        v = np.asarray(vertices, dtype=np.float64)
        ring = self._ring if which is None else self._ring[which]  # (N, max degree) incident faces, -1 padded
        tri = v[self.faces[np.maximum(ring, 0)]]  # (N, D, 3, 3)
        fn = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
        vn = (fn * (ring >= 0)[..., None]).sum(axis=1)
        return vn / np.maximum(np.linalg.norm(vn, axis=-1, keepdims=True), 1e-20)

    def penetration_counts(self, vertices: np.ndarray) -> np.ndarray:
        """(B, len(PART_PAIRS)) number of vertices of each part found inside the other, per pose."""
        v = np.asarray(vertices, dtype=np.float64)
        if v.ndim == 2:
            v = v[None]
        counts = np.zeros((len(v), len(PART_PAIRS)), dtype=np.int64)
        r = self.config.radius
        lows = {p: v[:, ix].min(axis=1) - r for p, ix in self._surface.items()}
        highs = {p: v[:, ix].max(axis=1) + r for p, ix in self._surface.items()}
        for i in range(len(v)):
            trees = {p: cKDTree(v[i, ix], balanced_tree=False, compact_nodes=False) for p, ix in self._surface.items()}
            boxes = {p: (lows[p][i], highs[p][i]) for p in self._surface}
            for k, (a, b) in enumerate(PART_PAIRS):
                pts = v[i, self._tested[(a, b)]]
                lo, hi = boxes[b]  # only points within the radius of the surface's bounding box can hit
                pts = pts[((pts >= lo) & (pts <= hi)).all(axis=1)]
                if len(pts) == 0:
                    continue
                dist, near = trees[b].query(pts, distance_upper_bound=r)
                hit = np.isfinite(dist)
                if not hit.any():
                    continue
                q = self._surface[b][near[hit]]
                offset = np.einsum("ij,ij->i", pts[hit] - v[i, q], self.vertex_normals(v[i], q))
                counts[i, k] = int((offset < -self.config.depth).sum())
        return counts

    def valid(self, vertices: np.ndarray) -> np.ndarray:
        """(B,) True where no limb passes through the torso, the other leg or a leg."""
        return self.penetration_counts(vertices).sum(axis=1) == 0


# -- sampler -------------------------------------------------------------------------------------
class PoseSampler:
    """Random valid poses: joint angles uniform within limits, limb-through-body poses rejected.

    Reproducible: the same ``seed`` (and body, limits, batch size) gives the same poses. ``body``
    defaults to the default-phenotype ``AnnyBody``; the knee/elbow hinges and the collision test
    use that body.
    """

    def __init__(
        self,
        limits: JointLimits | None = None,
        seed: int | None = 0,
        body: AnnyBody | None = None,
        collision: CollisionConfig | None = None,
        batch_size: int = 32,
        max_batches: int = 1000,
    ) -> None:
        self.body = body if body is not None else AnnyBody()
        self.limits = limits or JointLimits()
        self.rng = np.random.default_rng(seed)
        self.axes = hinge_axes(self.body)
        self.checker = LimbCollisionChecker(self.body, collision)
        self.batch_size = batch_size
        self.max_batches = max_batches
        self.acceptance_rate: float | None = None

    def sample(self, n: int, return_angles: bool = False):
        """``n`` valid poses (list of bone -> (3,) axis-angle dicts); with ``return_angles`` also their angles."""
        if n < 0:
            raise ValueError(f"number of poses must be >= 0, got {n}")
        poses: list[dict[str, np.ndarray]] = []
        angles: list[dict[str, float]] = []
        tried = 0
        for _ in range(self.max_batches):
            if len(poses) >= n:
                break
            batch_angles = sample_joint_angles(self.rng, self.batch_size, self.limits)
            batch_pose = angles_to_pose(batch_angles, self.axes)
            vertices, _ = self.body.pose_batch(batched_matrices(batch_pose))
            ok = self.checker.valid(vertices)
            tried += self.batch_size
            for i in np.flatnonzero(ok)[: n - len(poses)]:
                poses.append(unbatch(batch_pose, i))
                angles.append({k: float(v[i]) for k, v in batch_angles.items()})
        if len(poses) < n:
            raise RuntimeError(
                f"only {len(poses)} of {n} poses passed the collision test in {tried} tries; widen the joint limits"
            )
        self.acceptance_rate = len(poses) / max(tried, 1)
        return (poses, angles) if return_angles else poses


# -- sequences -----------------------------------------------------------------------------------
def interpolate_poses(
    pose_a: Mapping[str, np.ndarray], pose_b: Mapping[str, np.ndarray], num_frames: int
) -> list[dict[str, np.ndarray]]:
    """``num_frames`` poses from ``pose_a`` to ``pose_b`` (both included), slerp per bone; missing bones = identity."""
    if num_frames < 2:
        raise ValueError(f"num_frames must be >= 2 (both ends are included), got {num_frames}")
    bones = sorted(set(pose_a) | set(pose_b))
    if not bones:
        return [{} for _ in range(num_frames)]

    def rotvecs(pose: Mapping[str, np.ndarray]) -> torch.Tensor:
        out = []
        for bone in bones:
            r = np.asarray(pose.get(bone, np.zeros(3)), dtype=np.float64)
            if r.shape != (3,):
                raise ValueError(
                    f"bone {bone!r}: interpolate_poses takes axis-angle (3,) rotations, got shape {r.shape}"
                )
            out.append(r)
        return torch.as_tensor(np.stack(out))

    ra, rb = rotvecs(pose_a), rotvecs(pose_b)
    steps = torch.linspace(0.0, 1.0, num_frames, dtype=torch.float64)
    frames = roma.rotvec_slerp(ra, rb, steps).numpy()  # (T, bones, 3)
    frames[0], frames[-1] = ra.numpy(), rb.numpy()  # exact ends (slerp's round trip is ~1e-16 off)
    return [{bone: frames[t, j] for j, bone in enumerate(bones)} for t in range(num_frames)]


def stack_poses(poses: Sequence[Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """A list of pose dicts -> one batched dict (bone -> (T, 3)); missing bones are identity."""
    bones = sorted({b for p in poses for b in p})
    return {b: np.stack([np.asarray(p.get(b, np.zeros(3)), dtype=np.float64) for p in poses]) for b in bones}


def pose_sequence(
    body: AnnyBody, target_pose: Mapping[str, np.ndarray], num_frames: int
) -> tuple[np.ndarray, np.ndarray]:
    """Body moving from the T-pose to ``target_pose``: vertices (T, V, 3) and skinning transforms (T, J, 4, 4)."""
    frames = interpolate_poses(body.t_pose(), target_pose, num_frames)
    return body.pose_batch(batched_matrices(stack_poses(frames)))


# -- walk cycle ----------------------------------------------------------------------------------
LEG_LENGTH = 0.85
"""Hip-to-floor length (m) used to turn a stride into a hip swing amplitude."""


def walk_pose(phase: float | np.ndarray, stride: float = 0.6, axes: HingeAxes | None = None) -> dict[str, np.ndarray]:
    """Walk pose(s) at ``phase`` (radians, period 2 pi): legs swing in counter-phase, arms opposite the legs.

    ``stride`` is the distance (m) between the feet at full step; the hip swing amplitude is
    ``asin(stride / (2 * LEG_LENGTH))``; the arms hang at ``ARMS_DOWN``.
    Returns (n, 3) axis-angles per bone for n phases.
    """
    if not (0.0 < stride < 2 * LEG_LENGTH):
        raise ValueError(f"stride must be in (0, {2 * LEG_LENGTH}) metres, got {stride}")
    phi = np.atleast_1d(np.asarray(phase, dtype=np.float64))
    amp = math.degrees(math.asin(stride / (2 * LEG_LENGTH)))
    s = np.sin(phi)
    angles = {
        # Left leg forward while sin(phi) > 0; the right leg is half a period behind.
        "hip_flexion_L": amp * s,
        "hip_flexion_R": -amp * s,
        # The knee bends while the leg swings forwards (the quarter period before it reaches the front).
        "knee_flexion_L": 5.0 + 55.0 * np.clip(np.cos(phi - math.pi / 4), 0.0, None) ** 2,
        "knee_flexion_R": 5.0 + 55.0 * np.clip(np.cos(phi + math.pi - math.pi / 4), 0.0, None) ** 2,
        "hip_abduction_L": np.full_like(phi, 3.0),
        "hip_abduction_R": np.full_like(phi, 3.0),
        # Arms down by the sides, swinging opposite to the leg of the same side.
        "shoulder_elevation_L": np.full_like(phi, ARMS_DOWN),
        "shoulder_elevation_R": np.full_like(phi, ARMS_DOWN),
        "elbow_flexion_L": 10.0 + 10.0 * np.clip(-s, 0.0, None),
        "elbow_flexion_R": 10.0 + 10.0 * np.clip(s, 0.0, None),
        "spine_twist": -0.4 * amp * s,
    }
    # With the arm lowered, a forward swing is a rotation about X applied after the arm is lowered.
    pose = angles_to_pose(angles, axes)
    arm_amp = 0.8 * amp
    # Rx(-a) swings a hanging arm forwards (-Y): the left arm goes forwards while the left leg is back (s < 0).
    for side, sign in (("L", 1.0), ("R", -1.0)):
        swing = _rot(X, sign * arm_amp * s)
        base = roma.rotvec_to_rotmat(torch.as_tensor(pose[f"upperarm01.{side}"]))
        pose[f"upperarm01.{side}"] = roma.rotmat_to_rotvec(swing @ base).numpy()
    return pose


def walk_cycle(
    num_frames: int, stride: float = 0.6, axes: HingeAxes | None = None, include_end: bool = True
) -> list[dict[str, np.ndarray]]:
    """One period of a procedural walk in ``num_frames`` steps; with ``include_end`` frame N repeats frame 0."""
    if num_frames < 2:
        raise ValueError(f"num_frames must be >= 2, got {num_frames}")
    count = num_frames + 1 if include_end else num_frames
    phases = 2.0 * math.pi * np.arange(count) / num_frames
    batched = walk_pose(phases, stride, axes)
    return [unbatch(batched, i) for i in range(count)]


# -- motion library ------------------------------------------------------------------------------
def _pose(angles: Mapping[str, float]) -> dict[str, np.ndarray]:
    return unbatch(angles_to_pose(angles), 0)


STANDING: dict[str, np.ndarray] = _pose({"shoulder_elevation_L": ARMS_DOWN, "shoulder_elevation_R": ARMS_DOWN})
"""Standing with the arms down at the sides (the everyday rest pose the motions start from)."""


def motion(name: str, num_frames: int = 30) -> list[dict[str, np.ndarray]]:
    """A pose sequence of the motion library, ``num_frames`` poses (>= 2): ``walk`` (one cycle), ``raise_arms`` (from
    standing, arms down, to raised forwards and back), ``turn`` (a torso twist to the left, back, to the right and
    back), ``sit_down`` (hips and knees bend to a chair-height sit). All but the walk start from ``STANDING`` and pass
    through their keyframes on whole frames (``resample_poses``), so they need at least as many frames as keyframes
    (raise_arms 3, turn 5, sit_down 2)."""
    if num_frames < 2:
        raise ValueError(f"num_frames must be >= 2, got {num_frames}")
    if name == "walk":
        return walk_cycle(num_frames, include_end=False)
    arms_down = {"shoulder_elevation_L": ARMS_DOWN, "shoulder_elevation_R": ARMS_DOWN}
    keyframes = {
        "raise_arms": [
            _pose(
                {
                    "shoulder_elevation_L": 20.0,
                    "shoulder_elevation_R": 20.0,
                    "shoulder_flexion_L": 30.0,
                    "shoulder_flexion_R": 30.0,
                }
            ),
            STANDING,
        ],
        "turn": [
            _pose({**arms_down, "spine_twist": 25.0}),
            STANDING,
            _pose({**arms_down, "spine_twist": -25.0}),
            STANDING,
        ],
        "sit_down": [
            _pose(
                {
                    **arms_down,
                    "hip_flexion_L": 80.0,
                    "hip_flexion_R": 80.0,
                    "knee_flexion_L": 85.0,
                    "knee_flexion_R": 85.0,
                    "spine_flexion": 10.0,
                }
            )
        ],
    }
    if name not in keyframes:
        raise ValueError(f"unknown motion {name!r}; choose one of {MOTIONS}")
    return resample_poses([STANDING, *keyframes[name]], num_frames)


MOTIONS: tuple[str, ...] = ("walk", "raise_arms", "turn", "sit_down")


# -- pose sequences from files -------------------------------------------------------------------
class PoseFileError(ValueError):
    """A pose file garsim cannot read; the message names the file and what to fix."""


def _as_rotvec(name: str, value: object, where: str) -> np.ndarray:
    """One bone's rotation: axis-angle (3,) or a 3x3 / 4x4 rotation matrix -> axis-angle (3,)."""
    try:
        r = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise PoseFileError(f"{where}: bone {name!r} is not an array of numbers") from None
    if not np.isfinite(r).all():
        raise PoseFileError(f"{where}: bone {name!r} has a non-finite rotation")
    if r.shape == (4, 4):
        r = r[:3, :3]
    if r.shape == (3, 3):
        if np.abs(r @ r.T - np.eye(3)).max() > 1e-4 or np.linalg.det(r) <= 0:
            raise PoseFileError(f"{where}: bone {name!r} is a matrix that is not a rotation (orthonormal, det 1)")
        return roma.rotmat_to_rotvec(torch.as_tensor(r)).numpy()
    if r.shape != (3,):
        raise PoseFileError(
            f"{where}: bone {name!r} must be an axis-angle [x, y, z] (radians) or a 3x3 / 4x4 rotation matrix, "
            f"got shape {r.shape}"
        )
    if np.linalg.norm(r) > 2.0 * math.pi:
        raise PoseFileError(
            f"{where}: bone {name!r} turns by {np.linalg.norm(r):.3g} rad: axis-angles are radians (at most 2 pi)"
        )
    return r


def _frame_pose(frame: Mapping[str, object], where: str) -> dict[str, np.ndarray]:
    """One frame of a pose file: Anny bones -> axis-angle, or garsim joint angles (degrees) -> axis-angle."""
    if not isinstance(frame, Mapping):
        raise PoseFileError(f"{where}: a frame must be an object of bone (or joint-angle) names")
    if not frame:  # every bone left out: Anny's rest pose
        return {}
    keys = set(frame)
    angles = keys & set(angle_names())
    if angles and angles != keys:
        raise PoseFileError(
            f"{where}: mixes joint angles and bones ({sorted(keys - angles)[:3]}); use one kind per file"
        )
    if angles:
        try:
            values = {k: float(np.asarray(v, dtype=np.float64)) for k, v in frame.items()}
        except (TypeError, ValueError):
            values = {"": math.nan}
        if not all(math.isfinite(v) for v in values.values()):
            raise PoseFileError(f"{where}: every joint angle must be one finite number of degrees")
        wild = {k: v for k, v in values.items() if abs(v) > 180.0}
        if wild:
            raise PoseFileError(f"{where}: joint angles are degrees in [-180, 180], got {wild}")
        limits = {k: limit_of(JointLimits(), k) for k in values}
        beyond = {k: v for k, v in values.items() if not limits[k][0] <= v <= limits[k][1]}
        if beyond:
            log.warning(
                "%s: %s beyond the joint limits the training poses were sampled in (garsim.bodies.poses.JointLimits)",
                where,
                ", ".join(f"{k}={v:g}" for k, v in sorted(beyond.items())),
            )
        return unbatch(angles_to_pose(values), 0)
    return {str(k): _as_rotvec(str(k), v, where) for k, v in frame.items()}


def read_pose_sequence(path: str | Path) -> list[dict[str, np.ndarray]]:
    """The frames of a pose file (bone -> axis-angle (3,) per frame, for ``AnnyBody.pose_batch``).

    A ``.json`` file holds a list of frames (or ``{"frames": [...]}``); a frame maps either Anny bone names to
    rotations in Anny's ``local-ref`` parameterisation (axis-angle ``[x, y, z]`` in radians, or a 3x3 or 4x4
    matrix; bones left out keep Anny's rest pose, so give the arms of a T-pose yourself) or garsim's joint angles
    (``angle_names()``, degrees, measured from the T-pose: ``{"hip_flexion_L": 30, "shoulder_elevation_L": -60}``;
    angles left out are 0). A ``.npz`` holds one array per name: (T, 3), (T, 3, 3) or (T, 4, 4) per bone, or (T,)
    per joint angle, one kind per file. Bad content raises a one-line ``PoseFileError`` (a ``ValueError``) naming the
    file and what to fix.
    """
    import json

    p = Path(path)
    if not p.is_file():
        raise PoseFileError(f"{p}: no such pose file")
    suffix = p.suffix.lower()
    try:
        if suffix == ".json":
            doc = json.loads(p.read_text(encoding="utf-8"))
            frames = doc.get("frames") if isinstance(doc, dict) else doc
        elif suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                arrays = {k: np.asarray(z[k]) for k in z.files}
            lengths = {len(a) if a.ndim else 0 for a in arrays.values()}
            if not arrays or len(lengths) != 1 or 0 in lengths:
                raise PoseFileError(f"{p}: every array must have one row per frame (lengths {sorted(lengths)})")
            frames = [{k: a[t] for k, a in arrays.items()} for t in range(lengths.pop())]
        else:
            raise PoseFileError(f"{p}: a pose file is .json or .npz, not {suffix or 'extension-less'}")
    except PoseFileError:
        raise
    except Exception as exc:  # noqa: BLE001 - truncated, foreign or non-UTF-8 files raise json/zipfile/OS errors
        raise PoseFileError(f"{p}: not a readable pose file ({type(exc).__name__}: {exc})") from None
    if not isinstance(frames, list) or not frames:
        raise PoseFileError(f'{p}: expected a non-empty list of frames (or {{"frames": [...]}})')
    out = [_frame_pose(f, f"{p} frame {t}") for t, f in enumerate(frames)]
    named = [t for t, f in enumerate(frames) if f]  # an empty frame (the rest pose) is of either kind
    angles = [bool(set(frames[t]) & set(angle_names())) for t in named]
    if len(set(angles)) > 1:
        first = named[angles.index(not angles[0])]
        raise PoseFileError(
            f"{p}: frame {first} uses other names than frame {named[0]} (joint angles vs Anny bones); use one kind "
            "per file"
        )
    return out


def resample_poses(poses: Sequence[Mapping[str, np.ndarray]], num_frames: int) -> list[dict[str, np.ndarray]]:
    """``num_frames`` poses through keyframes ``poses``: keyframe k lands on frame round(k (T - 1) / (K - 1)), so
    every keyframe is shown exactly, and the frames between two keyframes slerp per bone between them (missing bones
    = identity). Needs ``num_frames`` >= the number of keyframes (one keyframe: held)."""
    if len(poses) < 1 or num_frames < max(2, len(poses)):
        raise ValueError(
            f"{len(poses)} keyframes need at least {max(2, len(poses))} frames (each keyframe on its own), "
            f"got {num_frames}"
        )
    if len(poses) == 1:
        return [dict(poses[0]) for _ in range(num_frames)]
    stacked = stack_poses(poses)
    bones = sorted(stacked)
    keys = torch.as_tensor(np.stack([stacked[b] for b in bones], axis=1))  # (K, bones, 3)
    at = np.round(np.linspace(0.0, num_frames - 1, len(poses))).astype(int)  # the keyframes' frames, increasing
    out = []
    for k in range(len(poses) - 1):
        steps = (np.arange(at[k], at[k + 1]) - at[k]) / (at[k + 1] - at[k])
        r = roma.rotvec_slerp(keys[k], keys[k + 1], torch.as_tensor(steps, dtype=torch.float64)).numpy()
        out += [{b: r[t, j] for j, b in enumerate(bones)} for t in range(len(steps))]
        out[at[k]] = {b: keys[k, j].numpy() for j, b in enumerate(bones)}  # exact keyframe (slerp's round trip)
    out.append({b: keys[-1, j].numpy() for j, b in enumerate(bones)})
    return out


def pose_bodies_rigged(body: AnnyBody, poses: Sequence[Mapping[str, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Body vertices (T, V, 3) of ``body`` in each pose of a sequence, and its bones' skinning transforms
    (T, J, 4, 4): linear blend skinning of ``body.rest_vertices`` by them gives the vertices."""
    return body.pose_batch(batched_matrices(stack_poses(poses)))


def pose_bodies(body: AnnyBody, poses: Sequence[Mapping[str, np.ndarray]]) -> np.ndarray:
    """Body vertices (T, V, 3) of ``body`` in each pose of a sequence."""
    return pose_bodies_rigged(body, poses)[0]
