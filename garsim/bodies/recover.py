"""Bone transforms recovered from a canonical/target mesh pair of a rigged topology.

A client may hold only meshes (e.g. Anny-topology bodies exported from another tool). Linear
blend skinning is linear in the bone transforms, so the per-bone affine maps X_j that best
explain canonical -> target, ``target_v ≈ sum_j w_vj X_j [canonical_v; 1]``, are one sparse
linear least-squares problem (V x 3 equations, 12 unknowns per bone), solved through its
normal equations with a small pull towards the whole body's affine map for bones that skin few
vertices.
The garment is then skinned with the same weights: the LBS prior without pose parameters.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_factor, cho_solve

from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.skinning import apply_transforms, blended_transforms, dense_weights, transfer_weights

DEFAULT_DAMPING = 1e-4


class _RigSystem:
    """The parts of the least-squares fit that depend only on the canonical mesh and the rig."""

    def __init__(
        self, canonical: np.ndarray, skin_indices: np.ndarray, skin_weights: np.ndarray, num_bones: int, damping: float
    ) -> None:
        c = np.asarray(canonical, dtype=np.float64)
        si = np.asarray(skin_indices, dtype=np.int64)
        sw = np.asarray(skin_weights, dtype=np.float64)
        if len(c) != len(si) or si.shape != sw.shape:
            raise ValueError(f"canonical {c.shape} and skinning {si.shape}/{sw.shape} must cover the same vertices")
        v, k = si.shape
        homo = np.concatenate([c, np.ones((v, 1))], axis=1)
        rows = np.repeat(np.arange(v), k * 4)
        cols = (si[:, :, None] * 4 + np.arange(4)).reshape(-1)
        vals = (sw[:, :, None] * homo[:, None, :]).reshape(-1)
        self.a_t = sp.csr_matrix((vals, (rows, cols)), shape=(v, 4 * num_bones)).T.tocsr()
        self.whole = np.linalg.pinv(homo)  # (4, V): the whole body's best affine map is whole @ target
        self.factor = cho_factor((self.a_t @ self.a_t.T).toarray() + damping * np.eye(4 * num_bones))
        self.damping = damping
        self.num_bones = num_bones
        self.dense = dense_weights(si, sw, num_bones)

    def fit(self, target: np.ndarray) -> np.ndarray:
        """(J, 4, 4) bone transforms taking the canonical mesh to ``target``."""
        t = np.asarray(target, dtype=np.float64)
        # pull every bone weakly towards the whole body's best affine map (exact for a rigid motion)
        rhs = self.a_t @ t + self.damping * np.tile(self.whole @ t, (self.num_bones, 1))
        x = cho_solve(self.factor, rhs)
        out = np.tile(np.eye(4), (self.num_bones, 1, 1))
        out[:, :3, :] = x.reshape(self.num_bones, 4, 3).transpose(0, 2, 1)
        return out


_SYSTEMS = ContentCache(4)  # per canonical mesh + rig
_FITS = ContentCache(16)  # per canonical/target pair


def _rig_key(
    canonical: np.ndarray, skin_indices: np.ndarray, skin_weights: np.ndarray, num_bones: int, damping: float
) -> tuple:
    return (content_key(canonical, skin_indices, skin_weights), num_bones, damping)


def _rig_system(
    key: tuple,
    canonical: np.ndarray,
    skin_indices: np.ndarray,
    skin_weights: np.ndarray,
    num_bones: int,
    damping: float,
) -> _RigSystem:
    return _SYSTEMS.get(key, lambda: _RigSystem(canonical, skin_indices, skin_weights, num_bones, damping))


def fit_bone_transforms(
    canonical: np.ndarray,
    target: np.ndarray,
    skin_indices: np.ndarray,
    skin_weights: np.ndarray,
    num_bones: int,
    damping: float = DEFAULT_DAMPING,
) -> np.ndarray:
    """(J, 4, 4) affine bone transforms (canonical -> target) fitted to the skinned body vertices.

    The canonical-side system is factorised once per canonical mesh and rig, and fits are cached per
    mesh pair, so many garments or many poses on one body pay for it once.
    """
    if np.shape(canonical) != np.shape(target):
        raise ValueError(f"canonical {np.shape(canonical)} and target {np.shape(target)} must cover the same vertices")
    key = _rig_key(canonical, skin_indices, skin_weights, num_bones, damping)
    system = _rig_system(key, canonical, skin_indices, skin_weights, num_bones, damping)
    return _FITS.get((key, content_key(target)), lambda: system.fit(target))


class RecoveredPrior:
    """The LBS prior of one garment on one canonical mesh of a rigged topology, set up once (the rig's factorised
    system and the garment's transferred weights); ``self(target)`` fits the bones and skins the garment."""

    def __init__(
        self,
        garment: np.ndarray,
        canonical: np.ndarray,
        skin_indices: np.ndarray,
        skin_weights: np.ndarray,
        num_bones: int,
    ) -> None:
        key = _rig_key(canonical, skin_indices, skin_weights, num_bones, DEFAULT_DAMPING)
        self.system = _rig_system(key, canonical, skin_indices, skin_weights, num_bones, DEFAULT_DAMPING)
        self.garment = np.asarray(garment, dtype=np.float64)
        self.weights = transfer_weights(garment, canonical, self.system.dense)
        self.num_vertices = len(canonical)

    def __call__(self, target: np.ndarray) -> np.ndarray:
        if np.shape(target) != (self.num_vertices, 3):
            raise ValueError(f"target {np.shape(target)} must cover the canonical mesh's {self.num_vertices} vertices")
        bones = self.system.fit(target)
        return apply_transforms(self.garment, blended_transforms(self.weights, bones)).astype(np.float32)


def recovered_lbs_prior(
    garment: np.ndarray,
    canonical: np.ndarray,
    target: np.ndarray,
    skin_indices: np.ndarray,
    skin_weights: np.ndarray,
    num_bones: int,
) -> np.ndarray:
    """The LBS prior from a canonical/target mesh pair of a rigged topology (no pose parameters)."""
    return RecoveredPrior(garment, canonical, skin_indices, skin_weights, num_bones)(target)
