"""The paper's four evaluation metrics (Sec. 4.3), in NumPy, per garment.

- Euclidean error (mm): mean per-vertex distance to the ground truth.
- Normal consistency (Eq. 5): mean over adjacent face pairs of 1 - cos(angle between normals).
- Smoothness (Eq. 4): mean norm of the uniform Laplacian of the vertex positions (metres).
- Collision (%): DeePSD's count: nearest body vertex, its normal, (x - b)·n < 0.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from garsim.geometry.inside import collision_fraction
from garsim.geometry.mesh import face_normals, face_pairs, uniform_laplacian, vertex_normals


@dataclass
class GarmentMetrics:
    euclidean_mm: float
    normal_consistency: float
    smoothness: float
    collision_pct: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def euclidean_error_mm(pred: np.ndarray, truth: np.ndarray) -> float:
    return float(np.linalg.norm(np.asarray(pred, np.float64) - truth, axis=1).mean() * 1000.0)


def normal_consistency(vertices: np.ndarray, faces: np.ndarray) -> float:
    pairs = face_pairs(faces)
    if len(pairs) == 0:
        return 0.0
    n = face_normals(np.asarray(vertices, np.float64), faces)
    return float(np.mean(1.0 - np.einsum("ij,ij->i", n[pairs[:, 0]], n[pairs[:, 1]])))


def smoothness(vertices: np.ndarray, faces: np.ndarray) -> float:
    lap = uniform_laplacian(faces, len(vertices)) @ np.asarray(vertices, np.float64)
    return float(np.linalg.norm(lap, axis=1).mean())


def collision_pct(vertices: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray) -> float:
    normals = vertex_normals(np.asarray(body_vertices, np.float64), body_faces)
    return 100.0 * collision_fraction(vertices, body_vertices, normals)


def garment_metrics(
    pred: np.ndarray, truth: np.ndarray, faces: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray
) -> GarmentMetrics:
    """All four metrics of one predicted garment."""
    return GarmentMetrics(
        euclidean_mm=euclidean_error_mm(pred, truth),
        normal_consistency=normal_consistency(pred, faces),
        smoothness=smoothness(pred, faces),
        collision_pct=collision_pct(pred, body_vertices, body_faces),
    )
