"""Anny (free, Apache-2.0, assets in the wheel) as a garsim body model."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from functools import lru_cache

import numpy as np
import torch

from garsim.bodies.anny_rig import anny_rig, match_anny_rig  # noqa: F401 - re-exported (cached on disk)
from garsim.bodies.base import BodyModel, PosedBody
from garsim.paths import anny_cache_dir

PHENOTYPE_KEYS: tuple[str, ...] = ("gender", "age", "muscle", "weight", "height", "proportions")
FREE_TOPOLOGIES: tuple[str, ...] = ("anny", "notoes_collapse10pc")
_DOWNLOADING_TOPOLOGIES = ("smpl", "smplx")
T_POSE_ARM_DEGREES = 40.0
"""Upper arms raised by this angle about Y from Anny's rest A-pose give the canonical T-pose."""

PoseSpec = Mapping[str, "np.ndarray | torch.Tensor | Sequence[float]"]
"""Bone name -> rotation: axis-angle (3,), matrix (3, 3) or homogeneous (4, 4), or batched (B, ...)."""


@lru_cache(maxsize=4)
def _load_anny(topology: str):
    if any(topology.startswith(t) for t in _DOWNLOADING_TOPOLOGIES):
        raise ValueError(
            f"Anny topology {topology!r} downloads non-free SMPL data; garsim never downloads at "
            f"run time. Use one of {FREE_TOPOLOGIES}, or pass your own meshes as a MeshPairBody."
        )
    os.environ.setdefault("ANNY_CACHE_DIR", str(anny_cache_dir()))
    from garsim.geometry.inside import quiet_warp

    quiet_warp()  # Anny's skinning initialises warp: do it first, without the banner on stdout
    import anny
    import anny.paths

    anny.paths.set_anny_cache_path(os.environ["ANNY_CACHE_DIR"])
    model = anny.Anny(topology=topology)
    model.eval()
    return model


def _is_rotation_matrix(r: torch.Tensor) -> bool:
    eye = torch.eye(3, dtype=r.dtype)
    return bool(torch.allclose(r @ r.T, eye, atol=1e-5) and abs(float(torch.linalg.det(r)) - 1.0) < 1e-5)


def rotation_to_homogeneous(rot: np.ndarray | torch.Tensor | Sequence[float]) -> torch.Tensor:
    """Axis-angle (3,) / (B, 3), matrix (3, 3) / (B, 3, 3) or (4, 4) / (B, 4, 4) -> (B, 4, 4) float64.

    A (3, 3) array is read as one rotation matrix when it is one (orthonormal, det 1), else as
    a batch of three axis-angles.
    """
    import roma

    r = torch.as_tensor(np.asarray(rot, dtype=np.float64))
    if r.shape == (3, 3) and not _is_rotation_matrix(r):
        r = r.reshape(3, 1, 3)  # three axis-angles, not one matrix
    if r.shape[-1:] == (3,) and r.shape[-2:] != (3, 3):
        r = roma.rotvec_to_rotmat(r.reshape(-1, 3))
    if r.shape[-2:] == (3, 3):
        r = r.reshape(-1, 3, 3)
        h = torch.eye(4, dtype=torch.float64).repeat(len(r), 1, 1)
        h[:, :3, :3] = r
        return h
    if r.shape[-2:] == (4, 4):
        return r.reshape(-1, 4, 4)
    raise ValueError(f"a rotation must be axis-angle (3,), a 3x3 or a 4x4 matrix, got shape {tuple(r.shape)}")


