"""Mesh connectivity and differential operators against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from garsim.geometry.mesh import (
    boundary_edges,
    directed_edges,
    face_areas,
    face_normals,
    face_pairs,
    piece_count,
    surface_smoother,
    top_border_loops,
    uniform_laplacian,
    unique_edges,
    vertex_normals,
    weld,
    weld_index,
)

# unit square in the z=0 plane split along the diagonal 0-2
SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])
# right-angled tetrahedron, faces oriented outward
TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_square_edges_pairs_boundary():
    np.testing.assert_array_equal(unique_edges(SQUARE_F), [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]])
    d = directed_edges(SQUARE_F)
    assert d.shape == (2, 10)
    assert {tuple(e) for e in d.T} == {(0, 1), (1, 0), (0, 2), (2, 0), (0, 3), (3, 0), (1, 2), (2, 1), (2, 3), (3, 2)}
    np.testing.assert_array_equal(np.sort(face_pairs(SQUARE_F), axis=1), [[0, 1]])  # the two faces share the diagonal
    np.testing.assert_array_equal(boundary_edges(SQUARE_F), [[0, 1], [0, 3], [1, 2], [2, 3]])


def test_square_normals_and_areas():
    np.testing.assert_allclose(face_normals(SQUARE_V, SQUARE_F), [[0, 0, 1], [0, 0, 1]])
    np.testing.assert_allclose(face_normals(SQUARE_V, SQUARE_F, normalize=False), [[0, 0, 1], [0, 0, 1]])
    np.testing.assert_allclose(face_areas(SQUARE_V, SQUARE_F), [0.5, 0.5])
    np.testing.assert_allclose(vertex_normals(SQUARE_V, SQUARE_F), np.tile([0, 0, 1.0], (4, 1)))


def test_square_laplacian_hand_computed():
    lap = uniform_laplacian(SQUARE_F, 4).toarray()
    expected = np.array(
        [
            [1, -1 / 3, -1 / 3, -1 / 3],  # vertex 0: neighbours 1, 2, 3
            [-1 / 2, 1, -1 / 2, 0],  # vertex 1: neighbours 0, 2
            [-1 / 3, -1 / 3, 1, -1 / 3],
            [-1 / 2, 0, -1 / 2, 1],
        ]
    )
    np.testing.assert_allclose(lap, expected)
    # vertex 0 minus the mean of (1,0,0), (1,1,0), (0,1,0)
    np.testing.assert_allclose((lap @ SQUARE_V)[0], [-2 / 3, -2 / 3, 0])


def test_tetrahedron_closed_mesh():
    assert len(unique_edges(TET_F)) == 6
    assert len(face_pairs(TET_F)) == 6  # every edge is shared by two faces
    assert len(boundary_edges(TET_F)) == 0
    s3 = 1 / np.sqrt(3)
    np.testing.assert_allclose(
        face_normals(TET_V, TET_F), [[0, 0, -1], [0, -1, 0], [-1, 0, 0], [s3, s3, s3]], atol=1e-12
    )
    np.testing.assert_allclose(face_areas(TET_V, TET_F), [0.5, 0.5, 0.5, np.sqrt(3) / 2])
    vn = vertex_normals(TET_V, TET_F)
    np.testing.assert_allclose(vn[0], [-s3, -s3, -s3])  # equal-area faces (0,0,-1), (0,-1,0), (-1,0,0)
    # vertex 1: area-weighted (0,0,-1)/2 + (0,-1,0)/2 + (1,1,1)/2 = (1/2, 0, 0)
    np.testing.assert_allclose(vn[1], [1.0, 0.0, 0.0], atol=1e-12)
    pairs = {tuple(p) for p in np.sort(face_pairs(TET_F), axis=1)}
    assert pairs == {(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)}
    lap = uniform_laplacian(TET_F, 4)
    np.testing.assert_allclose((lap @ TET_V)[0], [-1 / 3, -1 / 3, -1 / 3])
    np.testing.assert_allclose(np.asarray(lap.sum(axis=1)).ravel(), 0.0, atol=1e-12)


def _grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n x n vertex grid on [0, 1]^2, each cell split along the same diagonal."""
    xs, ys = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="xy")
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="xy")
    a = (j * n + i).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return v, f


