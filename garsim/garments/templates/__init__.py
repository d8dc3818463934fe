"""Parametric garment templates fitted to a canonical (T-pose) body: skirt, top, t-shirt, trousers, dress.

The package: ``landmarks`` (the measured template body), ``parameters`` (the schema of each family),
``primitives`` (rings, grids, straps, sleeves), ``builders`` (one per family) and, here, the finishing
(winding, clearance) and the entry points ``make_garment`` / ``make_garment_from_arrays``.

Every template is built from rings of vertices around the body: at each height (or, for sleeves,
each position along the arm) the body's cross-section is measured as a polar profile (the largest
radius of the relevant body part's vertices per angle) and the ring is placed at that radius plus
a looseness margin (plus a flare for skirts). Rings are joined as quad grids (two triangles per
quad), so the resolution knob (``target_vertices``) sets one edge length ``h`` for the whole
garment. Junctions stay edge-manifold by sharing vertices: straps and shoulder panels are grids
whose first and last rows are vertices of the torso's top ring, sleeves start on the armhole loop
(side arc of the torso ring + outer edge of the shoulder panel), and trouser legs split from the
waist tube at a crotch seam shared by both legs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from garsim.garments.garment import Garment
from garsim.garments.templates.builders import _BUILDERS
from garsim.garments.templates.landmarks import (
    MAX_TARGET_VERTICES,
    MIN_TARGET_VERTICES,
    PART_ARM_L,
    PART_ARM_R,
    PART_HEAD,
    PART_LEG_L,
    PART_LEG_R,
    PART_TORSO,
    TemplateBody,
    body_parts,
)
from garsim.garments.templates.parameters import (
    OOD_REACH,
    PARAMS,
    DressParams,
    SkirtParams,
    TopParams,
    TrousersParams,
    TShirtParams,
    garment_params,
    sample_garment_params,
)
from garsim.geometry.mesh import vertex_normals
from garsim.geometry.proximity import nearest_vertices


# ---------------------------------------------------------------------------------------------
# Finishing: orientation, clearance, public entry points
# ---------------------------------------------------------------------------------------------
def _consistent_winding(faces: np.ndarray) -> np.ndarray:
    """Flip faces so that every interior edge is traversed in opposite directions by its two faces."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order, connected_components, shortest_path

    f = np.asarray(faces, dtype=np.int64)
    nf = len(f)
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    fid = np.tile(np.arange(nf), 3)
    forward = d[:, 0] < d[:, 1]
    key = np.minimum(d[:, 0], d[:, 1]) * (f.max() + 1) + np.maximum(d[:, 0], d[:, 1])
    order = np.argsort(key, kind="stable")
    key, fid, forward = key[order], fid[order], forward[order]
    pair = np.flatnonzero(key[1:] == key[:-1])
    a, b = fid[pair], fid[pair + 1]
    same = forward[pair] == forward[pair + 1]  # same direction: one of the two faces must flip
    w = np.where(same, 2, 1)
    g = sp.coo_matrix(
        (np.concatenate([w, w]), (np.concatenate([a, b]), np.concatenate([b, a]))), shape=(nf, nf)
    ).tocsr()
    ncomp, labels = connected_components(g, directed=False)
    flip = np.zeros(nf, dtype=bool)
    for c in range(ncomp):
        root = int(np.flatnonzero(labels == c)[0])
        bfs, pred = breadth_first_order(g, root, directed=False, return_predecessors=True)
        dist = shortest_path(g, directed=False, unweighted=True, indices=root)
        depth = np.where(np.isfinite(dist), dist, 0).astype(np.int64)
        rel = np.asarray(g[bfs[1:], pred[bfs[1:]]]).ravel() == 2
        relative = np.zeros(nf, dtype=bool)
        relative[bfs[1:]] = rel
        nodes = bfs[1:]
        for level in range(1, int(depth[nodes].max(initial=0)) + 1):
            at = nodes[depth[nodes] == level]
            flip[at] = flip[pred[at]] ^ relative[at]
    out = f.copy()
    out[flip] = out[flip][:, ::-1]
    return out


