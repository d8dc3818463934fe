"""Mesh connectivity and differential quantities, vectorised (no per-vertex Python loops)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from garsim.geometry.cache import ContentCache, content_key


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """(E, 2) undirected edges (i < j), sorted, from (F, 3) triangles."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=0)
    n = int(f.max()) + 1
    # 1-D integer keys: ~10x faster than np.unique(axis=0), same sorted order
    key = np.unique(e.min(axis=1) * n + e.max(axis=1))
    return np.stack([key // n, key % n], axis=1)


def edge_lengths(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Lengths of ``unique_edges(faces)`` on ``vertices`` (float64), e.g. a template's rest lengths."""
    e = unique_edges(faces)
    v = np.asarray(vertices, dtype=np.float64)
    return np.linalg.norm(v[e[:, 1]] - v[e[:, 0]], axis=1)


def directed_edges(faces: np.ndarray) -> np.ndarray:
    """(2, 2E) both directions of every undirected edge: row 0 senders, row 1 receivers."""
    e = unique_edges(faces)
    return np.concatenate([e.T, e[:, ::-1].T], axis=1)


def face_pairs(faces: np.ndarray) -> np.ndarray:
    """(M, 2) indices of faces sharing an edge (interior edges of a manifold mesh)."""
    f = np.asarray(faces, dtype=np.int64)
    nf = len(f)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=0)
    e.sort(axis=1)
    face_id = np.tile(np.arange(nf), 3)
    key = e[:, 0] * (int(e.max(initial=0)) + 1) + e[:, 1]
    order = np.argsort(key, kind="stable")
    key, face_id = key[order], face_id[order]
    same = key[1:] == key[:-1]
    return np.stack([face_id[:-1][same], face_id[1:][same]], axis=1)


def face_normals(vertices: np.ndarray, faces: np.ndarray, normalize: bool = True) -> np.ndarray:
    """(F, 3) face normals (unit, or area-weighted when ``normalize`` is False)."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    if normalize:
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
    return n


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit vertex normals, area-weighted average of incident face normals."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    fn = face_normals(v, f, normalize=False)
    corners = np.asarray(f).ravel()  # each face's normal goes to its three corners (bincount: ~10x np.add.at)
    fn3 = np.repeat(fn, 3, axis=0)
    vn = np.stack([np.bincount(corners, weights=fn3[:, c], minlength=len(v)) for c in range(3)], axis=1)
    return (vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-20)).astype(v.dtype)


def vertex_normals_at(vertices: np.ndarray, faces: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """``vertex_normals(vertices, faces)[sel]`` from only the faces touching ``sel`` (same values)."""
    touched = np.zeros(len(vertices), dtype=bool)
    touched[sel] = True
    sub = faces[touched[faces].any(axis=1)]  # every face incident to a selected vertex, in order
    fn = face_normals(vertices, sub, normalize=False)
    idx = sub.T.ravel()  # the summation order of vertex_normals (corner 0 of all faces, then 1, 2)
    vn = np.stack([np.bincount(idx, weights=np.tile(fn[:, c], 3), minlength=len(vertices)) for c in range(3)], axis=1)[
        sel
    ]
    return (vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-20)).astype(vertices.dtype)


_NORMALS = ContentCache(8)


def cached_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``vertex_normals`` cached by content (a body reused across garments); the result is read-only."""

    def compute() -> np.ndarray:
        n = vertex_normals(vertices, faces)
        n.setflags(write=False)
        return n

    return _NORMALS.get(content_key(vertices, faces), compute)


def edge_adjacency(edges: np.ndarray, num_vertices: int, weights: np.ndarray | None = None) -> sp.csr_matrix:
    """Symmetric (V, V) adjacency of (E, 2) undirected ``edges`` (e.g. ``unique_edges(faces)``), each edge's weight
    (default 1) at (i, j) and (j, i)."""
    e = np.asarray(edges, dtype=np.int64)
    w = np.ones(len(e)) if weights is None else np.asarray(weights, dtype=np.float64)
    rows = np.concatenate([e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 1], e[:, 0]])
    return sp.coo_matrix((np.concatenate([w, w]), (rows, cols)), shape=(num_vertices, num_vertices)).tocsr()


def uniform_laplacian(faces: np.ndarray, num_vertices: int) -> sp.csr_matrix:
    """Uniform Laplacian L = I - D^-1 A (rows sum to zero); L @ V is each vertex minus its neighbours' mean, and 0 at
    a vertex no face uses (its row is empty)."""
    adj = edge_adjacency(unique_edges(faces), num_vertices)
    deg = np.asarray(adj.sum(axis=1)).ravel()
    inv = np.where(deg > 0, 1.0 / np.maximum(deg, 1), 0.0)
    return (sp.diags((deg > 0).astype(np.float64)) - sp.diags(inv) @ adj).tocsr()


def surface_smoother(vertices: np.ndarray, faces: np.ndarray, sigma: float) -> Callable[[np.ndarray], np.ndarray]:
    """A function that smooths (N, C) per-vertex values along the surface at about the length ``sigma`` (m): one
    implicit heat step (I + t L)^-1 with t = sigma^2 / 2, L the graph Laplacian with weights 2 / (3 l^2) per edge of
    length l (on an equilateral mesh the Laplace-Beltrami operator). Constant values stay constant."""
    from scipy.sparse.linalg import splu

    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    e = unique_edges(faces)
    adj = edge_adjacency(e, n, (2.0 / 3.0) / np.maximum(np.sum((v[e[:, 0]] - v[e[:, 1]]) ** 2, axis=1), 1e-12))
    lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    solve = splu((sp.identity(n) + (0.5 * sigma * sigma) * lap).tocsc()).solve
    return lambda values: solve(np.asarray(values, dtype=np.float64))


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(face_normals(vertices, faces, normalize=False), axis=1)


def boundary_edges(faces: np.ndarray) -> np.ndarray:
    """(B, 2) edges used by exactly one face (the mesh border)."""
    f = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=0)
    e.sort(axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    return uniq[counts == 1]


def vertex_rings(vertices: np.ndarray, faces: np.ndarray, k: int) -> np.ndarray:
    """(V, k) each vertex itself, then its mesh 1-ring neighbours nearest first, padded with itself.

    Mesh connectivity, not Euclidean kNN: a kNN set on a regular mesh has distance ties that flip
    under float rounding of a moved scene, while the ring's membership is fixed by the faces. Only a
    vertex of valence above k - 1 loses its farthest neighbours.
    """
    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    tab = np.repeat(np.arange(n, dtype=np.int64)[:, None], k, axis=1)
    if k < 2 or len(faces) == 0:
        return tab
    e = unique_edges(faces)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    dist = np.linalg.norm(v[dst] - v[src], axis=1)
    order = np.lexsort((dst, dist, src))
    src, dst = src[order], dst[order]
    start = np.searchsorted(src, np.arange(n))
    rank = np.arange(len(src)) - start[src]
    keep = rank < k - 1
    tab[src[keep], 1 + rank[keep]] = dst[keep]
    return tab


def border_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Vertex index sets of the border loops (connected components of the boundary edges)."""
    from scipy.sparse.csgraph import connected_components

    e = boundary_edges(faces)
    if len(e) == 0:
        return []
    verts, inv = np.unique(e.ravel(), return_inverse=True)
    inv = inv.reshape(-1, 2)
    adj = sp.coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(len(verts), len(verts)))
    ncomp, labels = connected_components(adj, directed=False)
    return [verts[labels == c] for c in range(ncomp)]


def piece_count(faces: np.ndarray, num_vertices: int) -> int:
    """How many separate pieces a mesh has: sets of faces joined through their vertices (two triangles that touch at
    one vertex are one piece)."""
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return 0
    labels = connected_components(edge_adjacency(unique_edges(f), num_vertices), directed=False)[1]
    return len(np.unique(labels[np.unique(f)]))


TOP_LOOP_BAND = 0.04
"""m: a border loop is a top loop when its highest vertex is within this of the highest border vertex (the band
the data generator pins shoulder-hung garments in, ``physics.generate.SHOULDER_PIN_BAND``)."""


def top_border_loops(vertices: np.ndarray, faces: np.ndarray, band: float = TOP_LOOP_BAND) -> list[np.ndarray]:
    """The border loops a garment hangs from, highest first: every loop whose highest vertex (Z up) is within
    ``band`` of the highest border vertex. A skirt's or trousers' waistband; the neck of a t-shirt (its sleeve
    hems end lower); the neckline and both armholes of a strapped top or dress (they meet on the straps). A
    garment without a border (closed) has none."""
    z = np.asarray(vertices)[:, 2]
    loops = border_loops(faces)
    if not loops:
        return []
    tops = np.array([z[loop].max() for loop in loops])
    keep = np.flatnonzero(tops >= tops.max() - band)
    return [loops[i] for i in keep[np.argsort(-tops[keep], kind="stable")]]


WELD_TOLERANCE = 1e-4
"""m: garment vertices this close to one another and not joined by an edge are one vertex split in the file (at UV
seams or hard edges, as glTF exporters write them) and are draped as one (``garsim.api.Scene``)."""


def weld_index(vertices: np.ndarray, faces: np.ndarray, tolerance: float = WELD_TOLERANCE) -> np.ndarray | None:
    """(N,) the welded vertex of each vertex when some lie within ``tolerance`` of another without sharing an edge
    with it (groups chain: a within reach of b, b of c), numbered by each group's lowest vertex index; None when no
    two do. A mesh's own short edges are left alone (remeshers leave some of a few micrometres), also where a seam
    crosses one: a pair is not welded where one of them lies nearer a mesh neighbour of the other than the other
    itself (it is that neighbour's copy)."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    pairs = cKDTree(v).query_pairs(tolerance, output_type="ndarray")  # i < j
    if len(pairs):
        edges = unique_edges(faces)  # i < j too
        pairs = pairs[~np.isin(pairs[:, 0] * n + pairs[:, 1], edges[:, 0] * n + edges[:, 1])]
    if len(pairs):
        adjacency = edge_adjacency(edges, n)
        gap = np.linalg.norm(v[pairs[:, 0]] - v[pairs[:, 1]], axis=1)
        keep = np.ones(len(pairs), dtype=bool)
        for a, b in ((0, 1), (1, 0)):  # b nearer a neighbour k of a than to a: b is k's copy
            rows = adjacency[pairs[:, a]]
            owner = np.repeat(np.arange(len(pairs)), np.diff(rows.indptr))
            near = np.linalg.norm(v[rows.indices] - v[pairs[owner, b]], axis=1) < gap[owner]
            keep[owner[near]] = False
        pairs = pairs[keep]
    if len(pairs) == 0:
        return None
    return connected_components(edge_adjacency(pairs, n), directed=False)[1].astype(np.int64)


def weld(vertices: np.ndarray, faces: np.ndarray, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with each group of ``index`` (:func:`weld_index`) as one vertex at the group's mean (so the result
    is continuous in the input); faces that collapse (two corners in one group) or repeat another's three
    vertices are dropped, the first of repeated ones kept."""
    v = np.asarray(vertices, dtype=np.float64)
    m = int(index.max()) + 1
    counts = np.bincount(index, minlength=m)[:, None]
    welded = np.stack([np.bincount(index, weights=v[:, k], minlength=m) for k in range(3)], axis=1) / counts
    f = index[np.asarray(faces, dtype=np.int64)]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]
    first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)[1]
    return welded.astype(np.asarray(vertices).dtype), f[np.sort(first)]
