"""Sample -> the garment graph's arrays: every input of the paper's Eq. 2, vectorised, in numpy (no torch here:
the numpy runtime drapes from these arrays; ``garsim.model.graph`` wraps them as a torch_geometric Data).

Continuity (a deviation from the paper, which takes q_i = the nearest body vertex): every feature is
a continuous function of the input geometry. q_i is the garment vertex's *soft anchor*, a blend of
the canonical body vertices near its closest one (``geometry.proximity.soft_anchor``: weights that
vanish where a vertex enters or leaves the blend), so where the nearest body vertex would jump (between
the legs, under the arms) the inputs move smoothly. Per garment vertex i, with the anchor weights w_ij:
B_q = Σ w_ij B_j, B̄_q = Σ w_ij B̄_j, δ_i = B̄_q − B_q, p_i = G_i − B_q, p^prior_i = G^prior_i − B̄_q,
the body geometry "at q_i" = Σ w_ij X^body_j (the geometry encoder's output on each body vertex's mesh
1-ring); the garment geometry uses each vertex's mesh 1-ring (not kNN sets, whose ties flip); the
body-semantic input splats max_i w_ij per body vertex. Fabric: physical values (log bending rigidity,
areal density and stretch, scaled so silk = 0 and leather = 1), not a one-hot. Per directed mesh
edge (i -> j): E_ij = G_j − G_i and E^prior_ij. Faces and face pairs for the losses. With ``target_surface``
(off in the paper and in the shipped model) the prior's soft anchor on the target body: offset, normal, signed
distance. With ``local_rotation`` (off in the paper and in the shipped model) per vertex the rotation that carries the
template's mesh neighbourhood onto the prior's (``local_rot``), which turns the decoded correction.
Everything about the canonical body alone (KD-tree, yaw frame, rings) is computed once per body and cached by content.

Frame: all vectors are expressed in a body frame (rotation ``rot``, world -> frame) whose
yaw comes from the canonical body alone (see ``body_yaw_frame``), so a rotation of the whole
scene about the vertical axis leaves every input unchanged and the model rotates its
output back: the prediction is exactly (to float rounding) equivariant to rotations about
Z and to translations. Full SO(3) equivariance is not wanted: gravity points down.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp

from garsim.bodies.prior import ring_operator, rotations_between
from garsim.data.sample import Sample
from garsim.garments.fabrics import PRESETS as FABRIC_PRESETS
from garsim.garments.fabrics import Fabric, fabric_from_values, get_fabric
from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.io import as_mesh
from garsim.geometry.mesh import cached_vertex_normals, directed_edges, face_pairs, vertex_rings
from garsim.geometry.proximity import about_centroid, cached_tree, soft_anchor, soft_surface
from garsim.model.config import FABRIC_FEATURES, GarSimConfig

_BODIES = ContentCache(8)  # per canonical body: its BodyFrame
_GARMENTS = ContentCache(8, scope="garment")  # per template garment: mesh rings and receiver-sorted edges


class BodyFrame:
    """Everything about one canonical body that does not depend on the garment, computed once.

    KD-tree, yaw frame ``rot`` (world -> body frame, identity without ``canonicalize_yaw``),
    the body's vertices in that frame (float64 and float32), and (lazily) each body vertex's mesh
    neighbourhood, the point set the geometry encoder sees there.
    """

    def __init__(self, body_canonical: np.ndarray, faces: np.ndarray, canonicalize_yaw: bool):
        self.vertices = np.ascontiguousarray(body_canonical, dtype=np.float32)
        if not np.isfinite(self.vertices).all():
            raise ValueError("the canonical body has non-finite vertices: fix the body mesh")
        self.faces = np.asarray(faces, dtype=np.int64)
        self.tree = cached_tree(self.vertices)
        self.rot64 = body_yaw_frame(self.vertices) if canonicalize_yaw else np.eye(3)
        self.rot = self.rot64.astype(np.float32)
        self.framed64 = self.vertices.astype(np.float64) @ self.rot64.T
        self.framed = self.framed64.astype(np.float32)
        self.bounds = (self.framed.min(axis=0), self.framed.max(axis=0))
        self._rings: dict[int, np.ndarray] = {}

    def ring(self, k: int) -> np.ndarray:
        """(Vb, k) each body vertex itself, then its mesh 1-ring (``geometry.mesh.vertex_rings``)."""
        if k not in self._rings:
            self._rings[k] = vertex_rings(self.vertices, self.faces, k)
        return self._rings[k]


def body_frame(body_canonical: np.ndarray, faces: np.ndarray, canonicalize_yaw: bool = True) -> BodyFrame:
    """The cached BodyFrame of a canonical body (keyed by its vertices' content, faces compared), so
    an edited body is never served stale data."""
    arr = np.ascontiguousarray(body_canonical, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    return _BODIES.get(
        content_key(arr, f) + (bool(canonicalize_yaw),), lambda: BodyFrame(arr, f.copy(), canonicalize_yaw)
    )


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
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """The garment-aware body-semantic input: the mask of body vertices in q, (D,) float32.

    ``weights`` (one per entry of ``q``, in [0, 1]) make the mask soft (the largest anchor weight each body
    vertex gets from any garment vertex: continuous in the garment); None is the paper's binary mask.
    ``"vertex"`` mode returns the mask itself (length = body vertex count).
    ``"grid"`` mode (default, any body topology) splats the masked vertices trilinearly onto a
    fixed grid in body-normalised coordinates (x, y centred on the body's bounding box and
    divided by its height, z from the feet up divided by the height; x in [-.5, .5],
    y in [-.25, .25], z in [0, 1]) and saturates each cell with 1 - exp(-count).
    ``bounds`` = the body's (min, max) corners, if already known (``BodyFrame.bounds``).
    """
    uq = np.asarray(q)
    mass = np.ones(len(uq)) if weights is None else np.asarray(weights, dtype=np.float64)
    if config.semantic == "vertex":
        nb = int(config.num_body_vertices)  # type: ignore[arg-type]
        if len(body_canonical_frame) != nb:
            raise ValueError(
                f"the model's body-semantic MLP expects {nb} body vertices but the body has "
                f"{len(body_canonical_frame)}; use semantic='grid' for other body topologies"
            )
        mask = np.zeros(nb, dtype=np.float32)
        mask[uq] = mass
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
    grid = np.bincount(flat.ravel(), weights=(w * mass[:, None]).ravel(), minlength=int(np.prod(dims)))
    return (1.0 - np.exp(-grid)).astype(np.float32)


def garment_topology(garment: np.ndarray, faces: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, k) garment mesh rings (self first) and (2, 2E) receiver-sorted directed edges of a template garment.

    Both depend only on the canonical garment, so they are cached by content: draping one garment
    on a sequence of target poses computes them once.
    """
    g = np.ascontiguousarray(garment, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    key = content_key(g, f) + (int(k),)

    def make() -> tuple[np.ndarray, np.ndarray]:
        ei = directed_edges(f)
        ei = np.ascontiguousarray(ei[:, np.argsort(ei[1], kind="stable")])  # receiver-sorted (CSR mean)
        return vertex_rings(g, f, k), ei

    return _GARMENTS.get(key, make)


_FABRIC_SCALE = {
    key: (np.log(getattr(FABRIC_PRESETS["silk"], key)), np.log(getattr(FABRIC_PRESETS["leather"], key)))
    for key in ("bending", "density", "stretch")
}


def sample_fabric(sample: Sample) -> Fabric:
    """The sample's fabric in physical units: its stored values, else the named preset."""
    if sample.fabric_values:
        return fabric_from_values(sample.fabric_values, sample.fabric)
    return get_fabric(sample.fabric)


assert len(_FABRIC_SCALE) == FABRIC_FEATURES


def fabric_features(sample: Sample) -> np.ndarray:
    """(FABRIC_FEATURES,) float32: the fabric's physical values on the silk (0) .. leather (1) log scales."""
    fab = sample_fabric(sample)
    return np.array(
        [(np.log(getattr(fab, k)) - lo) / (hi - lo) for k, (lo, hi) in _FABRIC_SCALE.items()], dtype=np.float32
    )


class StaticGraph:
    """The pose-free part of one garment's graph on one canonical body (computed once per garment, body and input
    configuration, cached by content): the arrays of :func:`graph_arrays` that do not depend on the target body or
    the prior, and what the per-pose part needs. ``token`` is unique per instance: a key for what a model derives
    from these arrays (its pose-free features)."""

    _tokens = itertools.count()

    def __init__(
        self, g: np.ndarray, faces: np.ndarray, body_canonical: np.ndarray, body_faces: np.ndarray, cfg: GarSimConfig
    ) -> None:
        n = len(g)
        body = body_frame(body_canonical, body_faces, cfg.canonicalize_yaw)
        # soft anchor q_i: a continuous blend of the canonical body vertices near G_i, taken about the body's centroid
        # as the prior takes it (``bodies.prior.MeshPairPrior``), so a new garment's anchor is computed once
        w = soft_anchor(*about_centroid(g, body.vertices)[:2]).tocoo()
        used, slot = np.unique(w.col, return_inverse=True)
        self.anchor_w = sp.csr_matrix((w.data, (w.row, slot)), shape=(n, len(used)))
        self.used = used
        self.rot64 = body.rot64
        self.body_faces = body.faces
        self.target_surface = cfg.target_surface
        # local rotation: the template's 2-ring edge sums, once per garment
        self.ring = ring_operator(faces, n, rings=2) if cfg.local_rotation else None
        # every vector in the body frame, in float64 (then float32): rotate the points, then subtract
        gf = g.astype(np.float64) @ self.rot64.T
        self.bq = self.anchor_w @ body.framed64[used]
        # body neighbourhoods (X^body): every anchoring body vertex with its mesh 1-ring, relative to it
        nbr = body.ring(cfg.knn_body)[used]
        gidx, ei = garment_topology(g, faces, cfg.knn_garment)
        snd, rcv = ei[0], ei[1]
        mass = np.zeros(len(used))
        referenced = np.zeros(n, dtype=bool)  # a vertex no face uses (a stray OBJ 'v' line) marks no body part
        referenced[np.asarray(faces).ravel()] = True
        keep = referenced[w.row]
        np.maximum.at(mass, slot[keep], w.data[keep])
        self.edge_garment = (gf[rcv] - gf[snd]).astype(np.float32)
        self.arrays = {
            "pos": g.copy(),
            "p": (gf - self.bq).astype(np.float32),
            "gar_rel": (gf[gidx] - gf[:, None, :]).astype(np.float32),
            "body_rel": (body.framed64[nbr] - body.framed64[used][:, None, :]).astype(np.float32),
            "anchor_index": np.stack([w.row.astype(np.int64), slot.astype(np.int64)]),
            "anchor_weight": w.data.astype(np.float32),
            "edge_index": ei.copy(),
            "faces": faces.copy(),
            "sem": semantic_vector(body.framed, used, cfg, bounds=body.bounds, weights=mass)[None],
            "rot": body.rot.copy()[None],
        }
        for a in self.arrays.values():
            a.flags.writeable = False  # shared by every pose of this garment
        self.token = next(self._tokens)

    def pose(self, prior: np.ndarray, body_target: np.ndarray) -> dict[str, np.ndarray]:
        """The arrays that depend on the target body and the prior (float32)."""
        pf = prior.astype(np.float64) @ self.rot64.T
        bq_t = self.anchor_w @ body_target[self.used].astype(np.float64)
        bq_tf = bq_t @ self.rot64.T
        snd, rcv = self.arrays["edge_index"]
        arrays = {
            "prior": prior,
            "anchor": bq_t.astype(np.float32),
            "p_prior": (pf - bq_tf).astype(np.float32),
            "delta": (bq_tf - self.bq).astype(np.float32),
            "edge_attr": np.concatenate([self.edge_garment, (pf[rcv] - pf[snd]).astype(np.float32)], axis=1),
        }
        if self.target_surface:
            arrays["surface"] = target_surface(prior, body_target, self.body_faces, self.rot64)
        if self.ring is not None:
            arrays["local_rot"] = rotations_between(self.arrays["pos"], prior, *self.ring).astype(np.float32)
        return arrays


def target_surface(points: np.ndarray, body: np.ndarray, faces: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(N, SURFACE_FEATURES) float32: per point, the offset from its soft anchor on ``body``, the body's blended unit
    normal there (``soft_surface``) and the signed distance along it (negative inside), vectors turned by ``rot``
    (world -> body frame). The body's normals are cached by content (the API gives the network the target in its
    root frame, ``api.root_frame``, and its push-out the target as given: each has its own unless they coincide)."""
    p = np.asarray(points, dtype=np.float64)
    anchor, n = soft_surface(p, body, cached_vertex_normals(body, faces))
    offset = p - anchor
    dist = np.einsum("ij,ij->i", offset, n)[:, None]
    return np.concatenate([offset @ rot.T, n @ rot.T, dist], axis=1).astype(np.float32)


_STATIC = ContentCache(8, scope="garment")  # per (garment, canonical body, input configuration): its StaticGraph


def static_graph(sample: Sample, config: GarSimConfig | None = None, name: str | None = None) -> StaticGraph:
    """The cached pose-free part of ``sample``'s graph (the garment validated by the one validator on a miss)."""
    cfg = config or GarSimConfig()
    inputs = (
        cfg.canonicalize_yaw,
        cfg.knn_garment,
        cfg.knn_body,
        cfg.semantic,
        cfg.semantic_grid,
        cfg.num_body_vertices,
        cfg.target_surface,
        cfg.local_rotation,
    )
    key = content_key(sample.garment, sample.garment_faces, sample.body_canonical, sample.body_faces) + inputs

    def make() -> StaticGraph:
        g, faces = as_mesh((sample.garment, sample.garment_faces), f"garment {name or ''}".strip())
        return StaticGraph(g, faces, np.asarray(sample.body_canonical, dtype=np.float32), sample.body_faces, cfg)

    return _STATIC.get(key, make)


def pose_arrays(static: StaticGraph, sample: Sample, name: str | None = None) -> dict[str, np.ndarray]:
    """The per-pose arrays of ``sample``'s graph (prior, target body, fabric, pins), checked to be finite."""
    body_t = np.asarray(sample.body_target, dtype=np.float32)
    prior = np.asarray(sample.prior, dtype=np.float32)
    if not (np.isfinite(prior).all() and np.isfinite(body_t).all()):
        raise ValueError(f"sample {name or ''} has non-finite positions (prior or bodies): fix the data")
    n = len(prior)
    return {
        **static.pose(prior, body_t),
        "fabric": np.repeat(fabric_features(sample)[None], n, axis=0),
        "pinned": np.asarray(sample.pinned, dtype=bool),
    }


def graph_arrays(
    sample: Sample,
    config: GarSimConfig | None = None,
    *,
    loss_inputs: bool = True,
    name: str | None = None,
) -> dict[str, np.ndarray]:
    """One Sample -> every Eq. 2 input of its garment graph as numpy arrays (and the target, if the sample has one).

    ``loss_inputs=False`` (inference) skips the face pairs only the losses need. The body geometry
    neighbourhoods ``body_rel`` are stored once per distinct q (``anchor_index`` maps each vertex to its
    rows, with ``anchor_weight``), and edges are sorted by receiver. Fresh, writable arrays: the caller may keep
    them (the runtime reads :func:`static_graph` and :func:`pose_arrays` without copies).
    """
    static = static_graph(sample, config, name)
    arrays = {k: v.copy() for k, v in static.arrays.items()}
    arrays.update({k: v.copy() for k, v in pose_arrays(static, sample, name).items()})
    if loss_inputs:
        arrays["face_pairs"] = face_pairs(arrays["faces"])
    if sample.target is not None:
        if not np.isfinite(sample.target).all():
            label = name if name is not None else str(sample.meta.get("name", ""))
            raise ValueError(f"sample {label!r} has a non-finite target (ground truth): fix or drop it")
        arrays["target"] = np.asarray(sample.target, dtype=np.float32).copy()
    return arrays
