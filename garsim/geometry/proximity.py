"""Nearest-body-vertex queries (KD-tree) and the DeePSD-style signed side test."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def nearest_vertices(points: np.ndarray, vertices: np.ndarray, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Indices and distances of the ``k`` nearest ``vertices`` to each point ((N,) or (N, k))."""
    tree = cKDTree(np.asarray(vertices, dtype=np.float64))
    dist, idx = tree.query(np.asarray(points, dtype=np.float64), k=k, workers=-1)
    return idx.astype(np.int64), dist


def signed_offset_to_nearest(points: np.ndarray, body_vertices: np.ndarray, body_normals: np.ndarray) -> np.ndarray:
    """(x - b_q) . n_q for each point's nearest body vertex q: negative means inside the body."""
    idx, _ = nearest_vertices(points, body_vertices)
    return np.einsum("ij,ij->i", np.asarray(points) - body_vertices[idx], body_normals[idx])
