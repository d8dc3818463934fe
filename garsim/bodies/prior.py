"""The garment deformation prior G^prior for any body: rigged (LBS) or a bare mesh pair.

- Rigged bodies (Anny): the paper's LBS prior (Sec. 3.1) with skinning weights transferred
  from the nearest canonical body vertices, see ``garsim.geometry.skinning.lbs_prior``.
- Unrigged bodies (``MeshPairBody``): each body vertex gets a local rotation from its
  neighbourhood (Kabsch over its incident edges, smoothed over ``rings`` rings), and each
  garment vertex follows its soft anchor's body vertices rigidly: B̄_q + R_q (G - B_q), blended.
Both blend body vertices with the soft anchor (``geometry.proximity.soft_anchor``), so the prior is a
continuous function of the garment and the bodies.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp

from garsim.bodies.base import BodyModel, PosedBody
from garsim.geometry.mesh import unique_edges
from garsim.geometry.proximity import about_centroid, soft_anchor
from garsim.geometry.skinning import apply_transforms

log = logging.getLogger(__name__)


def _ring_matrices(faces: np.ndarray, num_vertices: int) -> tuple[np.ndarray, sp.csr_matrix, sp.csr_matrix]:
    """Unique edges (E, 2), the (V, E) vertex-edge incidence and the (V, V) 1-ring adjacency (self included)."""
    e = unique_edges(faces)
    # each edge contributes to both endpoints (the outer product is symmetric in direction)
    inc = sp.coo_matrix(
        (np.ones(2 * len(e)), (np.concatenate([e[:, 0], e[:, 1]]), np.tile(np.arange(len(e)), 2))),
        shape=(num_vertices, len(e)),
    ).tocsr()
    adj = (inc @ inc.T).tocsr()
    adj.data[:] = 1.0
    return e, inc, adj


def _edge_outer(canonical: np.ndarray, target: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(E, 9) per edge the outer product of its canonical and its target vector (float64)."""
    c = np.asarray(canonical, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    ec = c[edges[:, 1]] - c[edges[:, 0]]
    et = t[edges[:, 1]] - t[edges[:, 0]]
    return np.einsum("ei,ej->eij", ec, et).reshape(-1, 9)


def _kabsch(cov: np.ndarray) -> np.ndarray:
    """(R, 9) summed edge outer products -> (R, 3, 3) the best rotations (no reflection) canonical -> target."""
    u, _, vt = np.linalg.svd(cov.reshape(-1, 3, 3))
    d = np.sign(np.linalg.det(np.einsum("vij,vjk->vik", u, vt)))
    vt[:, 2, :] *= d[:, None]
    return np.einsum("vij,vjk->vik", u, vt).transpose(0, 2, 1)


def vertex_rotations(
    canonical: np.ndarray, target: np.ndarray, faces: np.ndarray, rings: int = 2, subset: np.ndarray | None = None
) -> np.ndarray:
    """(V, 3, 3) best rotation per body vertex (or per vertex of ``subset``) mapping its canonical
    neighbourhood edges onto its target edges (an edge counted once per path of ``rings`` rings that reaches it)."""
    e, inc, adj = _ring_matrices(faces, len(canonical))
    cov = inc @ _edge_outer(canonical, target, e)
    for _ in range(max(rings - 1, 0)):
        cov = adj @ cov
    return _kabsch(cov if subset is None else cov[subset])


def ring_operator(faces: np.ndarray, num_vertices: int, rings: int = 2) -> tuple[np.ndarray, sp.csr_matrix]:
    """The pose-free part of :func:`vertex_rotations` for many poses of one small mesh (a garment): its unique edges
    and the (V, E) operator that sums a per-edge quantity over each vertex's ``rings`` rings, for
    :func:`rotations_between`. (One pose of a large mesh is cheaper through :func:`vertex_rotations`.)"""
    e, op, adj = _ring_matrices(faces, num_vertices)
    for _ in range(max(rings - 1, 0)):
        op = adj @ op
    return e, op.tocsr()


def rotations_between(canonical: np.ndarray, target: np.ndarray, edges: np.ndarray, op: sp.csr_matrix) -> np.ndarray:
    """:func:`vertex_rotations` through a :func:`ring_operator`: (V, 3, 3), the same rotations to rounding."""
    return _kabsch(op @ _edge_outer(canonical, target, edges))


def rigfree_prior(garment: np.ndarray, canonical: np.ndarray, target: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Prior for a body given only as a canonical/target mesh pair of one topology."""
    g = np.asarray(garment, dtype=np.float64)
    c = np.asarray(canonical, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    w = soft_anchor(g, c).tocoo()
    used, inverse = np.unique(w.col, return_inverse=True)
    rot = vertex_rotations(c, t, faces, subset=used)[inverse]
    moved = t[w.col] + np.einsum("mij,mj->mi", rot, g[w.row] - c[w.col])
    out = np.zeros_like(g)
    np.add.at(out, w.row, w.data[:, None] * moved)
    return out.astype(np.float32)


def garment_prior(
    body: BodyModel, canonical: PosedBody, target: PosedBody, garment: np.ndarray, bones: np.ndarray | None = None
) -> np.ndarray:
    """G^prior of ``garment`` (draped on ``canonical``) on ``target``: the LBS prior with the skinning weights
    of the soft anchor's nearby body vertices (the rig-free prior for bodies without a rig). ``bones`` ((J,) bool):
    skin with those bones' weights alone, renormalised (a body vertex with none of them keeps its own)."""
    if body.skin_weights is None or canonical.transforms is None or target.transforms is None:
        return rigfree_prior(garment, canonical.vertices, target.vertices, body.faces)
    # Same as lbs_prior(garment, transfer_weights(garment, canonical, dense_weights(...)), ...): blending is
    # linear in the weights, so each garment vertex's blended matrix is the soft-anchor blend of its body
    # vertices' blended matrices, and those need only the body's sparse skinning for the vertices used.
    w = soft_anchor(garment, canonical.vertices).tocsc()
    used = np.flatnonzero(np.diff(w.indptr))
    w = w[:, used]
    si = np.asarray(body.skin_indices)[used]
    sw = np.asarray(body.skin_weights, dtype=np.float64)[used]
    if bones is not None:
        kept = sw * np.asarray(bones, dtype=bool)[si]
        total = kept.sum(axis=1, keepdims=True)
        sw = np.where(total > 0, kept / np.maximum(total, 1e-300), sw)
    g = np.asarray(garment, dtype=np.float64)

    def blended(transforms: np.ndarray) -> np.ndarray:
        t = np.asarray(transforms, dtype=np.float64).reshape(-1, 16)
        per_body = np.einsum("us,usf->uf", sw, t[si])
        return np.asarray(w @ per_body).reshape(-1, 4, 4)

    composite = blended(target.transforms) @ np.linalg.inv(blended(canonical.transforms))
    return apply_transforms(g, composite).astype(np.float32)


class MeshPairPrior:
    """:func:`mesh_pair_prior` of one garment on one canonical body, set up once (rig match, bone-fit system,
    skinning weights); ``self(target)`` gives the prior on one target body: a pose sequence pays per frame only
    for the bone fit and the skinning."""

    def __init__(self, garment: np.ndarray, canonical: np.ndarray, faces: np.ndarray) -> None:
        from garsim.bodies.anny_rig import match_anny_rig
        from garsim.bodies.recover import RecoveredPrior

        self.garment, self.canonical, self.centre = about_centroid(garment, canonical)
        self.faces = faces
        rig = match_anny_rig(len(canonical), faces)
        self.lbs = None if rig is None else RecoveredPrior(self.garment, self.canonical, *rig)
        if rig is None:
            log.info(
                "the body (%d vertices, %d faces) is not in Anny's topology and vertex order: the rig-free prior "
                "(an Anny body re-saved in another vertex order, e.g. through STL, loses the skinning prior)",
                len(canonical),
                len(faces),
            )

    def __call__(self, target: np.ndarray) -> np.ndarray:
        t = np.asarray(target, dtype=np.float64) - self.centre
        if self.lbs is None:
            out = rigfree_prior(self.garment, self.canonical, t, self.faces)
        else:
            out = self.lbs(t)
        return (out.astype(np.float64) + self.centre).astype(np.float32)


def mesh_pair_prior(garment: np.ndarray, canonical: np.ndarray, target: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The garment prior from two body meshes: Anny-topology bodies get the LBS prior with bone transforms
    recovered from the meshes (the data generator's stored prior skins with the known pose instead: on 126 v5 test
    samples they differ by 0.33 mm on average and up to 3 cm at single vertices, and the raw network's error is the
    same with either, 23.59 vs 23.60 mm); any other topology the rig-free prior.

    Computed about the canonical body's centroid (float64), so moving the whole scene moves the prior with it
    exactly (the bone fit's damping pulls towards identity transforms, which is not translation invariant).
    """
    return MeshPairPrior(garment, canonical, faces)(target)
