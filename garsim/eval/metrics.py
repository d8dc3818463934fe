"""Evaluation metrics (the paper's Sec. 4.3 and the issue's additions), in NumPy, per garment or sequence.

With x the predicted garment (N, 3), x̄ the ground truth, E its unique mesh edges (i, j), and the target body:

- Euclidean error (mm): 1000 · mean_i ‖x_i − x̄_i‖.
- Normal consistency (Eq. 5): mean over adjacent face pairs (f, g) of 1 − n_f · n_g.
- Smoothness (Eq. 4): mean_i ‖x_i − mean_{j ∈ N(i)} x_j‖ (the uniform Laplacian, metres) over the vertices the
  faces use.
- Collision (%), DeePSD's count: 100 · share of i with (x_i − b_q) · n_q < 0, q the nearest body VERTEX and n_q
  its area-weighted vertex normal.
- HOOD collision (%): 100 · share of i with (x_i − c_i) · n_f < 0, c_i the closest point of the body surface
  (point-to-triangle) and n_f the unit normal of the FACE it lies on.
- Inside (%): 100 · share of i inside the body by the generalised winding number (> 0.5), the exact test.
- Edge crossings (%): 100 · share of edges (i, j) whose segment x_i x_j meets the body surface (a hit of the
  ray from x_i towards x_j within its length): an edge with one end inside, or a limb cutting the cloth
  between two outside vertices, which no vertex metric sees. Same definition as ``../shared/external-eval``.
- Edge-length error (mm): 1000 · mean_(i,j) | ‖x_i − x_j‖ − ‖x̄_i − x̄_j‖ |.
- Constraint figures (``constraint_figures``, the refinement's acceptance bounds): over the edges whose template rest
  length is at least ``min_rest`` (5 mm: seam edges are left out) and that have a free end, the max, 99th percentile
  and mean of the stretch ratio ‖x_i − x_j‖ / rest and the share over 1.5x; inside (%) and edge crossings (%), of
  all vertices / edges and of the free ones (pinned vertices follow the skinning prior, inside the body or not).
- Correction alignment (``correction_alignment``), with x^p the LBS prior: the cosine between the predicted and the
  needed correction over the whole garment, (x − x^p) · (x̄ − x^p) / (‖x − x^p‖ ‖x̄ − x^p‖) over the stacked (3N,)
  vectors (0 when either is zero), and the gain mean_i ‖x_i − x^p_i‖ / mean_i ‖x̄_i − x^p_i‖: whether a model corrects
  the prior in the right direction, and by how much (the ground truth: 1 and 1; the prior: 0 and 0).
- Jitter (mm/frame²), for a sequence of T ≥ 3 consecutive frames: 1000 · mean_{t, i} ‖x_i[t+1] − 2 x_i[t] + x_i[t−1]‖
  (the mean vertex acceleration), to be read beside the ground truth's own.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from garsim.geometry.inside import InsideTester, closest_on_mesh, collision_fraction, inside_mask, segment_hits
from garsim.geometry.mesh import (
    edge_lengths,
    face_normals,
    face_pairs,
    uniform_laplacian,
    unique_edges,
    vertex_normals,
)


@dataclass
class GarmentMetrics:
    euclidean_mm: float
    normal_consistency: float
    smoothness: float
    collision_pct: float
    hood_collision_pct: float
    inside_pct: float
    edge_crossing_pct: float
    edge_length_error_mm: float

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
    """Eq. 4 over the vertices the faces use (a vertex of no face has no neighbours' mean to compare with)."""
    used = np.zeros(len(vertices), dtype=bool)
    used[np.asarray(faces).ravel()] = True
    lap = uniform_laplacian(faces, len(vertices)) @ np.asarray(vertices, np.float64)
    return float(np.linalg.norm(lap[used], axis=1).mean())


def collision_pct(vertices: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray) -> float:
    """DeePSD's collision %: nearest body vertex and its normal."""
    normals = vertex_normals(np.asarray(body_vertices, np.float64), body_faces)
    return 100.0 * collision_fraction(vertices, body_vertices, normals)


def hood_collision_pct(vertices: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray) -> float:
    """HOOD's collision %: closest point on the body surface and the normal of its face."""
    x = np.asarray(vertices, np.float64)
    closest, face = closest_on_mesh(x, body_vertices, body_faces)
    n = face_normals(np.asarray(body_vertices, np.float64), np.asarray(body_faces)[face])
    return 100.0 * float(np.mean(np.einsum("ij,ij->i", x - closest, n) < 0.0))


def inside_pct(vertices: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray) -> float:
    """Share of vertices inside the body by the winding number (%)."""
    return 100.0 * float(np.mean(inside_mask(vertices, body_vertices, body_faces)))


def edge_crossing_pct(
    vertices: np.ndarray, faces: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray
) -> float:
    """Share of garment edges whose segment meets the body surface (%)."""
    e = unique_edges(faces)
    x = np.asarray(vertices)
    return 100.0 * float(np.mean(segment_hits(x[e[:, 0]], x[e[:, 1]], body_vertices, body_faces)))


def edge_length_error_mm(pred: np.ndarray, truth: np.ndarray, faces: np.ndarray) -> float:
    """Mean absolute difference of edge lengths, predicted vs true (mm)."""
    return float(np.abs(edge_lengths(pred, faces) - edge_lengths(truth, faces)).mean() * 1000.0)


MIN_REST = 0.005
"""m: edges shorter than this in the template (seams) are left out of the stretch figures."""


def constraint_figures(
    frames: np.ndarray,
    template: np.ndarray,
    faces: np.ndarray,
    pinned: np.ndarray,
    bodies: np.ndarray,
    body_faces: np.ndarray,
    min_rest: float = MIN_REST,
    ratios_out: list | None = None,
) -> dict[str, float]:
    """Stretch, inside and edge-crossing figures of (T, N, 3) drapes of one garment on their (T, Vb, 3) bodies,
    pooled over the frames (see the module doc). ``ratios_out``: a list that receives the counted edges' stretch
    ratios (to pool them over several garments)."""
    e = unique_edges(faces)
    rest = edge_lengths(template, faces)
    counted = (rest >= min_rest) & ~(pinned[e[:, 0]] & pinned[e[:, 1]])
    free_edges = ~(pinned[e[:, 0]] | pinned[e[:, 1]])
    ratios, inside, through = [], [], []
    tester = InsideTester(bodies[0], body_faces)
    for x, body in zip(np.asarray(frames, np.float64), bodies):
        tester.update(body)
        ratios.append(np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)[counted] / rest[counted])
        inside.append(tester.inside(x))
        through.append(tester.segment_hits(x[e[:, 0]], x[e[:, 1]]))
    r, inside, through = np.concatenate(ratios), np.stack(inside), np.stack(through)
    if ratios_out is not None:
        ratios_out.append(r)
    return {
        "max_stretch": float(r.max()) if len(r) else 1.0,
        "p99_stretch": float(np.percentile(r, 99)) if len(r) else 1.0,
        "mean_stretch": float(r.mean()) if len(r) else 1.0,
        "edges_over_1.5_pct": 100.0 * float(np.mean(r > 1.5)) if len(r) else 0.0,
        "inside_pct": 100.0 * float(inside.mean()),
        "inside_free_pct": 100.0 * float(inside[:, ~pinned].mean()) if (~pinned).any() else 0.0,
        "edges_through_pct": 100.0 * float(through.mean()),
        "edges_through_free_pct": 100.0 * float(through[:, free_edges].mean()) if free_edges.any() else 0.0,
    }


