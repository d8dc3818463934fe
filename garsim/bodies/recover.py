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

from garsim.geometry.skinning import apply_transforms, blended_transforms, dense_weights, transfer_weights

DEFAULT_K = 4


def fit_bone_transforms(
    canonical: np.ndarray,
    target: np.ndarray,
    skin_indices: np.ndarray,
    skin_weights: np.ndarray,
    num_bones: int,
    damping: float = 1e-4,
) -> np.ndarray:
    """(J, 4, 4) affine bone transforms (canonical -> target) fitted to the skinned body vertices."""
    c = np.asarray(canonical, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    si = np.asarray(skin_indices, dtype=np.int64)
    sw = np.asarray(skin_weights, dtype=np.float64)
    if c.shape != t.shape or len(c) != len(si) or si.shape != sw.shape:
        raise ValueError(
            f"canonical {c.shape}, target {t.shape} and skinning {si.shape}/{sw.shape} must cover the same vertices"
        )
    v, k = si.shape
    homo = np.concatenate([c, np.ones((v, 1))], axis=1)
    rows = np.repeat(np.arange(v), k * 4)
    cols = (si[:, :, None] * 4 + np.arange(4)).reshape(-1)
    vals = (sw[:, :, None] * homo[:, None, :]).reshape(-1)
    a = sp.csr_matrix((vals, (rows, cols)), shape=(v, 4 * num_bones))
    # pull every bone weakly towards the whole body's best affine map (exact for a rigid motion)
    whole = np.linalg.lstsq(homo, t, rcond=None)[0]  # (4, 3)
    lhs = (a.T @ a).toarray() + damping * np.eye(4 * num_bones)
    x = np.linalg.solve(lhs, a.T @ t + damping * np.tile(whole, (num_bones, 1)))
    out = np.tile(np.eye(4), (num_bones, 1, 1))
    out[:, :3, :] = x.reshape(num_bones, 4, 3).transpose(0, 2, 1)
    return out


def recovered_lbs_prior(
    garment: np.ndarray,
    canonical: np.ndarray,
    target: np.ndarray,
    skin_indices: np.ndarray,
    skin_weights: np.ndarray,
    num_bones: int,
    k: int = DEFAULT_K,
) -> np.ndarray:
    """The LBS prior from a canonical/target mesh pair of a rigged topology (no pose parameters)."""
    bones = fit_bone_transforms(canonical, target, skin_indices, skin_weights, num_bones)
    w = transfer_weights(garment, canonical, dense_weights(skin_indices, skin_weights, num_bones), k=k)
    return apply_transforms(np.asarray(garment, dtype=np.float64), blended_transforms(w, bones)).astype(np.float32)