def test_laplacian_of_a_tilted_plane_vanishes_in_the_interior():
    v, f = _grid(6)
    v[:, 2] = 0.3 * v[:, 0] - 0.7 * v[:, 1] + 0.2  # a tilted plane: linear coordinates
    lap = uniform_laplacian(f, len(v))
    np.testing.assert_allclose(np.asarray(lap.sum(axis=1)).ravel(), 0.0, atol=1e-12)
    interior = np.ones(len(v), dtype=bool)
    interior[np.unique(boundary_edges(f))] = False
    assert interior.sum() == 16
    np.testing.assert_allclose((lap @ v)[interior], 0.0, atol=1e-12)
    assert np.abs((lap @ v)[~interior]).max() > 1e-3  # border vertices are not at their neighbours' mean


def test_vertex_normals_of_a_sphere_point_outward(icosphere):
    v, f = icosphere
    vn = vertex_normals(v, f)
    np.testing.assert_allclose(np.linalg.norm(vn, axis=1), 1.0, atol=1e-5)
    assert np.einsum("ij,ij->i", vn, v / np.linalg.norm(v, axis=1, keepdims=True)).min() > 0.99
    assert len(face_pairs(f)) == len(unique_edges(f)) == 3 * len(f) // 2


@pytest.mark.parametrize("faces", [SQUARE_F, TET_F])
def test_directed_edges_are_symmetric(faces):
    d = directed_edges(faces)
    fwd = {tuple(e) for e in d.T}
    assert fwd == {(b, a) for a, b in fwd}


def test_unique_edges_matches_row_unique_on_random_mesh():
    rng = np.random.default_rng(0)
    faces = rng.integers(0, 500, size=(2000, 3))
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    np.testing.assert_array_equal(unique_edges(faces), np.unique(e, axis=0))


def test_top_border_loops_of_an_open_cylinder_is_its_top_ring_only():
    from mesh_fixtures import loop_rows, open_cylinder

    v, f = open_cylinder(radius=0.3, z0=0.2, z1=1.0, rings=6, sections=16)
    loops = top_border_loops(v, f)
    assert len(loops) == 1
    np.testing.assert_array_equal(np.sort(loops[0]), loop_rows(16, 5))
    # turned upside down, the other ring is the top
    np.testing.assert_array_equal(np.sort(top_border_loops(v * [1, 1, -1], f)[0]), loop_rows(16, 0))


def test_top_border_loops_keeps_every_loop_reaching_the_top_band():
    """Two tubes side by side (a strapped top's neckline and armholes meet near the top): both top rings within
    the band are picked, highest first; the bottom rings and a tube ending 10 cm lower are not."""
    from mesh_fixtures import open_cylinder

    parts = [
        open_cylinder(0.1, 0.0, 1.0, centre=(0.0, 0.0)),
        open_cylinder(0.1, 0.0, 0.98, centre=(0.5, 0.0)),
        open_cylinder(0.1, 0.0, 0.9, centre=(1.0, 0.0)),
    ]
    v = np.concatenate([p[0] for p in parts])
    f = np.concatenate([p[1] + k * len(parts[0][0]) for k, p in enumerate(parts)])
    loops = top_border_loops(v, f)
    assert [float(v[loop, 2].max()) for loop in loops] == pytest.approx([1.0, 0.98])
    assert top_border_loops(v, f, band=0.0)[0].max() < len(parts[0][0])
    assert top_border_loops(TET_V, TET_F) == []  # a closed surface has no border


