"""Sample -> garment graph: every input of the paper's Eq. 2, vectorised, as a torch_geometric Data.

Per garment vertex i: q_i (canonical body vertex nearest G_i, KD-tree), δ_i = B̄_q − B_q,
p_i = G_i − B_q, p^prior_i = G^prior_i − B̄_q, fabric one-hot f, pinned flag; per directed
mesh edge (i -> j): E_ij = G_j − G_i and E^prior_ij; local neighbourhoods for the geometry
encoder (k nearest garment vertices of G_i relative to G_i; and, once per distinct q, the
body vertex q with its body-mesh 1-ring relative to B_q, i.e. the body's geometry "at q_i");
the garment-aware body-semantic input (binary mask over the body vertices in q); faces and
face pairs for the losses. Everything about the canonical body alone (KD-tree, yaw frame,
rings) is computed once per body and cached by content (see ``body_frame``).

Frame: all vectors are expressed in a body frame (rotation ``rot``, world -> frame) whose
yaw comes from the canonical body alone (see ``body_yaw_frame``), so a rotation of the whole
scene about the vertical axis leaves every input unchanged and the model rotates its
output back: the prediction is exactly (to float rounding) equivariant to rotations about
Z and to translations. Full SO(3) equivariance is not wanted: gravity points down.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterable, Sequence

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch_geometric.data import Batch, Data

from garsim.data.sample import FABRICS, Sample
from garsim.geometry.proximity import cached_nearest, cached_tree
from garsim.geometry.mesh import directed_edges, face_normals, face_pairs, unique_edges
from garsim.model.config import GarSimConfig

_CACHE_SIZE = 8
_BODY_CACHE: OrderedDict[tuple, "BodyFrame"] = OrderedDict()


def _content_key(arr: np.ndarray) -> tuple:
    """Cache key from an array's content (shape, dtype and a hash of its bytes): safe under mutation."""
    return (arr.shape, arr.dtype.str, hash(arr.tobytes()))


def _lru_get(cache: OrderedDict, key: tuple, make):
    value = cache.get(key)
    if value is None:
        value = cache[key] = make()
        if len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return value


class BodyFrame:
    """Everything about one canonical body that does not depend on the garment, computed once.

    KD-tree, yaw frame ``rot`` (world -> body frame, identity without ``canonicalize_yaw``),
    the body's vertices in that frame, and (lazily) each body vertex's mesh neighbourhood,
    the point set the geometry encoder sees at ``q``.
    """

    def __init__(self, body_canonical: np.ndarray, faces: np.ndarray, canonicalize_yaw: bool):
        self.vertices = np.ascontiguousarray(body_canonical, dtype=np.float32)
        if not np.isfinite(self.vertices).all():
            raise ValueError("the canonical body has non-finite vertices: fix the body mesh")
        self.faces = np.asarray(faces, dtype=np.int64)
        self.tree = cached_tree(self.vertices)
        rot = body_yaw_frame(self.vertices) if canonicalize_yaw else np.eye(3)
        self.rot = rot.astype(np.float32)
        self.framed = self.vertices @ self.rot.T
        self.bounds = (self.framed.min(axis=0), self.framed.max(axis=0))
        self._rings: dict[int, np.ndarray] = {}

    def ring(self, k: int) -> np.ndarray:
        """(Vb, k) each body vertex itself, then its 1-ring neighbours (by index), padded with itself.

        Mesh connectivity, not Euclidean kNN: distance ties on the body's regular mesh would make
        a kNN set flip under float rounding of a moved scene; the ring (and its order) is exactly
        invariant. Anny's valence is at most 8, so k = 9 keeps whole rings; on bodies with larger
        valence the ring is cut to the k - 1 lowest-index neighbours.
        """
        if k not in self._rings:
            v = len(self.vertices)
            tab = np.repeat(np.arange(v, dtype=np.int64)[:, None], k, axis=1)
            if k > 1 and len(self.faces):
                e = unique_edges(self.faces)
                src = np.concatenate([e[:, 0], e[:, 1]])
                dst = np.concatenate([e[:, 1], e[:, 0]])
                order = np.lexsort((dst, src))
                src, dst = src[order], dst[order]
                start = np.searchsorted(src, np.arange(v))
                rank = np.arange(len(src)) - start[src]
                keep = rank < k - 1
                tab[src[keep], 1 + rank[keep]] = dst[keep]
            self._rings[k] = tab
        return self._rings[k]


