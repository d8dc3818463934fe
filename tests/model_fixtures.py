"""Synthetic Samples for the model/training tests: an Anny body, a skirt-like ring grid, its LBS prior,
and a smooth, fabric-dependent "ground truth" (gravity-like sag + inward pull) on top of the prior."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from garsim.bodies.anny import AnnyBody
from garsim.data.sample import FABRICS, Sample
from garsim.geometry.skinning import dense_weights, lbs_prior, transfer_weights

POSES: tuple[dict[str, list[float]], ...] = (
    {},
    {"upperleg01.L": [-0.5, 0.0, 0.0], "upperleg01.R": [0.3, 0.0, 0.0]},
    {"upperleg01.L": [0.4, 0.0, 0.0], "upperleg01.R": [-0.4, 0.0, 0.0]},
    {"upperleg01.L": [0.0, 0.3, 0.0], "upperleg01.R": [0.0, -0.3, 0.0]},
    {"upperleg01.L": [-0.8, 0.0, 0.0]},
    {"upperleg01.R": [-0.7, 0.0, 0.2]},
)
SAG = {"silk": 0.03, "cotton": 0.022, "denim": 0.014, "leather": 0.006}
PULL = {"silk": 0.02, "cotton": 0.015, "denim": 0.01, "leather": 0.004}


@lru_cache(maxsize=1)
def anny_body() -> AnnyBody:
    """One default Anny body per test process."""
    return AnnyBody()


@lru_cache(maxsize=1)
def _body_weights() -> np.ndarray:
    body = anny_body()
    return dense_weights(body.skin_indices, body.skin_weights, len(body.bone_labels))


@lru_cache(maxsize=16)
def _posed(pose_id: int):
    body = anny_body()
    return body.pose({**body.t_pose(), **POSES[pose_id]})


def ring_garment(
    body_vertices: np.ndarray, n_around: int, n_down: int, length: float = 0.45, flare: float = 0.08, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A skirt-like elliptic cone grid around the hips: (vertices, faces, pinned top ring)."""
    b = np.asarray(body_vertices)
    z0 = 0.0
    band = b[np.abs(b[:, 2] - z0) < 0.03]
    lo, hi = band.min(axis=0), band.max(axis=0)
    cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
    rx, ry = 0.5 * (hi[0] - lo[0]) + 0.015, 0.5 * (hi[1] - lo[1]) + 0.015
    ang = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    t = np.linspace(0.0, 1.0, n_down)
    a, tt = np.meshgrid(ang, t)  # rows = heights
    v = np.stack(
        [cx + (rx + flare * tt) * np.cos(a), cy + (ry + flare * tt) * np.sin(a), z0 - length * tt], axis=-1
    ).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    v = v + rng.normal(scale=0.0015, size=v.shape)  # break exact symmetries (kNN ties)
    i = np.arange(n_down - 1)[:, None] * n_around
    j = np.arange(n_around)[None, :]
    v00 = (i + j).ravel()
    v01 = (i + (j + 1) % n_around).ravel()
    v10 = v00 + n_around
    v11 = v01 + n_around
    faces = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    pinned = np.zeros(len(v), dtype=bool)
    pinned[:n_around] = True
    return v.astype(np.float32), faces.astype(np.int64), pinned


def make_sample(
    n_around: int = 24,
    n_down: int = 8,
    fabric: str = "cotton",
    pose_id: int = 1,
    seed: int = 0,
    name: str | None = None,
) -> Sample:
    """A synthetic Sample with an exact LBS prior and a smooth fabric-dependent ground truth."""
    body = anny_body()
    can, tgt = _posed(0), _posed(pose_id)
    g, faces, pinned = ring_garment(can.vertices, n_around, n_down, seed=seed)
    w = transfer_weights(g, can.vertices, _body_weights())
    prior = lbs_prior(g, w, can.transforms, tgt.transforms)
    depth = np.clip((0.0 - g[:, 2]) / 0.45, 0.0, 1.0)[:, None]
    centre = prior[pinned].mean(axis=0)
    radial = prior - centre
    radial[:, 2] = 0.0
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-9)
    down = np.array([0.0, 0.0, -1.0], dtype=np.float32)
    target = prior + SAG[fabric] * depth**2 * down - PULL[fabric] * depth * radial
    return Sample(
        body_canonical=can.vertices.astype(np.float32),
        body_target=tgt.vertices.astype(np.float32),
        body_faces=body.faces,
        garment=g,
        garment_faces=faces,
        pinned=pinned,
        prior=prior.astype(np.float32),
        fabric=fabric,
        garment_type="skirt",
        target=target.astype(np.float32),
        meta={"name": name or f"ring{n_around}x{n_down}_{fabric}_pose{pose_id}_s{seed}"},
    )


def make_samples(count: int, seed: int = 0) -> list[Sample]:
    """``count`` varied samples (resolutions, fabrics, poses)."""
    out = []
    for k in range(count):
        out.append(
            make_sample(
                n_around=16 + 4 * (k % 3),
                n_down=6 + (k % 2),
                fabric=FABRICS[k % len(FABRICS)],
                pose_id=1 + (k % (len(POSES) - 1)),
                seed=seed + k,
            )
        )
    return out


def transform_sample(sample: Sample, rot: np.ndarray | None = None, shift: np.ndarray | None = None) -> Sample:
    """Apply x -> R x + t to every position of a Sample (the whole scene moves rigidly)."""
    r = np.eye(3) if rot is None else np.asarray(rot, dtype=np.float64)
    t = np.zeros(3) if shift is None else np.asarray(shift, dtype=np.float64)

    def f(x):
        return None if x is None else (np.asarray(x, dtype=np.float64) @ r.T + t).astype(np.float32)

    return Sample(
        body_canonical=f(sample.body_canonical),
        body_target=f(sample.body_target),
        body_faces=sample.body_faces,
        garment=f(sample.garment),
        garment_faces=sample.garment_faces,
        pinned=sample.pinned,
        prior=f(sample.prior),
        fabric=sample.fabric,
        garment_type=sample.garment_type,
        target=f(sample.target),
        meta=dict(sample.meta),
    )


def rot_z(angle: float) -> np.ndarray:
    """Rotation matrix about Z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