def test_surface_smoother_keeps_constants_and_spreads_a_spike_by_sigma():
    """On a flat 1 cm grid: constant values are kept, a unit spike keeps its sum and spreads with a standard
    deviation of sigma per axis, and a larger sigma spreads it further."""
    n, h = 61, 0.01
    x, y = np.meshgrid(np.arange(n) * h, np.arange(n) * h, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    centre = idx[n // 2, n // 2]
    r2 = np.sum((v[:, :2] - v[centre, :2]) ** 2, axis=1)
    for sigma in (0.02, 0.04):
        smooth = surface_smoother(v, f, sigma)
        np.testing.assert_allclose(smooth(np.full((n * n, 2), 3.0)), 3.0, atol=1e-9)
        spike = np.zeros((n * n, 1))
        spike[centre] = 1.0
        out = smooth(spike)[:, 0]
        assert out.sum() == pytest.approx(1.0, abs=1e-9)
        assert np.sqrt(np.sum(out * r2) / 2.0) == pytest.approx(sigma, rel=0.02)


def test_a_square_split_along_its_diagonal_is_welded_back():
    """The square's second triangle on copies of the diagonal's vertices (4 = 0, 5 = 2), as a file split at a seam
    stores it (one copy 5e-5 m off): welded, the square again, each group at its copies' mean."""
    v = np.concatenate([SQUARE_V, SQUARE_V[[0, 2]] + [[0.0, 0.0, 0.0], [0.0, 0.0, 5e-5]]])
    index = weld_index(v, np.array([[0, 1, 2], [4, 5, 3]]))
    np.testing.assert_array_equal(index, [0, 1, 2, 3, 0, 2])
    welded, faces = weld(v, np.array([[0, 1, 2], [4, 5, 3]]), index)
    np.testing.assert_allclose(welded, SQUARE_V + [[0, 0, 0], [0, 0, 0], [0, 0, 2.5e-5], [0, 0, 0]])
    np.testing.assert_array_equal(faces, SQUARE_F)


def test_a_seam_across_a_short_edge_welds_each_end_to_its_own_copy():
    """Edge 0-1 is 50 micrometres long and a seam runs along it: the second triangle stores copies 4 (of 0) and 5 (of
    1). Each copy is within the tolerance of both ends, but lies on the other end's copy: 4 -> 0, 5 -> 1, and the
    short edge stays (a chained weld merged all four and dropped both faces)."""
    v = np.array([[0, 0, 0], [5e-5, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 0], [5e-5, 0, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [5, 4, 3]])
    index = weld_index(v, f)
    np.testing.assert_array_equal(index, [0, 1, 2, 3, 0, 1])
    np.testing.assert_array_equal(weld(v, f, index)[1], [[0, 1, 2], [1, 0, 3]])


def test_weld_leaves_short_edges_and_distant_vertices_and_drops_collapsed_and_repeated_faces():
    tiny = np.array([[0, 0, 0], [1e-5, 0, 0], [0, 1, 0]], dtype=np.float64)  # an edge of 10 micrometres
    assert weld_index(tiny, np.array([[0, 1, 2]])) is None
    assert weld_index(SQUARE_V, SQUARE_F) is None
    # vertex 4 a copy of 2: face [1, 2, 4] collapses, face [4, 3, 0] repeats [0, 2, 3]
    v = np.concatenate([SQUARE_V, SQUARE_V[[2]]])
    f = np.array([[0, 1, 2], [0, 2, 3], [1, 2, 4], [4, 3, 0]])
    index = np.array([0, 1, 2, 3, 2])
    _, faces = weld(v, f, index)
    np.testing.assert_array_equal(faces, SQUARE_F)


def test_piece_count_counts_vertex_connected_faces():
    assert piece_count(SQUARE_F, 4) == 1
    assert piece_count(np.array([[0, 1, 2], [3, 4, 5]]), 7) == 2  # vertex 6 in no face: no piece
    assert piece_count(np.array([[0, 1, 2], [2, 3, 4]]), 5) == 1  # touching at a vertex: one piece
