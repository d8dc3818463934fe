"""Training data from a dataset store: train / validation samples without leakage."""

from __future__ import annotations

import dataclasses
import os

from garsim.data.sample import Sample
from garsim.data.store import RESOLUTIONS, DatasetStore, SequenceRecord

TRAIN_RESOLUTIONS: tuple[str, ...] = (*RESOLUTIONS, "both")


def rest_sample(sample: Sample) -> Sample:
    """The sample's template on its own canonical body: target = canonical body, ground truth = template.

    Free supervision (no simulation): a settled template must stay where it is when the body does not
    move, which the prior gets exactly and a network must learn."""
    return dataclasses.replace(
        sample,
        body_target=sample.body_canonical,
        prior=sample.garment,
        target=sample.garment,
        meta={**sample.meta, "name": f"{sample.meta.get('seq_id', '')}@rest", "rest": True},
    )


def record_samples(rec: SequenceRecord, levels: tuple[str, ...], rest: bool) -> list[Sample]:
    """A record's samples at ``levels``, plus (``rest``) one rest sample per level for settled templates."""
    out = []
    for level in levels:
        samples = rec.samples(level)
        out.extend(samples)
        if rest and samples and rec.meta.get("settle", {}).get("settled"):
            out.append(rest_sample(samples[0]))
    return out


def train_val_samples(
    data_dir: str | os.PathLike, resolution: str = "low", val_every: int = 10, rest: bool = True
) -> tuple[list[Sample], list[Sample]]:
    """The store's ``train`` split, with every ``val_every``-th garment instance held out for validation.

    Validation holds whole jobs (garment instance, body and poses unseen in training; all fabric copies of
    a paired group together), so nothing of a validation instance is trained on.
    ``resolution="both"`` takes every frame at the
    low and at the full resolution (one model for any mesh density). ``rest`` adds one rest sample per
    settled training record (``rest_sample``).
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
    jobs = sorted({e.get("job", e["id"]) for e in entries})
    held = {job for i, job in enumerate(jobs) if i % val_every == val_every - 1}
    train: list[Sample] = []
    val: list[Sample] = []
    for entry in sorted(entries, key=lambda e: e["id"]):
        rec = store.read_sequence(entry)
        if entry.get("job", entry["id"]) in held:
            val.extend(s for level in levels for s in rec.samples(level))
        else:
            train.extend(record_samples(rec, levels, rest))
    return train, val
