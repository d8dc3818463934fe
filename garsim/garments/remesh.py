"""Garment decimation (fast-simplification, borders kept) and barycentric transfer between resolutions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from garsim.garments.garment import Garment
from garsim.geometry.mesh import boundary_edges


@dataclass
class BarycentricMap:
    """Each low-res vertex as a barycentric combination of one full-res triangle's vertices."""

    triangles: np.ndarray  # (M, 3) int64 full-res vertex indices
    weights: np.ndarray  # (M, 3) float64 barycentric weights (sum to 1)


def _closest_point_barycentric(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest full-res triangle of each point and the barycentric coordinates of the closest point on it."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False, validate=False)
    closest, _, tri_id = trimesh.proximity.closest_point(mesh, points)
    tri = vertices[faces[tri_id]]
    bary = trimesh.triangles.points_to_barycentric(tri, closest)
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    return faces[tri_id].astype(np.int64), bary


def decimate(garment: Garment, ratio: float = 0.25) -> tuple[Garment, BarycentricMap]:
    """Decimate to ~``ratio`` of the faces keeping border vertices; returns the garment and a full->low map."""
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
    # drop vertices the simplifier left unreferenced
    used = np.unique(f_low)
    remap = np.full(len(v_low), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    v_low, f_low = v_low[used], remap[f_low]
    tris, bary = _closest_point_barycentric(v_low, v, garment.faces)
    # pinned mask: carried over from the nearest original vertex of the closest triangle
    nearest = tris[np.arange(len(tris)), np.argmax(bary, axis=1)]
    pinned = garment.pinned[nearest]
    params = dict(garment.params)
    params["decimation_ratio"] = float(ratio)
    low = Garment(v_low.astype(np.float32), f_low.astype(np.int64), pinned, garment.kind, params)
    return low, BarycentricMap(tris, bary)


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


def border_vertex_count(faces: np.ndarray) -> int:
    """Number of distinct vertices on the mesh border."""
    return int(len(np.unique(boundary_edges(faces))))
