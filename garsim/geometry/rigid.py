"""Rigid alignments of point sets about the vertical axis."""

from __future__ import annotations

import numpy as np


def yaw_alignment(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), t (3,)), float64: the rotation about Z and the translation that best take ``source`` onto
    ``target`` (corresponding points, least squares), so ``target ≈ source @ R.T + t``.

    With centred points a, b the angle is atan2(Σ a_x b_y - a_y b_x, Σ a_x b_x + a_y b_y) and t = mean(b) - R mean(a):
    a continuous function of both sets, exactly the identity for equal sets, and turning or moving ``target`` by a
    rotation about Z and a translation turns and moves the alignment with it."""
    a = np.asarray(source, dtype=np.float64)
    b = np.asarray(target, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3 or len(a) < 2:
        raise ValueError(f"yaw_alignment takes two (N >= 2, 3) sets of corresponding points, got {a.shape}, {b.shape}")
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    pa, pb = a - ca, b - cb
    angle = np.arctan2(
        np.sum(pa[:, 0] * pb[:, 1] - pa[:, 1] * pb[:, 0]), np.sum(pa[:, 0] * pb[:, 0] + pa[:, 1] * pb[:, 1])
    )
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot, cb - rot @ ca
