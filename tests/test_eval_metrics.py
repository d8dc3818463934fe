import numpy as np
import trimesh

from garsim.eval.metrics import collision_pct, euclidean_error_mm, garment_metrics, normal_consistency, smoothness

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
SQUARE_FACES = np.array([[0, 1, 2], [0, 2, 3]])


def test_euclidean_error_in_mm():
    a = np.zeros((4, 3))
    b = a.copy()
    b[:, 2] = [0.001, 0.002, 0.003, 0.006]
    assert np.isclose(euclidean_error_mm(a, b), 3.0)


def test_normal_consistency_hand_computed():
    assert np.isclose(normal_consistency(SQUARE, SQUARE_FACES), 0.0)
    folded = SQUARE.copy()
    folded[3] = [0, 0, 1]  # second face now vertical: normals at 90 degrees -> 1 - cos = 1
    assert np.isclose(normal_consistency(folded, SQUARE_FACES), 1.0)


def test_smoothness_zero_on_plane_interior_and_positive_on_bump():
    grid = trimesh.creation.box().subdivide().subdivide()
    flat = np.asarray(grid.vertices)
    base = smoothness(flat, grid.faces)
    bumped = flat.copy()
    bumped[0] *= 1.5
    assert smoothness(bumped, grid.faces) > base


def test_collision_pct_counts_points_inside_a_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    pts = np.concatenate([sphere.vertices[:10] * 0.9, sphere.vertices[10:40] * 1.1])
    assert np.isclose(collision_pct(pts, sphere.vertices, sphere.faces), 25.0)


def test_garment_metrics_perfect_prediction():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    g = np.asarray(sphere.vertices) * 1.2
    m = garment_metrics(g, g, sphere.faces, sphere.vertices, sphere.faces)
    assert m.euclidean_mm == 0.0 and m.collision_pct == 0.0
    assert 0.0 < m.normal_consistency < 0.1
