"""Fast physical refinement of a predicted garment: a few vectorised constraint projections, no simulator.

:func:`refine` runs after the network on the inference path. It corrects what a learned prediction
gets wrong and a viewer notices, and leaves everything else exactly where the network put it:

(a) stretch: every edge longer than ``max_stretch`` x its rest length (from ``template``) is shortened
    to that limit; compression is left alone (cloth buckles);
(b) contact: every vertex closer than ``margin`` to the obstacle surface, or inside it, goes to
    ``margin`` outside along the outward direction from its closest point on the obstacle's triangles;
(c) edges through the obstacle: three sample points per edge (t = 1/4, 1/2, 3/4) may sit at most
    ``margin`` inside the surface, so a limb cannot cut the cloth between two outside vertices;
(d) a small bending term: the correction (not the shape) is diffused once to the one-ring with a
    weight from the fabric's bending length, so a stiff fabric lifts its neighbours a little with a
    pushed vertex. A valid drape has no correction, so this never moves it.

Algorithm: position-based dynamics with Jacobi sweeps (order-independent, so the result does not
depend on vertex order) and averaging by the number of active constraints per vertex, over-relaxed.
Contacts are linearised as half-spaces (closest point c, outward unit normal n: n.(x - c) >= margin)
from exact closest-point queries, refreshed after every ``iterations`` sweeps (a round) only for the
vertices that moved; rounds repeat until nothing is violated (at most ``MAX_ROUNDS``), and a final exact
contact projection guarantees the margin (contact wins over stretch where they conflict).

Closest point on the obstacle: the triangles are split (1-to-4, per triangle, until each piece fits in
a ball of ``FINE_RADIUS``); a KD-tree over the pieces' centroids gives candidates (only those within
reach of the band around the surface) and an exact vectorised point-triangle distance (Ericson 5.1.5)
picks the closest. The candidate set grows (8, then 32 = ``MAX_CANDIDATES``) until it provably holds the
closest piece (distance <= k-th centroid distance - piece radius); past 32 the best found is taken. The
inside/outside sign is the angle-weighted pseudo-normal of the closest feature (vertex, edge or face
of the original mesh; Baerentzen & Aanaes 2005), exact for a closed, outward-oriented mesh. Points away
from the surface get a distance lower bound and a sign from their nearest piece (nearest obstacle
vertex beyond ~5 cm); one that looks inside gets an unlimited exact search. Edge samples are only
queried where the 1-Lipschitz bound from their endpoints' distances allows a violation, and only
again when they moved. Per-obstacle work (split, trees, pseudo-normals; ~0.15 s for Anny's 27k
triangles) is cached by content, so a body reused across garments is prepared once.

Limits: points farther than ``margin`` + ``BAND`` from the obstacle are classified by one nearby
piece's (or vertex's) pseudo-normal; a point deep inside a concave fold could be missed there. The
obstacle should be closed and outward-oriented for the sign to be right. Stretch and contact can
conflict (a pinned vertex inside the body, a garment too small for the body): contact wins.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from garsim.garments.fabrics import Fabric, get_fabric
from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.mesh import unique_edges

DEFAULT_STRETCH = 1.10
"""Default edge-length limit (x rest length) for preset-like fabrics (membrane stiffness >= 3e3 N/m)."""
MAX_DEFAULT_STRETCH = 1.15
"""The derived default never exceeds this (a very soft custom fabric gets up to it)."""
FINE_RADIUS = 0.012
"""m: for the exact search, obstacle triangles are split until each piece fits in a ball of this radius."""
COARSE_RADIUS = 0.012
"""m: the (coarser or same) split used for distance bounds and inside tests away from the surface."""
BAND = 0.004
"""m: vertices within ``margin`` + this of the obstacle get exact contact half-spaces for the sweeps."""
MAX_ROUNDS = 12
"""Rounds of ``iterations`` sweeps at most; a round ends with fresh exact queries for moved vertices."""
EDGE_SAMPLES = (0.25, 0.5, 0.75)
"""Edge parameters tested against the obstacle for (c)."""
RELAXATION = 1.5
"""Over-relaxation of the averaged Jacobi stretch sweeps (1 = plain averaging; < 2 is stable)."""
MAX_CANDIDATES = 32
"""Candidate pieces per point at most in the near-surface search (the proof of exactness usually needs 8-32)."""
_STRETCH_TOL = 1e-3  # relative: an edge within limit * (1 + this) counts as satisfied
_DIST_TOL = 1e-6  # m


# ----------------------------------------------------------------------------------------------------
# obstacle: split triangles, KD-tree, pseudo-normals (cached by content)


class _Pieces:
    """A mesh's triangles split (1-to-4) until each piece fits in a ball of ``radius`` around its centroid,
    a KD-tree over the centroids, and the pseudo-normal of every piece feature (corner, edge, interior)."""

    def __init__(
        self, tri: np.ndarray, vn_corner: np.ndarray, face_n: np.ndarray, face_edge_n: np.ndarray, radius: float
    ) -> None:
        nf = len(tri)
        parent = np.arange(nf)
        bary = np.broadcast_to(np.eye(3), (nf, 3, 3)).copy()  # (P, piece corner, weight of parent vertex)
        done_parent, done_bary = [], []
        for _ in range(16):
            pts = np.einsum("pcw,pwd->pcd", bary, tri[parent])
            r = np.linalg.norm(pts - pts.mean(1, keepdims=True), axis=2).max(1)
            big = r > radius
            done_parent.append(parent[~big])
            done_bary.append(bary[~big])
            if not big.any():
                break
            parent, b0 = parent[big], bary[big]
            m01, m12, m20 = 0.5 * (b0[:, 0] + b0[:, 1]), 0.5 * (b0[:, 1] + b0[:, 2]), 0.5 * (b0[:, 2] + b0[:, 0])
            bary = np.concatenate(
                [
                    np.stack([b0[:, 0], m01, m20], 1),
                    np.stack([m01, b0[:, 1], m12], 1),
                    np.stack([m20, m12, b0[:, 2]], 1),
                    np.stack([m01, m12, m20], 1),
                ],
                0,
            )
            parent = np.tile(parent, 4)
        else:  # pragma: no cover - 16 halvings shrink any body triangle far below the radius
            done_parent.append(parent)
            done_bary.append(bary)
        parent = np.concatenate(done_parent)
        bary = np.concatenate(done_bary)
        pts = np.einsum("pcw,pwd->pcd", bary, tri[parent])  # (P, 3, 3)
        self.num = len(parent)
        self.a = np.ascontiguousarray(pts[:, 0])
        self.ab = np.ascontiguousarray(pts[:, 1] - pts[:, 0])
        self.ac = np.ascontiguousarray(pts[:, 2] - pts[:, 0])
        self.aa = (self.ab * self.ab).sum(1)
        self.cc = (self.ac * self.ac).sum(1)
        self.bc = (self.ab * self.ac).sum(1)
        cen = pts.mean(1)
        rad = np.linalg.norm(pts - cen[:, None], axis=2).max(1)
        self.radius = float(rad.max())
        self.tree = cKDTree(cen)
        # pseudo-normals: a piece corner or edge inherits the parent feature it lies on (exact zeros
        # survive halving), else the parent face normal
        nz = bary > 0
        ncount = nz.sum(2)
        self.face_n = face_n[parent]
        self.corner_n = np.repeat(self.face_n[:, None], 3, axis=1)
        self.edge_n = self.corner_n.copy()
        for c in range(3):
            on_vertex = ncount[:, c] == 1
            on_edge = ncount[:, c] == 2
            pv = np.argmax(bary[:, c], axis=1)
            pe = np.argmin(bary[:, c], axis=1)
            self.corner_n[on_vertex, c] = vn_corner[parent[on_vertex], pv[on_vertex]]
            self.corner_n[on_edge, c] = face_edge_n[parent[on_edge], pe[on_edge]]
            shared_zero = ~nz[:, (c + 1) % 3] & ~nz[:, (c + 2) % 3]  # piece edge opposite c on a parent edge
            on_parent_edge = shared_zero.any(1)
            zi = np.argmax(shared_zero, axis=1)
            self.edge_n[on_parent_edge, c] = face_edge_n[parent[on_parent_edge], zi[on_parent_edge]]

    def closest(self, p: np.ndarray, cand: np.ndarray) -> tuple[np.ndarray, ...]:
        """Exact closest point of each p (M, 3) over candidate pieces (M, k) (Ericson 5.1.5, vectorised):
        (distance, piece, v, w, closest point) with v, w the barycentrics of the piece's 2nd and 3rd corner."""
        a, ab, ac = self.a[cand], self.ab[cand], self.ac[cand]
        ap = p[:, None, :] - a
        d1 = np.einsum("mkd,mkd->mk", ab, ap)
        d2 = np.einsum("mkd,mkd->mk", ac, ap)
        aa, cc, bc = self.aa[cand], self.cc[cand], self.bc[cand]
        d3, d4 = d1 - aa, d2 - bc
        d5, d6 = d1 - bc, d2 - cc
        va = d3 * d6 - d5 * d4
        vb = d5 * d2 - d1 * d6
        vc = d1 * d4 - d3 * d2
        den = va + vb + vc
        den = np.where(den > 1e-300, den, 1.0)
        t_ab = d1 / np.where(d1 - d3 > 1e-300, d1 - d3, 1.0)
        t_ac = d2 / np.where(d2 - d6 > 1e-300, d2 - d6, 1.0)
        s_bc = (d4 - d3) + (d5 - d6)
        t_bc = (d4 - d3) / np.where(s_bc > 1e-300, s_bc, 1.0)
        conds = [
            (d1 <= 0) & (d2 <= 0),
            (d3 >= 0) & (d4 <= d3),
            (d6 >= 0) & (d5 <= d6),
            (vc <= 0) & (d1 >= 0) & (d3 <= 0),
            (vb <= 0) & (d2 >= 0) & (d6 <= 0),
            (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0),
        ]
        v = np.clip(np.select(conds, [0.0, 1.0, 0.0, t_ab, 0.0, 1.0 - t_bc], vb / den), 0.0, 1.0)
        w = np.clip(np.select(conds, [0.0, 0.0, 1.0, 0.0, t_ac, t_bc], vc / den), 0.0, 1.0)
        q = a + v[..., None] * ab + w[..., None] * ac
        d2q = ((p[:, None, :] - q) ** 2).sum(-1)
        best = np.argmin(d2q, axis=1)
        rows = np.arange(len(p))
        return np.sqrt(d2q[rows, best]), cand[rows, best], v[rows, best], w[rows, best], q[rows, best]

    def feature_normal(self, piece: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The (unnormalised) pseudo-normal of the feature holding each closest point."""
        bw = np.stack([1.0 - v - w, v, w], 1)
        cnt = (bw > 1e-12).sum(1)
        out = self.face_n[piece].copy()
        one = cnt == 1
        if one.any():
            out[one] = self.corner_n[piece[one], np.argmax(bw[one], axis=1)]
        two = cnt == 2
        if two.any():
            out[two] = self.edge_n[piece[two], np.argmin(bw[two], axis=1)]
        return out

    def sign(self, p, close, piece, v, w) -> np.ndarray:
        s = np.einsum("md,md->m", p - close, self.feature_normal(piece, v, w))
        return np.where(s < 0, -1.0, 1.0)

    def search(self, p: np.ndarray, todo: np.ndarray, reach: float) -> tuple[np.ndarray, tuple, np.ndarray]:
        """Closest pieces of the points ``p[todo]``, unless farther than ``reach``.

        Candidates are the nearest centroids within ``reach`` + radius; their number grows 4x until the
        set provably holds the closest piece (best distance <= k-th centroid distance - radius), up
        to ``MAX_CANDIDATES`` for a finite ``reach`` (then the best found is taken: exact except where
        tiny and big pieces meet) and without limit otherwise. Returns (resolved indices, their
        (distance, piece, v, w, closest), far indices).
        """
        res_idx, res, far_idx = [], [], []
        k = min(8, self.num)
        ub = reach + self.radius
        while len(todo):
            dc, cand = self.tree.query(p[todo], k=k, distance_upper_bound=ub)
            dc = np.asarray(dc).reshape(len(todo), k)
            cand = np.asarray(cand, dtype=np.int64).reshape(len(todo), k)
            has = np.isfinite(dc[:, 0])  # no centroid within ub: farther than reach
            if (~has).any():
                far_idx.append(todo[~has])
            todo, dc, cand = todo[has], dc[has], cand[has]
            if not len(todo):
                break
            valid = np.isfinite(dc)
            cand = np.where(valid, cand, cand[:, :1])
            dd, pc, vv, ww, qq = self.closest(p[todo], cand)
            full = valid[:, -1] & (k < self.num)
            lb = np.where(full, dc[:, -1] - self.radius, np.inf)  # every untested piece is at least this far
            last = np.isfinite(reach) and k >= MAX_CANDIDATES
            proven = (dd <= lb) | (last & (dd <= reach))
            far = ~proven & (np.minimum(dd, lb) > reach) | (last & ~proven)
            res_idx.append(todo[proven])
            res.append((dd[proven], pc[proven], vv[proven], ww[proven], qq[proven]))
            if far.any():
                far_idx.append(todo[far])
            todo = todo[~proven & ~far]
            k = min(4 * k, self.num)
        if res_idx:
            best = tuple(np.concatenate([r[i] for r in res]) for i in range(5))
            idx = np.concatenate(res_idx)
        else:
            best = (np.zeros(0), np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros((0, 3)))
            idx = np.zeros(0, dtype=np.int64)
        far = np.concatenate(far_idx) if far_idx else np.zeros(0, dtype=np.int64)
        return idx, best, far


class _Obstacle:
    """A triangle mesh prepared for signed closest-point queries: fine pieces for the exact search near the
    surface, coarse pieces for distance bounds and the sign farther out, vertex pseudo-normals beyond."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        tri = v[f]
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)
        ang = np.empty((len(f), 3))  # corner angles: angle-weighted vertex pseudo-normals
        for c in range(3):
            e1 = tri[:, (c + 1) % 3] - tri[:, c]
            e2 = tri[:, (c + 2) % 3] - tri[:, c]
            cosang = (e1 * e2).sum(1) / np.maximum(np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-30)
            ang[:, c] = np.arccos(np.clip(cosang, -1.0, 1.0))
        wn = (ang[:, :, None] * fn[:, None, :]).reshape(-1, 3)
        vn = np.stack([np.bincount(f.ravel(), weights=wn[:, k], minlength=len(v)) for k in range(3)], axis=1)
        # edge pseudo-normals (sum of the adjacent unit face normals); face edge c is opposite corner c
        a = np.stack([f[:, 1], f[:, 2], f[:, 0]], axis=1).ravel()
        b = np.stack([f[:, 2], f[:, 0], f[:, 1]], axis=1).ravel()
        _, inv = np.unique(np.minimum(a, b) * len(v) + np.maximum(a, b), return_inverse=True)
        fn3 = np.repeat(fn, 3, axis=0)
        en = np.stack([np.bincount(inv, weights=fn3[:, k]) for k in range(3)], axis=1)
        face_edge_n = en[inv].reshape(len(f), 3, 3)
        vn_corner = vn[f]
        self.fine = _Pieces(tri, vn_corner, fn, face_edge_n, FINE_RADIUS)
        same = COARSE_RADIUS == FINE_RADIUS
        self.coarse = self.fine if same else _Pieces(tri, vn_corner, fn, face_edge_n, COARSE_RADIUS)
        self.vpos = v
        self.vnormal = vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
        self.vtree = cKDTree(v)

    def query(
        self, points: np.ndarray, band: float, far_outside: np.ndarray | None = None, reach: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance (negative inside), closest point, outward unit normal and an ``exact`` flag.

        Exact for every point within ``band`` of the surface and every point found inside. Any other
        point is reported at a lower bound of its distance (>= ``band``; with ``reach`` > ``band`` the
        bound from the nearest coarse piece within ``reach``), closest point and normal zero,
        ``exact`` False. Its inside test uses the nearest coarse piece's pseudo-normal (the nearest
        obstacle vertex's beyond ``reach``) and an exact search when that says inside.
        ``far_outside`` (M,) bool marks points known not to be deeper than ``band`` (no test needed).
        """
        p = np.asarray(points, dtype=np.float64)
        m = len(p)
        band = float(band)
        sdist = np.full(m, band)
        close = np.zeros((m, 3))
        normal = np.zeros((m, 3))
        exact = np.zeros(m, dtype=bool)
        if m == 0:
            return sdist, close, normal, exact
        fine, coarse = self.fine, self.coarse
        near, best, far = fine.search(p, np.arange(m), band)
        if len(far):
            ub = max(reach, band) + coarse.radius
            sel = np.ones(len(far), dtype=bool) if far_outside is None else ~np.asarray(far_outside, bool)[far]
            if reach > band:  # a distance bound for every far point
                dc, pc1 = coarse.tree.query(p[far], k=1, distance_upper_bound=ub)
                sdist[far] = np.maximum(band, np.minimum(dc, ub) - coarse.radius)
                test, dc, pc1 = far[sel], dc[sel], pc1[sel]
            else:
                test = far[sel]
                dc, pc1 = coarse.tree.query(p[test], k=1, distance_upper_bound=ub)
            got = np.isfinite(dc)
            looks_inside = np.zeros(len(test), dtype=bool)
            if got.any():
                tg = test[got]
                _, pcg, vg, wg, qg = coarse.closest(p[tg], pc1[got].astype(np.int64)[:, None])
                looks_inside[got] = coarse.sign(p[tg], qg, pcg, vg, wg) < 0
            if (~got).any():
                tr = test[~got]
                _, vi = self.vtree.query(p[tr], k=1)
                looks_inside[~got] = np.einsum("md,md->m", p[tr] - self.vpos[vi], self.vnormal[vi]) < 0
            deep = test[looks_inside]
            if len(deep):
                found, best2, _ = fine.search(p, deep, np.inf)
                near = np.concatenate([near, found])
                best = tuple(np.concatenate([a, b]) for a, b in zip(best, best2))
        if len(near):
            _, pc, vv, ww, qq = best
            sign = fine.sign(p[near], qq, pc, vv, ww)
            diff = p[near] - qq
            nrm = np.linalg.norm(diff, axis=1)
            feat_n = fine.feature_normal(pc, vv, ww)
            feat_n /= np.maximum(np.linalg.norm(feat_n, axis=1, keepdims=True), 1e-30)
            normal[near] = np.where(
                (nrm > 1e-12)[:, None], sign[:, None] * diff / np.maximum(nrm, 1e-30)[:, None], feat_n
            )
            sdist[near] = sign * nrm
            close[near] = qq
            exact[near] = True
        return sdist, close, normal, exact


_OBSTACLES = ContentCache(4)


def obstacle(body_vertices: np.ndarray, body_faces: np.ndarray) -> _Obstacle:
    """The prepared obstacle for a triangle mesh, cached by the arrays' content."""
    return _OBSTACLES.get(content_key(body_vertices, body_faces), lambda: _Obstacle(body_vertices, body_faces))


# ----------------------------------------------------------------------------------------------------
# garment topology (cached by content)


class _Topology:
    def __init__(self, faces: np.ndarray, n: int) -> None:
        self.edges = unique_edges(faces) if len(faces) else np.zeros((0, 2), dtype=np.int64)
        e = self.edges
        deg = np.bincount(e.ravel(), minlength=n).astype(np.float64)
        self.inv_degree = np.where(deg > 0, 1.0 / np.maximum(deg, 1.0), 0.0)


_TOPOLOGY = ContentCache(8)


def _topology(faces: np.ndarray, n: int) -> _Topology:
    return _TOPOLOGY.get(content_key(faces) + (n,), lambda: _Topology(faces, n))


# ----------------------------------------------------------------------------------------------------
# validation


def _points(a, name: str, n: int | None = None) -> np.ndarray:
    arr = np.asarray(a)
    if arr.ndim != 2 or arr.shape[1] != 3 or (n is not None and len(arr) != n):
        want = f"({n}, 3)" if n is not None else "(N, 3)"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite numbers (found NaN/inf or a non-numeric dtype)")
    return arr


def _faces(a, name: str, n: int) -> np.ndarray:
    f = np.asarray(a)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"{name} must be an integer (F, 3) array, got {f.dtype} {f.shape}")
    if len(f) and (f.min() < 0 or f.max() >= n):
        raise ValueError(f"{name} index vertices outside [0, {n - 1}]")
    return f.astype(np.int64, copy=False)