def _orient_outward(vertices: np.ndarray, faces: np.ndarray, body: TemplateBody) -> np.ndarray:
    """Consistently wind ``faces`` and flip them so normals point away from the body."""
    f = _consistent_winding(faces)
    vn = vertex_normals(vertices, f)
    idx, _ = nearest_vertices(vertices, body.vertices)
    away = vertices - body.vertices[idx]
    if np.einsum("ij,ij->i", vn, away).mean() < 0:
        f = f[:, ::-1].copy()
    return f


def _push_out(vertices: np.ndarray, body: TemplateBody, clearance: float, inside_fn: Any) -> tuple[np.ndarray, int]:
    """Move vertices closer than ``clearance`` to the body (nearest-vertex normal offset) or inside it outward."""
    v = vertices.copy()
    moved = np.zeros(len(v), dtype=bool)
    for _ in range(4):
        idx, _ = nearest_vertices(v, body.vertices)
        n = body.normals[idx]
        off = np.einsum("ij,ij->i", v - body.vertices[idx], n)
        bad = off < 0.5 * clearance
        if inside_fn is not None:
            bad |= inside_fn(v)
        if not bad.any():
            break
        moved |= bad
        v[bad] += (clearance - off[bad])[:, None] * n[bad]
    return v, int(moved.sum())


def _inside_fn(body: TemplateBody) -> Any:
    try:
        from garsim.geometry.inside import InsideTester
    except ImportError:  # pragma: no cover - the inside module is part of the package
        return None
    tester = InsideTester(body.vertices.astype(np.float32), body.faces)
    return tester.inside


def _as_template_body(body: Any) -> TemplateBody:
    if isinstance(body, TemplateBody):
        return body
    if hasattr(body, "canonical") and hasattr(body, "skin_indices"):
        return TemplateBody.from_anny(body)
    raise TypeError(f"body must be a TemplateBody or an AnnyBody, got {type(body).__name__}")


def make_garment(kind: str, body: Any, params: dict[str, float] | None = None, target_vertices: int = 2500) -> Garment:
    """Build a ``kind`` template fitted to ``body`` (AnnyBody or TemplateBody) with ~``target_vertices`` vertices."""
    p = garment_params(kind, params)
    if not isinstance(target_vertices, (int, np.integer)) or not (
        MIN_TARGET_VERTICES <= target_vertices <= MAX_TARGET_VERTICES
    ):
        raise ValueError(
            f"target_vertices={target_vertices!r} must be an integer in [{MIN_TARGET_VERTICES}, {MAX_TARGET_VERTICES}]"
        )
    tb = _as_template_body(body)
    builder = _BUILDERS[kind]
    h = 0.03
    mesh, pinned = builder(tb, p, h)
    for _ in range(3):
        ratio = mesh.n / target_vertices
        if abs(ratio - 1.0) < 0.08:
            break
        h = h * math.sqrt(ratio)
        mesh, pinned = builder(tb, p, h)
    vertices, faces = mesh.arrays()
    inside = _inside_fn(tb)
    clearance = min(0.006, 0.5 * getattr(p, "looseness", 0.01))
    vertices, moved = _push_out(vertices, tb, clearance, inside)
    faces = _orient_outward(vertices, faces, tb)
    info = p.as_dict()
    info["edge_length"] = float(h)
    info["pushed_out"] = moved
    return Garment(vertices.astype(np.float32), faces, pinned, kind, info)


def make_garment_from_arrays(
    kind: str,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    skin_indices: np.ndarray,
    skin_weights: np.ndarray | None,
    bone_labels: list[str],
    params: dict[str, float] | None = None,
    target_vertices: int = 2500,
) -> Garment:
    """:func:`make_garment` for any canonical body given as arrays plus its skinning bones."""
    tb = TemplateBody.from_skinning(body_vertices, body_faces, skin_indices, skin_weights, bone_labels)
    return make_garment(kind, tb, params, target_vertices)


__all__ = [
    "MAX_TARGET_VERTICES",
    "MIN_TARGET_VERTICES",
    "OOD_REACH",
    "PARAMS",
    "PART_ARM_L",
    "PART_ARM_R",
    "PART_HEAD",
    "PART_LEG_L",
    "PART_LEG_R",
    "PART_TORSO",
    "DressParams",
    "SkirtParams",
    "TShirtParams",
    "TemplateBody",
    "TopParams",
    "TrousersParams",
    "body_parts",
    "garment_params",
    "make_garment",
    "make_garment_from_arrays",
    "sample_garment_params",
]
