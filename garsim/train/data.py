"""Training data from a dataset store: train / validation samples without leakage."""

from __future__ import annotations

import dataclasses
import os
import random
from collections.abc import Sequence

from garsim.data.sample import GARMENT_TYPES, Sample
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
    data_dir: str | os.PathLike,
    resolution: str = "low",
    val_every: int = 10,
    rest: bool = True,
    families: Sequence[str] | None = None,
    fraction: float = 1.0,
    seed: int = 0,
) -> tuple[list[Sample], list[Sample]]:
    """The store's ``train`` split, with every ``val_every``-th garment instance held out for validation.

    Validation holds whole jobs (garment instance, body and poses unseen in training; all fabric copies of
    a paired group together), so nothing of a validation instance is trained on.
    ``resolution="both"`` takes every frame at the low and at the full resolution (one model for any mesh
    density). ``rest`` adds one rest sample per settled training record (``rest_sample``). ``families`` (garment
    types) keeps only those families, in training and in validation. ``fraction`` trains on that share of the
    remaining training jobs (whole jobs, at least one, picked by ``seed``; a smaller share's jobs are a subset of a
    larger one's), validation unchanged.
    """
    if resolution not in TRAIN_RESOLUTIONS:
        raise ValueError(f"resolution must be one of {TRAIN_RESOLUTIONS}, got {resolution!r}")
    unknown = sorted(set(families or ()) - set(GARMENT_TYPES))
    if unknown:
        raise ValueError(f"unknown garment families {unknown}; choose from {GARMENT_TYPES}")
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction must be in (0, 1], got {fraction}")
    levels = RESOLUTIONS if resolution == "both" else (resolution,)
    store = DatasetStore(data_dir)
    entries = [e for e in store.entries() if e["split"] == "train"]
    if not entries:
        raise ValueError(f"{data_dir}: no training sequences; run `garsim data generate --out {data_dir}` first")
    if families is not None:
        entries = [e for e in entries if e["garment_type"] in families]
        if not entries:
            raise ValueError(f"{data_dir}: no training sequences of the families {sorted(families)}")
    if val_every < 2:
        raise ValueError(f"val_every must be >= 2, got {val_every}")
    jobs = sorted({e.get("job", e["id"]) for e in entries})
    held = {job for i, job in enumerate(jobs) if i % val_every == val_every - 1}
    kept = [job for job in jobs if job not in held]
    random.Random(seed).shuffle(kept)
    kept = set(kept[: max(1, round(fraction * len(kept)))])
    train: list[Sample] = []
    val: list[Sample] = []
    for entry in sorted(entries, key=lambda e: e["id"]):
        job = entry.get("job", entry["id"])
        if job in held:
            val.extend(s for level in levels for s in store.read_sequence(entry).samples(level))
        elif job in kept:
            train.extend(record_samples(store.read_sequence(entry), levels, rest))
    return train, val
