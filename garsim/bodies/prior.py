"""The garment deformation prior G^prior for any body: rigged (LBS) or a bare mesh pair.

- Rigged bodies (Anny): the paper's LBS prior (Sec. 3.1) with skinning weights transferred
  from the nearest canonical body vertices, see ``garsim.geometry.skinning.lbs_prior``.
- Unrigged bodies (``MeshPairBody``): each body vertex gets a local rotation from its
  neighbourhood (Kabsch over its incident edges, smoothed over ``rings`` rings), and each
  garment vertex follows its k nearest body vertices rigidly: B̄_q + R_q (G - B_q), blended.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from garsim.bodies.base import BodyModel, PosedBody
from garsim.geometry.mesh import unique_edges
from garsim.geometry.proximity import cached_nearest, nearest_vertices

DEFAULT_K = 4


def vertex_rotations(
    canonical: np.ndarray, target: np.ndarray, faces: np.ndarray, rings: int = 2, subset: np.ndarray | None = None
) -> np.ndarray:
    """(V, 3, 3) best rotation per body vertex (or per vertex of ``subset``) mapping its canonical
    neighbourhood edges onto its target edges."""
    c = np.asarray(canonical, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    e = unique_edges(faces)
    ec = c[e[:, 1]] - c[e[:, 0]]
    et = t[e[:, 1]] - t[e[:, 0]]
    outer = np.einsum("ei,ej->eij", ec, et).reshape(-1, 9)
    v = len(c)
    # each edge contributes to both endpoints (the outer product is symmetric in direction)
    inc = sp.coo_matrix(
        (np.ones(2 * len(e)), (np.concatenate([e[:, 0], e[:, 1]]), np.tile(np.arange(len(e)), 2))),
        shape=(v, len(e)),
    ).tocsr()
    cov = inc @ outer
    adj = (inc @ inc.T).tocsr()
    adj.data[:] = 1.0
    for _ in range(max(rings - 1, 0)):
        cov = adj @ cov
    if subset is not None:
        cov = cov[subset]
    u, _, vt = np.linalg.svd(cov.reshape(-1, 3, 3))
    d = np.sign(np.linalg.det(np.einsum("vij,vjk->vik", u, vt)))
    vt[:, 2, :] *= d[:, None]
    return np.einsum("vij,vjk->vik", u, vt).transpose(0, 2, 1)


def rigfree_prior(
    garment: np.ndarray, canonical: np.ndarray, target: np.ndarray, faces: np.ndarray, k: int = DEFAULT_K
) -> np.ndarray:
    """Prior for a body given only as a canonical/target mesh pair of one topology."""
    g = np.asarray(garment, dtype=np.float64)
    idx, dist = nearest_vertices(g, canonical, k=k)
    idx, dist = idx.reshape(len(g), -1), dist.reshape(len(g), -1)
    used, inverse = np.unique(idx, return_inverse=True)
    rot = vertex_rotations(canonical, target, faces, subset=used)[inverse.reshape(idx.shape)]
    w = 1.0 / np.maximum(dist, 1e-6)
    w /= w.sum(axis=1, keepdims=True)
    local = g[:, None, :] - canonical[idx]
    moved = target[idx] + np.einsum("nkij,nkj->nki", rot, local)
    return np.einsum("nk,nki->ni", w, moved).astype(np.float32)


def garment_prior(
    body: BodyModel, canonical: PosedBody, target: PosedBody, garment: np.ndarray, k: int = DEFAULT_K
) -> np.ndarray:
    """G^prior of ``garment`` (draped on ``canonical``) on ``target``."""
    if body.skin_weights is None or canonical.transforms is None or target.transforms is None:
        return rigfree_prior(garment, canonical.vertices, target.vertices, body.faces, k=k)
    # Same as lbs_prior(garment, transfer_weights(garment, canonical, dense_weights(...), k), ...):
    # blending is linear in the weights, so each garment vertex's blended matrix is the
    # inverse-distance blend of its k nearest body vertices' blended matrices, and those need
    # only the body's sparse skinning (9 bones per vertex) for the body vertices actually used.
    dist, idx = cached_nearest(garment, canonical.vertices, k=k)  # shared with the model's q query
    g = np.asarray(garment, dtype=np.float64)
    if k == 1:
        a = np.ones((len(g), 1))
    else:
        a = 1.0 / np.maximum(dist, 1e-6)
        a /= a.sum(axis=1, keepdims=True)
    used, inverse = np.unique(idx, return_inverse=True)
    si = np.asarray(body.skin_indices)[used]
    sw = np.asarray(body.skin_weights, dtype=np.float64)[used]

    def blended(transforms: np.ndarray) -> np.ndarray:
        t = np.asarray(transforms, dtype=np.float64).reshape(-1, 16)
        per_body = np.einsum("us,usf->uf", sw, t[si])
        return np.einsum("nk,nkf->nf", a, per_body[inverse.reshape(idx.shape)]).reshape(-1, 4, 4)

    # M_tgt M_can^-1 [g; 1] without a batched 4x4 inverse: bone transforms are affine, so a
    # blend is [[A, t], [0, s]] (s = weight sum) and M_can^-1 [g; 1] = [A^-1 (g - t/s); 1/s]
    # with A^-1 b by Cramer's rule (rows r0, r1, r2 of A; det = r0 . (r1 x r2)).
    m_can, m_tgt = blended(canonical.transforms), blended(target.transforms)
    s_can = m_can[:, 3, 3]
    b = g - m_can[:, :3, 3] / s_can[:, None]
    r0, r1, r2 = m_can[:, 0, :3], m_can[:, 1, :3], m_can[:, 2, :3]
    c0, c1, c2 = np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)
    det = np.einsum("ni,ni->n", r0, c0)
    x = (c0 * b[:, :1] + c1 * b[:, 1:2] + c2 * b[:, 2:3]) / det[:, None]
    out = np.einsum("nij,nj->ni", m_tgt[:, :3, :3], x) + m_tgt[:, :3, 3] / s_can[:, None]
    return out.astype(np.float32)
