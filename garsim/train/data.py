"""Training data from a dataset store: train / validation samples without leakage."""

from __future__ import annotations

import os

from garsim.data.sample import Sample
from garsim.data.store import RESOLUTIONS, DatasetStore

TRAIN_RESOLUTIONS: tuple[str, ...] = (*RESOLUTIONS, "both")


def train_val_samples(
    data_dir: str | os.PathLike, resolution: str = "low", val_every: int = 10
) -> tuple[list[Sample], list[Sample]]:
    """The store's ``train`` split, with every ``val_every``-th sequence held out for validation.

    Validation holds whole sequences (garment instance, body and pose unseen in training), so no
    frame of a validation sequence is trained on. ``resolution="both"`` takes every frame at the
    low and at the full resolution (one model for any mesh density).
    """
    if resolution not in TRAIN_RESOLUTIONS:
        raise ValueError(f"resolution must be one of {TRAIN_RESOLUTIONS}, got {resolution!r}")
    levels = RESOLUTIONS if resolution == "both" else (resolution,)
    store = DatasetStore(data_dir)
    entries = [e for e in store.entries() if e["split"] == "train"]
    if not entries:
        raise ValueError(f"{data_dir}: no training sequences; run `garsim data generate --out {data_dir}` first")
    if val_every < 2:
        raise ValueError(f"val_every must be >= 2, got {val_every}")
    entries.sort(key=lambda e: e["id"])
    train: list[Sample] = []
    val: list[Sample] = []
    for i, entry in enumerate(entries):
        rec = store.read_sequence(entry)
        samples = [s for level in levels for s in rec.samples(level)]
        (val if i % val_every == val_every - 1 else train).extend(samples)
    return train, val