class AnnyBody(BodyModel):
    """An Anny body of one phenotype; canonical pose is the T-pose (as the paper / CLOTH3D).

    ``phenotype`` values are in [0, 1] for keys in ``PHENOTYPE_KEYS`` (missing keys: 0.5).
    Poses are dicts of bone name -> rotation in Anny's ``local-ref`` parameterisation, where
    rotation axes are world-aligned (X: right->left, Y: back, Z: up) at each bone's head.
    """

    def __init__(self, phenotype: Mapping[str, float] | None = None, topology: str = "anny") -> None:
        phenotype = dict(phenotype or {})
        unknown = set(phenotype) - set(PHENOTYPE_KEYS)
        if unknown:
            raise ValueError(f"unknown phenotype keys {sorted(unknown)}; valid keys: {PHENOTYPE_KEYS}")
        for key, value in phenotype.items():
            if not (0.0 <= float(value) <= 1.0) or not math.isfinite(float(value)):
                raise ValueError(f"phenotype {key}={value} must be a number in [0, 1]")
        self.phenotype = {k: float(phenotype.get(k, 0.5)) for k in PHENOTYPE_KEYS}
        self.topology = topology
        self._model = _load_anny(topology)
        self.bone_labels: list[str] = list(self._model.bone_labels)
        with torch.no_grad():
            out = self._run(None)
        self._rest = out["rest_vertices"][0].numpy()
        self._faces = self._model.get_triangular_faces().numpy().astype(np.int64)
        self._weights = self._model.vertex_bone_weights.numpy().astype(np.float64)
        self._indices = self._model.vertex_bone_indices.numpy().astype(np.int64)
        self._canonical: PosedBody | None = None

    # -- BodyModel -------------------------------------------------------------------------
    @property
    def faces(self) -> np.ndarray:
        return self._faces

    @property
    def rest_vertices(self) -> np.ndarray:
        return self._rest

    @property
    def skin_weights(self) -> np.ndarray:
        return self._weights

    @property
    def skin_indices(self) -> np.ndarray:
        return self._indices

    def canonical(self, kind: str = "tpose") -> PosedBody:
        """The T-pose (garsim's canonical pose, as the paper's) or Anny's rest A-pose (``kind="apose"``)."""
        if kind == "apose":
            return self.pose(None)
        if kind != "tpose":
            raise ValueError(f"canonical pose kind must be 'tpose' or 'apose', got {kind!r}")
        if self._canonical is None:
            self._canonical = self.pose(self.t_pose())
        return self._canonical

    def pose(self, pose: PoseSpec | None) -> PosedBody:
        vertices, transforms = self.pose_batch(pose)
        return PosedBody(vertices=vertices[0], transforms=transforms[0])

    # -- Anny specifics --------------------------------------------------------------------
    @staticmethod
    def t_pose() -> dict[str, np.ndarray]:
        """Anny's rest A-pose with both upper arms raised to a T-pose."""
        a = math.radians(T_POSE_ARM_DEGREES)
        return {"upperarm01.L": np.array([0.0, -a, 0.0]), "upperarm01.R": np.array([0.0, a, 0.0])}

    @property
    def rest_bone_poses(self) -> np.ndarray:
        """(J, 4, 4) bone poses of Anny's rest mesh for this phenotype."""
        with torch.no_grad():
            return self._run(None)["rest_bone_poses"][0].numpy()

    def bone_index(self, name: str) -> int:
        try:
            return self.bone_labels.index(name)
        except ValueError:
            raise ValueError(f"unknown bone {name!r}; Anny bones include {self.bone_labels[:8]}...") from None

    def bone_mask(self, prefixes: tuple[str, ...]) -> np.ndarray:
        """(J,) bool: the bones whose labels start with one of ``prefixes`` (e.g. ``TORSO_BONES``)."""
        return np.array([label.startswith(prefixes) for label in self.bone_labels])

    def pose_batch(self, pose: PoseSpec | None) -> tuple[np.ndarray, np.ndarray]:
        """Batched posing: returns vertices (B, V, 3) float32 and skinning transforms (B, J, 4, 4)."""
        with torch.no_grad():
            out = self._run(pose)
        transforms = out["bone_poses"] @ torch.linalg.inv(out["rest_bone_poses"])
        return out["vertices"].numpy().astype(np.float32), transforms.numpy()

    def _run(self, pose: PoseSpec | None) -> dict[str, torch.Tensor]:
        params = None
        if pose:
            params = {}
            for name, rot in pose.items():
                self.bone_index(name)
                params[name] = rotation_to_homogeneous(rot)
            sizes = {len(v) for v in params.values()}
            if len(sizes) > 1:
                if len(sizes - {1}) > 1:
                    raise ValueError(f"pose batch sizes differ between bones: {sorted(sizes)}")
                b = max(sizes)
                params = {k: v.expand(b, 4, 4) for k, v in params.items()}
        return self._model(pose_parameters=params, phenotype_kwargs=self.phenotype)
