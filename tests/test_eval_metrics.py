import numpy as np
import pytest
import trimesh

from garsim.eval.metrics import (
    collision_pct,
    correction_alignment,
    edge_crossing_pct,
    edge_length_error_mm,
    euclidean_error_mm,
    garment_metrics,
    hood_collision_pct,
    inside_pct,
    jitter_mm,
    normal_consistency,
    smoothness,
)

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


def test_smoothness_by_hand_on_the_square_and_without_a_vertex_no_face_uses():
    """Unit square, diagonal 0-2: vertices 1 and 3 sit (1/2, 1/2) from their two neighbours' mean, 0 and 2 (2/3, 2/3)
    from their three's: mean sqrt(2) (1/2 + 2/3) / 2; an extra vertex that no face uses changes nothing (it used to
    count as its distance from the origin)."""
    expected = np.sqrt(2.0) * (1 / 2 + 2 / 3) / 2
    assert smoothness(SQUARE, SQUARE_FACES) == pytest.approx(expected)
    assert smoothness(np.vstack([SQUARE, [[3.0, 4.0, 0.0]]]), SQUARE_FACES) == pytest.approx(expected)


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


# A closed unit cube (corners at ±0.5) as the body: flat faces, so closest points and face normals are exact.
CUBE = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
CUBE_V, CUBE_F = np.asarray(CUBE.vertices), np.asarray(CUBE.faces)
# above the top face (outside), below it (inside), far above, above the bottom face from inside
PROBES = np.array([[0.0, 0.0, 0.6], [0.0, 0.0, 0.4], [0.0, 0.0, 5.0], [0.0, 0.0, -0.4]])


def test_hood_collision_uses_the_closest_face_where_deepsd_uses_the_nearest_corner():
    """0.1 above the top face's centre: the closest point is (0, 0, 0.5) on a +Z face, (x - c)·n = 0.1 > 0, so
    HOOD counts it outside; the nearest body vertex is a top corner (±0.5, ±0.5, 0.5), whose normal points out
    diagonally: (x - b)·n ∝ -0.5 k_x - 0.5 k_y + 0.1 k_z < 0 (k: its incident triangles per side, 1 or 2), a
    DeePSD collision. The other probes agree: 2 of 4 inside for HOOD (50%), 3 of 4 for DeePSD (75%)."""
    assert hood_collision_pct(PROBES, CUBE_V, CUBE_F) == 50.0
    assert collision_pct(PROBES, CUBE_V, CUBE_F) == 75.0
    assert inside_pct(PROBES, CUBE_V, CUBE_F) == 50.0  # the winding number: (0, 0, 0.4) and (0, 0, -0.4)


def test_edge_crossings_count_segments_that_meet_the_body():
    """Edges (0, 1) through the cube with both ends outside, (0, 3) and (1, 3) into it from outside: 3 of 5."""
    v = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 3.0], [0.0, 0.0, 0.4]])
    faces = np.array([[0, 1, 2], [0, 3, 1]])  # edges (0,1) (0,2) (1,2) (0,3) (1,3); (1,2) passes above the cube
    assert np.isclose(edge_crossing_pct(v, faces, CUBE_V, CUBE_F), 60.0)
    assert inside_pct(v, CUBE_V, CUBE_F) == 25.0  # only vertex 3: the vertex count misses edge (0, 1)


def test_edge_length_error_of_a_uniform_stretch():
    """Every edge 0.2% longer: mean |Δ| = 0.002 x mean length = 2 mm x (4 sides + √2 diagonal) / 5."""
    assert np.isclose(edge_length_error_mm(SQUARE * 1.002, SQUARE, SQUARE_FACES), 2.0 * (4 + np.sqrt(2)) / 5)
    assert edge_length_error_mm(SQUARE + 5.0, SQUARE, SQUARE_FACES) < 1e-9  # a rigid motion keeps every length


