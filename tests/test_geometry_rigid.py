import numpy as np
import pytest

from garsim.geometry.rigid import yaw_alignment


def _turn(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def test_a_turn_about_the_vertical_and_a_move_are_recovered():
    pts = np.random.default_rng(0).normal(size=(50, 3))
    for degrees in (0.0, 37.0, 90.0, 180.0, -120.0):
        shift = np.array([2.0, -1.0, 0.3])
        rot, t = yaw_alignment(pts, pts @ _turn(degrees).T + shift)
        np.testing.assert_allclose(rot, _turn(degrees), atol=1e-12)
        np.testing.assert_allclose(t, shift, atol=1e-12)


def test_equal_sets_give_exactly_the_identity():
    pts = np.random.default_rng(1).normal(size=(20, 3)).astype(np.float32)
    rot, t = yaw_alignment(pts, pts)
    assert np.array_equal(rot, np.eye(3)) and np.array_equal(t, np.zeros(3))


def test_by_hand_two_points_turned_a_quarter_and_the_best_fit_of_a_tilt():
    a = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    rot, t = yaw_alignment(a, np.array([[0.0, 1.0, 5.0], [0.0, -1.0, 5.0]]))
    np.testing.assert_allclose(rot, _turn(90.0), atol=1e-12)
    np.testing.assert_allclose(t, [0.0, 0.0, 5.0], atol=1e-12)
    # a turn about another axis has no vertical part: the best turn about z is none, the centroids still match
    tilted = a @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]).T + [0.0, 0.0, 1.0]
    rot, t = yaw_alignment(np.vstack([a, [[0.0, 1.0, 0.0]]]), np.vstack([tilted, [[0.0, 1.0, 1.0]]]))
    np.testing.assert_allclose(rot, np.eye(3), atol=1e-12)


def test_bad_point_sets_are_refused():
    with pytest.raises(ValueError, match="corresponding points"):
        yaw_alignment(np.zeros((3, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="corresponding points"):
        yaw_alignment(np.zeros((1, 3)), np.zeros((1, 3)))