def body_frame(body_canonical: np.ndarray, faces: np.ndarray, canonicalize_yaw: bool = True) -> BodyFrame:
    """The cached BodyFrame of a canonical body (keyed by its vertices' content, faces compared), so
    an edited body is never served stale data."""
    arr = np.ascontiguousarray(body_canonical, dtype=np.float32)
    f = np.asarray(faces, dtype=np.int64)
    key = _content_key(arr) + (bool(canonicalize_yaw),)
    hit = _BODY_CACHE.get(key)
    if hit is not None and (hit.faces is f or (hit.faces.shape == f.shape and np.array_equal(hit.faces, f))):
        _BODY_CACHE.move_to_end(key)
        return hit
    _BODY_CACHE.pop(key, None)
    return _lru_get(_BODY_CACHE, key, lambda: BodyFrame(arr, f.copy(), canonicalize_yaw))


def body_yaw_frame(body_canonical: np.ndarray) -> np.ndarray:
    """(3, 3) rotation about Z (world -> body frame) from the canonical body's horizontal shape.

    The frame's X axis is the major axis of the body's horizontal vertex covariance (the
    arm span in the T-pose), its Y axis the minor one, signed so that the body's horizontal
    third moment along +Y is negative (toes and belly stick out towards -Y, as in Anny's
    rest frame: the body faces -Y), and Z stays up. The construction commutes with rotations
    about Z and is translation invariant, which makes the model's prediction equivariant.
    """
    b = np.asarray(body_canonical, dtype=np.float64)[:, :2]
    c = b - b.mean(axis=0)
    cxx, cyy, cxy = (c[:, 0] ** 2).mean(), (c[:, 1] ** 2).mean(), (c[:, 0] * c[:, 1]).mean()
    theta = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    major = np.array([np.cos(theta), np.sin(theta)])
    minor = np.array([-major[1], major[0]])
    if ((c @ minor) ** 3).mean() > 0:
        minor = -minor
    x_axis = np.array([minor[1], -minor[0]])  # minor x up
    return np.array([[x_axis[0], x_axis[1], 0.0], [minor[0], minor[1], 0.0], [0.0, 0.0, 1.0]])