def test_jitter_is_the_mean_second_difference():
    """Vertex 0 accelerates (x = a t², second difference 2a = 2 mm), vertex 1 moves at constant speed (0)."""
    t = np.arange(4, dtype=float)
    frames = np.zeros((4, 2, 3))
    frames[:, 0, 0] = 0.001 * t**2
    frames[:, 1, 1] = 0.01 * t
    assert np.isclose(jitter_mm(frames), 1.0)
    with pytest.raises(ValueError, match="T >= 3"):
        jitter_mm(frames[:2])


def test_correction_alignment_hand_computed():
    """Needed corrections +x (1 m) at both vertices; predicted +x 0.5 m at one, +y 0.5 m at the other: cosine
    (0.5 + 0) / (sqrt(0.5) * sqrt(2)) = 0.5, gain 0.5 / 1; the truth itself 1 and 1; no correction 0 and 0."""
    prior = np.zeros((2, 3))
    truth = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    pred = np.array([[0.5, 0, 0], [0, 0.5, 0]])
    assert np.allclose(correction_alignment(pred, prior, truth), (0.5, 0.5))
    assert np.allclose(correction_alignment(truth, prior, truth), (1.0, 1.0))
    assert correction_alignment(prior, prior, truth) == (0.0, 0.0)
    assert np.allclose(correction_alignment(-truth, prior, truth), (-1.0, 1.0))


def test_garment_metrics_reports_every_metric():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    g = np.asarray(sphere.vertices) * 1.2
    m = garment_metrics(g * 0.5, g, sphere.faces, sphere.vertices, sphere.faces).as_dict()
    assert set(m) == {
        "euclidean_mm",
        "normal_consistency",
        "smoothness",
        "collision_pct",
        "hood_collision_pct",
        "inside_pct",
        "edge_crossing_pct",
        "edge_length_error_mm",
    }
    assert m["inside_pct"] == m["hood_collision_pct"] == m["collision_pct"] == 100.0  # shrunk to 0.6: all inside
    assert m["edge_crossing_pct"] == 0.0  # inside, but no edge meets the surface
    assert np.isclose(m["euclidean_mm"], 600.0) and m["edge_length_error_mm"] > 0


def test_constraint_figures_hand_computed():
    """Three triangles (a 10 cm square and a sliver) beside a unit box: vertex 3 moved 15 cm into the box stretches
    edge 2-3 to 2.5x and 0-3 to 1.8x; the pinned-pinned edge 0-1 and the 2 mm seam edge 3-4 are left out."""
    from garsim.eval.metrics import constraint_figures

    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    bv, bf = np.asarray(box.vertices), np.asarray(box.faces)
    tpl = np.array([[0.6, 0.0, 0.0], [0.7, 0.0, 0.0], [0.7, 0.1, 0.0], [0.6, 0.1, 0.0], [0.6, 0.102, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [3, 2, 4]])
    pinned = np.array([True, True, False, False, False])
    x = tpl.copy()
    x[3] = [0.45, 0.1, 0.0]  # inside the box (|x| < 0.5)
    ratios: list = []
    fig = constraint_figures(x[None], tpl, faces, pinned, bv[None], bf, ratios_out=ratios)
    # counted edges 0-2, 0-3, 1-2, 2-3, 2-4: ratios 1, 0.18 / 0.1, 1, 0.25 / 0.1, 1
    np.testing.assert_allclose(np.sort(ratios[0]), [1.0, 1.0, 1.0, np.hypot(0.15, 0.1) / 0.1, 2.5], atol=1e-9)
    assert fig["max_stretch"] == pytest.approx(2.5) and fig["edges_over_1.5_pct"] == pytest.approx(40.0)
    assert fig["inside_pct"] == pytest.approx(20.0) and fig["inside_free_pct"] == pytest.approx(100.0 / 3)
    # edges meeting the box: the three at vertex 3 (0-3, 2-3, 3-4) of seven; of the free ones (2-3, 2-4, 3-4): two
    assert fig["edges_through_pct"] == pytest.approx(300.0 / 7)
    assert fig["edges_through_free_pct"] == pytest.approx(200.0 / 3)