def correction_alignment(pred: np.ndarray, prior: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(cosine, gain) of the predicted correction over the prior against the needed one (module docstring)."""
    got = np.asarray(pred, np.float64) - prior
    need = np.asarray(truth, np.float64) - prior
    norm = np.linalg.norm(got) * np.linalg.norm(need)
    cosine = float(got.ravel() @ need.ravel() / norm) if norm > 0 else 0.0
    need_mean = np.linalg.norm(need, axis=1).mean()
    gain = float(np.linalg.norm(got, axis=1).mean() / need_mean) if need_mean > 0 else 0.0
    return cosine, gain


def jitter_mm(frames: np.ndarray) -> float:
    """Mean norm of the second difference over consecutive frames (T, N, 3), mm/frame²."""
    x = np.asarray(frames, np.float64)
    if x.ndim != 3 or len(x) < 3:
        raise ValueError(f"jitter needs (T >= 3, N, 3) frames, got shape {x.shape}")
    return float(np.linalg.norm(x[2:] - 2.0 * x[1:-1] + x[:-2], axis=2).mean() * 1000.0)


def garment_metrics(
    pred: np.ndarray, truth: np.ndarray, faces: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray
) -> GarmentMetrics:
    """Every per-garment metric of one predicted garment."""
    return GarmentMetrics(
        euclidean_mm=euclidean_error_mm(pred, truth),
        normal_consistency=normal_consistency(pred, faces),
        smoothness=smoothness(pred, faces),
        collision_pct=collision_pct(pred, body_vertices, body_faces),
        hood_collision_pct=hood_collision_pct(pred, body_vertices, body_faces),
        inside_pct=inside_pct(pred, body_vertices, body_faces),
        edge_crossing_pct=edge_crossing_pct(pred, faces, body_vertices, body_faces),
        edge_length_error_mm=edge_length_error_mm(pred, truth, faces),
    )