def semantic_vector(
    body_canonical_frame: np.ndarray,
    q: np.ndarray,
    config: GarSimConfig,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """The garment-aware body-semantic input: the binary mask of body vertices in q, (D,) float32.

    ``"vertex"`` mode returns the paper's mask itself (length = body vertex count).
    ``"grid"`` mode (default, any body topology) splats the masked vertices trilinearly onto a
    fixed grid in body-normalised coordinates (x, y centred on the body's bounding box and
    divided by its height, z from the feet up divided by the height; x in [-.5, .5],
    y in [-.25, .25], z in [0, 1]) and saturates each cell with 1 - exp(-count).
    ``bounds`` = the body's (min, max) corners, if already known (``BodyFrame.bounds``).
    """
    uq = np.unique(q)
    if config.semantic == "vertex":
        nb = int(config.num_body_vertices)  # type: ignore[arg-type]
        if len(body_canonical_frame) != nb:
            raise ValueError(
                f"the model's body-semantic MLP expects {nb} body vertices but the body has "
                f"{len(body_canonical_frame)}; use semantic='grid' for other body topologies"
            )
        mask = np.zeros(nb, dtype=np.float32)
        mask[uq] = 1.0
        return mask
    b = body_canonical_frame
    lo, hi = bounds if bounds is not None else (b.min(axis=0), b.max(axis=0))
    height = max(float(hi[2] - lo[2]), 1e-6)
    centre = 0.5 * (lo + hi)
    pts = b[uq]
    u = np.stack(
        [
            (pts[:, 0] - centre[0]) / height + 0.5,
            ((pts[:, 1] - centre[1]) / height + 0.25) / 0.5,
            (pts[:, 2] - lo[2]) / height,
        ],
        axis=1,
    )
    dims = np.asarray(config.semantic_grid)
    g = np.clip(u, 0.0, 1.0) * (dims - 1)
    i0 = np.minimum(np.floor(g).astype(np.int64), dims - 2)
    t = g - i0
    off = (np.arange(8)[:, None] >> np.arange(3)[None, :]) & 1  # (8, 3) cell corners
    w = np.prod(np.where(off[None] == 1, t[:, None, :], 1.0 - t[:, None, :]), axis=2)  # (U, 8)
    idx = i0[:, None, :] + off[None]
    flat = (idx[..., 0] * dims[1] + idx[..., 1]) * dims[2] + idx[..., 2]
    grid = np.bincount(flat.ravel(), weights=w.ravel(), minlength=int(np.prod(dims)))
    return (1.0 - np.exp(-grid)).astype(np.float32)


def _knn_self(points: np.ndarray, k: int) -> np.ndarray:
    """(N, k) indices of the k nearest points (self first); padded with self when N < k."""
    n = len(points)
    kk = min(k, n)
    _, idx = cKDTree(points).query(points, k=kk)
    idx = np.asarray(idx, dtype=np.int64).reshape(n, kk)
    if kk < k:
        idx = np.concatenate([idx, np.repeat(np.arange(n)[:, None], k - kk, axis=1)], axis=1)
    return idx


_GARMENT_CACHE: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()


def garment_topology(garment: np.ndarray, faces: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, k) garment kNN (self first) and (2, 2E) receiver-sorted directed edges of a template garment.

    Both depend only on the canonical garment, so they are cached by content: draping one garment
    on a sequence of target poses computes them once.
    """
    g = np.ascontiguousarray(garment, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    key = _content_key(g) + _content_key(f) + (int(k),)

    def make() -> tuple[np.ndarray, np.ndarray]:
        ei = directed_edges(f)
        ei = np.ascontiguousarray(ei[:, np.argsort(ei[1], kind="stable")])  # receiver-sorted (CSR mean)
        return _knn_self(g, k), ei

    return _lru_get(_GARMENT_CACHE, key, make)


def clear_caches() -> None:
    """Forget every cached body frame, garment topology, KD-tree and nearest-vertex answer."""
    from garsim.geometry import proximity

    _BODY_CACHE.clear()
    _GARMENT_CACHE.clear()
    proximity._TREE_CACHE.clear()
    proximity._QUERY_CACHE.clear()


class GarmentGraph(Data):
    """A garment graph; knows how to offset its index attributes when batched."""

    def __inc__(self, key: str, value, *args, **kwargs):
        if key in ("edge_index", "faces"):
            return self.num_nodes
        if key == "face_pairs":
            return int(self.faces.shape[0])
        if key == "q_slot":
            return int(self.body_rel.shape[0])
        if key == "col_batch":
            return 1
        return 0

    def __cat_dim__(self, key: str, value, *args, **kwargs):
        if key == "edge_index":
            return -1
        return 0


def build_graph(
    sample: Sample,
    config: GarSimConfig | None = None,
    *,
    with_collision: bool = False,
    loss_inputs: bool = True,
    name: str | None = None,
) -> GarmentGraph:
    """One Sample -> a GarmentGraph with every Eq. 2 input (and the target, if the sample has one).

    ``with_collision`` adds the target-body vertices near the garment and their normals
    (``col_body``, ``col_normal``, ``col_batch``) for the collision loss; ``loss_inputs=False``
    (inference) skips the face pairs only the losses need. The body geometry neighbourhoods
    ``body_rel`` are stored once per distinct q (``q_slot`` maps each vertex to its row), and
    edges are sorted by receiver.
    """
    cfg = config or GarSimConfig()
    body_c = np.asarray(sample.body_canonical, dtype=np.float32)
    body_t = np.asarray(sample.body_target, dtype=np.float32)
    g = np.asarray(sample.garment, dtype=np.float32)
    prior = np.asarray(sample.prior, dtype=np.float32)
    faces = np.asarray(sample.garment_faces, dtype=np.int64)
    n = len(g)
    if n == 0 or faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"garment needs vertices and (F, 3) triangle faces, got {g.shape} and {faces.shape}")
    if faces.min() < 0 or faces.max() >= n:
        raise ValueError(f"garment faces index vertices 0..{faces.max()} but the garment has {n} vertices")
    if not (np.isfinite(g).all() and np.isfinite(prior).all() and np.isfinite(body_t).all()):
        raise ValueError(f"sample {name or ''} has non-finite positions (garment, prior or bodies): fix the data")

    # nearest canonical body vertex q_i (KD-tree of the body, cached per body)
    body = body_frame(body_c, sample.body_faces, cfg.canonicalize_yaw)
    q = cached_nearest(g, body.vertices, k=1)[1][:, 0]
    r32 = body.rot

    # every vector in the body frame: rotate the points once, then subtract
    gf = g @ r32.T
    pf = prior @ r32.T
    bq = body.framed[q]
    bq_t = body_t[q]
    bq_tf = bq_t @ r32.T
    p = gf - bq
    p_prior = pf - bq_tf
    delta = bq_tf - bq
    # body neighbourhoods (X^body at q): each distinct q and its mesh 1-ring, relative to B_q
    uq, q_slot = np.unique(q, return_inverse=True)
    nbr = body.ring(cfg.knn_body)[uq]
    body_rel = body.framed[nbr] - body.framed[uq][:, None, :]
    gidx, ei = garment_topology(g, faces, cfg.knn_garment)
    gar_rel = gf[gidx] - gf[:, None, :]

    snd, rcv = ei[0], ei[1]
    edge_attr = np.concatenate([gf[rcv] - gf[snd], pf[rcv] - pf[snd]], axis=1)

    fab = np.zeros((n, len(FABRICS)), dtype=np.float32)
    fab[:, sample.fabric_index] = 1.0
    sem = semantic_vector(body.framed, uq, cfg, bounds=body.bounds)

    data = GarmentGraph(
        num_nodes=n,
        pos=torch.from_numpy(g.copy()),
        prior=torch.from_numpy(prior.copy()),
        anchor=torch.from_numpy(bq_t),
        p=torch.from_numpy(p),
        p_prior=torch.from_numpy(p_prior),
        delta=torch.from_numpy(delta),
        fabric=torch.from_numpy(fab),
        pinned=torch.from_numpy(np.asarray(sample.pinned, dtype=bool).copy()),
        gar_rel=torch.from_numpy(gar_rel),
        body_rel=torch.from_numpy(body_rel),
        q_slot=torch.from_numpy(q_slot.reshape(n).astype(np.int64)),
        edge_index=torch.from_numpy(ei.copy()),  # the cached array stays private
        edge_attr=torch.from_numpy(edge_attr),
        faces=torch.from_numpy(faces.copy()),
        sem=torch.from_numpy(sem)[None],
        rot=torch.from_numpy(r32.copy())[None],
        q=torch.from_numpy(q),
        name=name if name is not None else str(sample.meta.get("name", "")),
    )
    if loss_inputs:
        data.face_pairs = torch.from_numpy(face_pairs(faces))
    if sample.target is not None:
        if not np.isfinite(sample.target).all():
            raise ValueError(f"sample {data.name!r} has a non-finite target (ground truth): fix or drop it")
        data.target = torch.from_numpy(np.asarray(sample.target, dtype=np.float32).copy())
    if with_collision:
        data.update(collision_body(sample))
    return data


def _vertex_normals_at(vertices: np.ndarray, faces: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """``vertex_normals(vertices, faces)[sel]`` from only the faces touching ``sel`` (same values)."""
    touched = np.zeros(len(vertices), dtype=bool)
    touched[sel] = True
    sub = faces[touched[faces].any(axis=1)]  # every face incident to a selected vertex, in order
    fn = face_normals(vertices, sub, normalize=False)
    idx = sub.T.ravel()  # the summation order of vertex_normals (corner 0 of all faces, then 1, 2)
    vn = np.stack([np.bincount(idx, weights=np.tile(fn[:, c], 3), minlength=len(vertices)) for c in range(3)], axis=1)[sel]
    return (vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-20)).astype(vertices.dtype)


def collision_body(sample: Sample, k: int = 16) -> dict[str, torch.Tensor]:
    """Target-body vertices near the garment (k nearest of each prior/target vertex) and their unit normals."""
    body_t = np.asarray(sample.body_target, dtype=np.float32)
    pts = sample.prior if sample.target is None else np.concatenate([sample.prior, sample.target])
    _, idx = cKDTree(body_t).query(pts, k=min(k, len(body_t)), workers=-1)
    sel = np.unique(np.asarray(idx).ravel())
    normals = _vertex_normals_at(body_t, np.asarray(sample.body_faces, dtype=np.int64), sel)
    return {
        "col_body": torch.from_numpy(body_t[sel].copy()),
        "col_normal": torch.from_numpy(np.ascontiguousarray(normals, dtype=np.float32)),
        "col_batch": torch.zeros(len(sel), dtype=torch.long),
    }


def collate(graphs: Sequence[GarmentGraph]) -> Batch:
    """Batch garment graphs of any sizes/topologies (indices offset per graph)."""
    return Batch.from_data_list(list(graphs))


def build_batch(
    samples: Iterable[Sample], config: GarSimConfig | None = None, *, with_collision: bool = False
) -> Batch:
    """Several Samples -> one batched graph."""
    return collate([build_graph(s, config, with_collision=with_collision) for s in samples])