def default_max_stretch(fabric: str | Fabric) -> float:
    """The edge-length limit for a fabric: 1.10 for the presets, up to 1.15 for a very soft membrane."""
    s = get_fabric(fabric).stretch
    return float(min(MAX_DEFAULT_STRETCH, DEFAULT_STRETCH + float(np.clip(0.05 * np.log10(3.0e3 / s), 0.0, 0.05))))


def smoothing_weight(fabric: str | Fabric, edge_length: float) -> float:
    """Weight of the one-ring diffusion of the correction: 0.5 * l_b / (l_b + edge length), l_b the bending length."""
    lb = get_fabric(fabric).bending_length
    return float(0.5 * lb / (lb + max(edge_length, 1e-6)))


# ----------------------------------------------------------------------------------------------------
# the refinement


def refine(
    garment: np.ndarray,
    template: np.ndarray,
    faces: np.ndarray,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    fabric: str | Fabric = "cotton",
    pinned: np.ndarray | None = None,
    iterations: int = 10,
    margin: float = 0.002,
    max_stretch: float | None = None,
) -> np.ndarray:
    """Project a predicted garment onto the stretch-limit and no-penetration constraints (see module doc).

    ``garment`` (N, 3) the prediction on the target body, ``template`` (N, 3) its rest shape (edge rest
    lengths), ``faces`` (F, 3); ``body_vertices`` / ``body_faces`` any closed, outward-oriented
    triangle mesh as the obstacle; ``pinned`` (N,) bool vertices that never move. Returns (N, 3) in
    the garment's float dtype (float64 for integer input); a garment that violates nothing is returned
    unchanged.
    """
    x_in = _points(garment, "garment")
    n = len(x_in)
    tpl = _points(template, "template", n)
    f = _faces(faces, "faces", n)
    bv = _points(body_vertices, "body_vertices")
    bf = _faces(body_faces, "body_faces", len(bv))
    if len(bf) == 0:
        raise ValueError("body_faces is empty: the obstacle needs at least one triangle")
    fab = get_fabric(fabric)
    if pinned is None:
        pin = np.zeros(n, dtype=bool)
    else:
        pin = np.asarray(pinned)
        if pin.shape != (n,) or pin.dtype != bool:
            raise ValueError(f"pinned must be a bool array of shape ({n},), got {pin.dtype} {pin.shape}")
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    if not isinstance(margin, (int, float, np.floating)) or not np.isfinite(margin) or margin < 0:
        raise ValueError(f"margin must be a finite number >= 0 metres, got {margin!r}")
    if max_stretch is None:
        limit = default_max_stretch(fab)
    else:
        if not isinstance(max_stretch, (int, float, np.floating)) or not np.isfinite(max_stretch) or max_stretch < 1:
            raise ValueError(f"max_stretch must be a finite number >= 1, got {max_stretch!r}")
        limit = float(max_stretch)
    out_dtype = x_in.dtype if np.issubdtype(x_in.dtype, np.floating) else np.float64
    if n == 0:
        return np.array(x_in, dtype=out_dtype)

    obs = obstacle(bv, bf)
    topo = _topology(f, n)
    edges = topo.edges
    margin = float(margin)
    band = margin + BAND
    mobile = (~pin).astype(np.float64)

    x0 = np.asarray(x_in, dtype=np.float64)
    rest = np.linalg.norm(np.asarray(tpl, np.float64)[edges[:, 1]] - np.asarray(tpl, np.float64)[edges[:, 0]], axis=1)
    use = (rest > 1e-12) & ((mobile[edges[:, 0]] + mobile[edges[:, 1]]) > 0)
    e_s, rest_s = edges[use], rest[use]
    lim_s = limit * rest_s
    ts = np.asarray(EDGE_SAMPLES)
    e_mov = edges[(mobile[edges[:, 0]] + mobile[edges[:, 1]]) > 0]

    # exact state of every vertex
    x = x0.copy()

    def reach(x):  # how far a vertex distance matters for the edge-sample bound below
        if len(e_mov) == 0:
            return band
        return float(min(0.75 * np.linalg.norm(x[e_mov[:, 1]] - x[e_mov[:, 0]], axis=1).max() + BAND, 0.1))

    d, c, nrm, _ = obs.query(x, band, reach=reach(x))
    xq = x.copy()  # positions at the last query

    # edge samples: results cached per (edge, t) and recomputed only where the sample moved
    ne = len(e_mov)
    s_pos = np.full((ne, len(ts), 3), np.nan)
    s_d = np.zeros((ne, len(ts)))
    s_c = np.zeros((ne, len(ts), 3))
    s_n = np.zeros((ne, len(ts), 3))

    def sample_state(x, d):
        """Edge samples that may lie deeper than ``margin`` inside: (edge, t, dist, closest, normal) or None."""
        if ne == 0:
            return None
        i, j = e_mov[:, 0], e_mov[:, 1]
        length = np.linalg.norm(x[j] - x[i], axis=1)
        di, dj = d[i], d[j]
        # the distance is 1-Lipschitz: the sample at t is at least max(d_i - t L, d_j - (1 - t) L) from the surface
        bound = np.maximum(di[:, None] - ts[None] * length[:, None], dj[:, None] - (1 - ts[None]) * length[:, None])
        ke, kt = np.nonzero(bound < -margin + 0.5 * BAND)
        if len(ke) == 0:
            return None
        t = ts[kt]
        s = (1 - t)[:, None] * x[i[ke]] + t[:, None] * x[j[ke]]
        new = ~np.all(s == s_pos[ke, kt], axis=1)
        if new.any():
            kn, tn = ke[new], kt[new]
            # a sample that cannot be deeper than BAND and has no surface within BAND is outside
            sd, sc, sn, _ = obs.query(s[new], BAND, far_outside=bound[kn, tn] > -BAND)
            s_pos[kn, tn], s_d[kn, tn], s_c[kn, tn], s_n[kn, tn] = s[new], sd, sc, sn
        sd = s_d[ke, kt]
        keep = sd < -margin + 0.5 * BAND  # near the -margin limit: kept as half-spaces for the sweeps
        ke, kt = ke[keep], kt[keep]
        return e_mov[ke], ts[kt], s_d[ke, kt], s_c[ke, kt], s_n[ke, kt]

    def violated(x, d, samples) -> bool:
        if len(e_s):
            length = np.linalg.norm(x[e_s[:, 1]] - x[e_s[:, 0]], axis=1)
            if (length > lim_s * (1 + _STRETCH_TOL)).any():
                return True
        if ((d < margin - _DIST_TOL) & (mobile > 0)).any():
            return True
        if samples is not None and (samples[2] < -margin - _DIST_TOL).any():
            return True
        return False

    samples = sample_state(x, d)
    if not violated(x, d, samples):
        return np.array(x_in, dtype=out_dtype)

    mean_edge = float(rest.mean()) if len(rest) else 0.0
    alpha = smoothing_weight(fab, mean_edge)
    wdeg = topo.inv_degree

    def requery(x, d, c, nrm, xq):
        moved = np.any(x != xq, axis=1)
        if moved.any():
            dm, cm, nm, _ = obs.query(x[moved], band, reach=reach(x))
            d, c, nrm = d.copy(), c.copy(), nrm.copy()
            d[moved], c[moved], nrm[moved] = dm, cm, nm
            xq = x.copy()
        return d, c, nrm, xq

    for rnd in range(MAX_ROUNDS):
        cv = np.nonzero((d < band) & (mobile > 0))[0]
        cc, cn = c[cv], nrm[cv]
        if samples is not None:
            se, st, _, sc, sn = samples
            si, sj = se[:, 0], se[:, 1]
            wi, wj = mobile[si] * (1 - st), mobile[sj] * st
            sden = wi * (1 - st) + wj * st
        for _ in range(int(iterations)):
            # (a) stretch, averaged Jacobi, over-relaxed
            if len(e_s):
                i, j = e_s[:, 0], e_s[:, 1]
                dx = x[j] - x[i]
                length = np.linalg.norm(dx, axis=1)
                act = length > lim_s
                if act.any():
                    ia, ja = i[act], j[act]
                    mi, mj = mobile[ia], mobile[ja]
                    corr = ((length[act] - lim_s[act]) / (length[act] * (mi + mj)))[:, None] * dx[act]
                    idx = np.concatenate([ia, ja])
                    wts = np.concatenate([mi, mj])
                    vec = np.concatenate([corr, -corr])
                    acc = np.stack([np.bincount(idx, weights=wts * vec[:, k], minlength=n) for k in range(3)], 1)
                    cnt = np.bincount(idx, weights=wts, minlength=n)
                    x += RELAXATION * acc / np.maximum(cnt, 1.0)[:, None]
            # (c) edge samples through the obstacle (half-spaces), averaged Jacobi
            if samples is not None and len(st):
                s = (1 - st)[:, None] * x[si] + st[:, None] * x[sj]
                depth = -margin - np.einsum("md,md->m", s - sc, sn)
                act = (depth > 0) & (sden > 0)
                if act.any():
                    lam = depth[act] / sden[act]
                    idx = np.concatenate([si[act], sj[act]])
                    wts = np.concatenate([wi[act], wj[act]])
                    vec = np.concatenate([lam[:, None] * sn[act], lam[:, None] * sn[act]])
                    acc = np.stack([np.bincount(idx, weights=wts * vec[:, k], minlength=n) for k in range(3)], 1)
                    cnt = np.bincount(idx, weights=(wts > 0).astype(np.float64), minlength=n)
                    x += acc / np.maximum(cnt, 1.0)[:, None]
            # (b) vertex contact half-spaces, direct projection
            if len(cv):
                g = np.einsum("md,md->m", x[cv] - cc, cn) - margin
                hit = g < 0
                if hit.any():
                    x[cv[hit]] -= g[hit, None] * cn[hit]
        # (d) one diffusion of the correction to the one-ring (first round only), weighted by bending
        if rnd == 0 and alpha > 0 and len(edges):
            delta = x - x0
            nb = np.zeros_like(delta)
            for k in range(3):
                nb[:, k] = np.bincount(edges[:, 0], weights=delta[edges[:, 1], k], minlength=n) + np.bincount(
                    edges[:, 1], weights=delta[edges[:, 0], k], minlength=n
                )
            nb *= wdeg[:, None]
            x = x0 + delta + (alpha * mobile)[:, None] * (nb - delta)
        d, c, nrm, xq = requery(x, d, c, nrm, xq)
        samples = sample_state(x, d)
        if not violated(x, d, samples):
            break

    # final exact contact projection (contact wins over stretch), re-checked where the body is concave
    for _ in range(4):
        bad = (d < margin - _DIST_TOL) & (mobile > 0)
        if not bad.any():
            break
        x[bad] += (margin - d[bad])[:, None] * nrm[bad]
        d, c, nrm, xq = requery(x, d, c, nrm, xq)
    return x.astype(out_dtype)
