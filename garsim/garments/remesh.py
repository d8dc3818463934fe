"""Garment decimation (fast-simplification, borders kept), midpoint subdivision, and barycentric transfer between
resolutions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from garsim.garments.garment import Garment
from garsim.geometry.io import zero_area_faces


@dataclass
class BarycentricMap:
    """Each low-res vertex as a barycentric combination of one full-res triangle's vertices."""

    triangles: np.ndarray  # (M, 3) int64 full-res vertex indices
    weights: np.ndarray  # (M, 3) float64 barycentric weights (sum to 1)


def _closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 3) of the closest point on triangles abc to points p (Ericson 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = p - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = p - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    eps = 1e-30
    denom = va + vb + vc
    v_in = vb / np.where(np.abs(denom) > eps, denom, eps)
    w_in = vc / np.where(np.abs(denom) > eps, denom, eps)
    out = np.stack([1 - v_in - w_in, v_in, w_in], -1)
    # edge regions
    t_ab = d1 / np.where(np.abs(d1 - d3) > eps, d1 - d3, eps)
    t_ac = d2 / np.where(np.abs(d2 - d6) > eps, d2 - d6, eps)
    t_bc = (d4 - d3) / np.where(np.abs((d4 - d3) + (d5 - d6)) > eps, (d4 - d3) + (d5 - d6), eps)
    z = np.zeros_like(d1)
    o = np.ones_like(d1)
    cases = [
        ((d1 <= 0) & (d2 <= 0), np.stack([o, z, z], -1)),
        ((d3 >= 0) & (d4 <= d3), np.stack([z, o, z], -1)),
        ((d6 >= 0) & (d5 <= d6), np.stack([z, z, o], -1)),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), np.stack([1 - t_ab, t_ab, z], -1)),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), np.stack([1 - t_ac, z, t_ac], -1)),
        ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), np.stack([z, 1 - t_bc, t_bc], -1)),
    ]
    done = np.zeros(d1.shape, dtype=bool)
    for cond, val in cases:
        take = cond & ~done
        out[take] = val[take]
        done |= take
    return np.clip(out, 0.0, 1.0)


def _closest_point_barycentric(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, k: int = 16
) -> tuple[np.ndarray, np.ndarray]:
    """Closest full-res triangle of each point and the barycentric coordinates of the closest point on it."""
    from scipy.spatial import cKDTree

    tri = vertices[faces]  # (F, 3, 3)
    centroids = tri.mean(axis=1)
    k = min(k, len(faces))
    _, cand = cKDTree(centroids).query(points, k=k)
    cand = cand.reshape(len(points), k)
    t = tri[cand]  # (M, k, 3, 3)
    p = np.broadcast_to(points[:, None, :], (len(points), k, 3))
    bary = _closest_on_triangles(p, t[:, :, 0], t[:, :, 1], t[:, :, 2])
    bary /= bary.sum(-1, keepdims=True)
    closest = np.einsum("mkj,mkjd->mkd", bary, t)
    dist = np.linalg.norm(closest - p, axis=-1)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(points))
    return faces[cand[rows, best]].astype(np.int64), bary[rows, best]


def barycentric_map(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> BarycentricMap:
    """Each point as a barycentric combination of its closest triangle of the mesh (vertices, faces)."""
    tris, bary = _closest_point_barycentric(
        np.asarray(points, np.float64), np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    )
    return BarycentricMap(tris, bary)


def decimate(garment: Garment, ratio: float = 0.25) -> tuple[Garment, BarycentricMap]:
    """Decimate to ~``ratio`` of the faces keeping border vertices; returns the garment and a full->low map.

    Low-res vertices are placed on the full-res surface, so ``transfer_barycentric(full.vertices, map)``
    reproduces them; the same map moves any per-vertex data (ground truth, priors) to the low-res mesh.
    """
    if not (0.0 < ratio <= 1.0):
        raise ValueError(f"decimation ratio must be in (0, 1], got {ratio}")
    import fast_simplification

    v = garment.vertices.astype(np.float64)
    f = garment.faces.astype(np.int32)
    target = max(4, int(round(ratio * len(f))))
    if ratio < 1.0:
        v_low, f_low = fast_simplification.simplify(v, f, target_count=target, preserve_border=True)
    else:
        v_low, f_low = v.copy(), f.astype(np.int64)
    mapping = barycentric_map(v_low, v, garment.faces)
    # snap the low-res vertices onto the full-res surface (quadric placement moves them off it by ~mm),
    # so the low-res garment is exactly the barycentric transfer of the full-res one
    v_low = np.einsum("mk,mkd->md", mapping.weights, v[mapping.triangles])
    # drop zero-area faces (collapses between collinear vertices, e.g. of a subdivided mesh), then the vertices
    # left unreferenced
    f_low = f_low[~zero_area_faces(v_low.astype(np.float32), f_low)]
    used = np.unique(f_low)
    remap = np.full(len(v_low), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    v_low, f_low = v_low[used], remap[f_low]
    tris, bary = mapping.triangles[used], mapping.weights[used]
    mapping = BarycentricMap(tris, bary)
    # pinned mask: carried over from the nearest original vertex of the closest triangle
    nearest = tris[np.arange(len(tris)), np.argmax(bary, axis=1)]
    pinned = garment.pinned[nearest]
    params = dict(garment.params)
    params["decimation_ratio"] = float(ratio)
    low = Garment(v_low.astype(np.float32), f_low.astype(np.int64), pinned, garment.kind, params)
    return low, mapping


def transfer_barycentric(values_full: np.ndarray, mapping: BarycentricMap) -> np.ndarray:
    """Per-vertex values (N, ...) on the full mesh -> (M, ...) on the low-res mesh through ``mapping``."""
    values = np.asarray(values_full)
    if len(values) <= int(mapping.triangles.max(initial=-1)):
        raise ValueError(
            f"values have {len(values)} rows but the mapping indexes vertex {int(mapping.triangles.max())}; "
            "pass per-vertex values of the full-resolution garment"
        )
    gathered = values[mapping.triangles]  # (M, 3, ...)
    w = mapping.weights.reshape(mapping.weights.shape + (1,) * (values.ndim - 1))
    return (gathered * w).sum(axis=1).astype(values.dtype if values.dtype.kind == "f" else np.float64)


def subdivide(faces: np.ndarray, num_vertices: int) -> tuple[np.ndarray, BarycentricMap]:
    """Midpoint subdivision (each triangle into four, orientation kept): the fine faces and the coarse -> fine map.

    The fine mesh's vertices are the ``num_vertices`` coarse ones followed by one midpoint per edge, so
    ``transfer_barycentric`` carries any per-vertex data (positions, priors, ground truth) onto it; piecewise-linear
    data keeps its surface exactly (a simulated garment is the same surface, sampled twice as densely)."""
    f = np.asarray(faces, np.int64)
    edges = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    m01, m12, m20 = (num_vertices + inverse.reshape(-1, 3)).T
    a, b, c = f.T
    fine = np.concatenate([np.stack(t, axis=1) for t in ((a, m01, m20), (m01, b, m12), (m20, m12, c), (m01, m12, m20))])
    own = np.arange(num_vertices)
    triangles = np.concatenate([np.stack([own, own, own], axis=1), np.column_stack([unique, unique[:, 0]])])
    weights = np.concatenate([np.tile([1.0, 0.0, 0.0], (num_vertices, 1)), np.tile([0.5, 0.5, 0.0], (len(unique), 1))])
    return fine, BarycentricMap(triangles, weights)
