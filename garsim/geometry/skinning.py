"""Skinning-weight transfer and the LBS garment deformation prior G^prior (paper Sec. 3.1).

The prior "unposes" each garment vertex with the canonical body's blended bone transforms
and "reposes" it with the target's: G_prior = M_tgt(w) M_can(w)^-1 G, where
M(w) = sum_j w_j T_j. On the body's own vertices, with the body's own weights, this
reproduces the posed body exactly.
"""

from __future__ import annotations

import numpy as np

from garsim.geometry.proximity import soft_anchor


def dense_weights(indices: np.ndarray, weights: np.ndarray, num_bones: int) -> np.ndarray:
    """(V, K) sparse skinning (bone indices + weights) -> (V, J) dense weights."""
    v = len(indices)
    dense = np.zeros((v, num_bones), dtype=np.float64)
    np.add.at(dense, (np.repeat(np.arange(v), indices.shape[1]), indices.ravel()), weights.ravel())
    return dense


def transfer_weights(points: np.ndarray, body_vertices: np.ndarray, body_dense_weights: np.ndarray) -> np.ndarray:
    """Skinning weights of ``points``: the soft anchor's blend of nearby canonical body vertices' weights
    (continuous in the points; no seam where neighbouring garment vertices pick different bones)."""
    return np.asarray(soft_anchor(points, body_vertices) @ np.asarray(body_dense_weights, dtype=np.float64))


def blended_transforms(weights: np.ndarray, transforms: np.ndarray) -> np.ndarray:
    """(N, J) weights x (J, 4, 4) transforms -> (N, 4, 4) blended matrices."""
    j = transforms.shape[0]
    return (weights @ transforms.reshape(j, 16)).reshape(-1, 4, 4)


def apply_transforms(points: np.ndarray, mats: np.ndarray) -> np.ndarray:
    """Apply per-point (N, 4, 4) affine matrices to (N, 3) points."""
    return np.einsum("nij,nj->ni", mats[:, :3, :3], points) + mats[:, :3, 3]


def lbs_prior(
    garment: np.ndarray,
    weights: np.ndarray,
    transforms_canonical: np.ndarray,
    transforms_target: np.ndarray,
) -> np.ndarray:
    """G^prior: move garment vertices with the body's skinning, canonical -> target.

    ``weights`` (N, J) are the garment's (transferred) skinning weights; the transforms
    (J, 4, 4) map the body model's rest mesh to the canonical and the target pose.
    """
    g = np.asarray(garment, dtype=np.float64)
    m_can = blended_transforms(weights, transforms_canonical)
    m_tgt = blended_transforms(weights, transforms_target)
    composite = m_tgt @ np.linalg.inv(m_can)
    return apply_transforms(g, composite).astype(np.float32)
