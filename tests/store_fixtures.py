"""Synthetic dataset records for the store, training-data and generator tests."""

from __future__ import annotations

import numpy as np

from garsim.data.store import GarmentLevel, SequenceRecord


def make_record(seq_id: str, split: str = "train", k: int = 3, seed: int = 0) -> SequenceRecord:
    rng = np.random.default_rng(seed)
    vb, n = 20, 12
    faces = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6]])
    levels = {
        res: GarmentLevel(
            template=rng.normal(size=(m, 3)).astype(np.float32),
            faces=np.array([[0, 1, 2], [2, 1, 3]]),
            pinned=np.arange(m) < 2,
            priors=rng.normal(size=(k, m, 3)).astype(np.float32),
            targets=rng.normal(size=(k, m, 3)).astype(np.float32),
        )
        for res, m in (("full", n), ("low", n // 3))
    }
    return SequenceRecord(
        seq_id=seq_id,
        split=split,
        garment_type="skirt",
        fabric="denim",
        body_canonical=rng.normal(size=(vb, 3)).astype(np.float32),
        body_targets=rng.normal(size=(k, vb, 3)).astype(np.float32),
        body_faces=faces,
        frames=np.arange(k) * 5,
        levels=levels,
        meta={"garment_params": {"length": 0.5}, "phenotype": {"gender": 0.3}},
    )
