"""Paired-fabric groups in training: which samples share one template, body and pose (and differ only in the
fabric), and batches that keep each group together so that ``losses.fabric_pair_loss`` can compare them.

A group is the stored (not remeshed, not rest) samples of one paired job at one frame and one mesh level: the
same template, prior and body, four fabrics. Inside a batch of such a group the simulated differences between
fabrics are the only signal of what the fabric changes; the pair loss asks the network for the same differences.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from garsim.data.sample import Sample

MIRROR_SUFFIX = "~mirror"
"""Appended to a mirrored sample's key: its group is the mirror images of one group, never mixed with it."""


def pair_key(sample: Sample) -> str | None:
    """The paired-fabric group of a stored training sample, or None (unpaired, rest or remeshed samples)."""
    meta = sample.meta
    if not meta.get("paired") or meta.get("rest") or "remesh" in meta or "job" not in meta:
        return None
    key = f"{meta['job']}@{meta.get('frame', 0)}#{len(sample.garment)}"
    return key + MIRROR_SUFFIX if meta.get("mirror") else key


def pair_keys(samples: Sequence[Sample]) -> list[str | None]:
    """``pair_key`` of every sample; an augmented sequence that knows its keys without building its variants
    (``augment.RemeshAugmented``, ``augment.MirrorAugmented``) answers through its own ``pair_keys``."""
    own = getattr(samples, "pair_keys", None)
    return own() if callable(own) else [pair_key(s) for s in samples]


def pair_ids(samples: Sequence[Sample]) -> np.ndarray:
    """(len(samples),) int64 group id of each sample (-1: in no group of two or more)."""
    keys = pair_keys(samples)
    sizes = Counter(k for k in keys if k is not None)
    groups = {k: g for g, k in enumerate(sorted(k for k, n in sizes.items() if n > 1))}
    return np.array([groups.get(k, -1) for k in keys], dtype=np.int64)


def plan_batches(ids: np.ndarray, batch_size: int, rng: np.random.Generator) -> list[list[int]]:
    """Every index once, in batches of at most ``batch_size``: each group (ids >= 0) in one batch (groups larger
    than a batch in consecutive chunks of it), topped up with ungrouped indices; the rest in full batches; batch
    order shuffled. The number of batches depends only on the group sizes, not on ``rng``."""
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    ids = np.asarray(ids)
    singles = list(rng.permutation(np.flatnonzero(ids < 0)))
    grouped = np.flatnonzero(ids >= 0)
    groups = [grouped[ids[grouped] == g] for g in np.unique(ids[grouped])]
    batches: list[list[int]] = []
    for g in rng.permutation(len(groups)):
        members = [int(i) for i in groups[g]]
        for start in range(0, len(members), batch_size):
            batch = members[start : start + batch_size]
            fill = min(batch_size - len(batch), len(singles))
            batch += [int(i) for i in singles[:fill]]
            del singles[:fill]
            batches.append(batch)
    batches += [[int(i) for i in singles[s : s + batch_size]] for s in range(0, len(singles), batch_size)]
    return [batches[i] for i in rng.permutation(len(batches))]


def shard_indices(ids: np.ndarray, world: int, seed: int = 0) -> list[np.ndarray]:
    """A fixed partition of ``range(len(ids))`` into ``world`` shards of near-equal size, each group (ids >= 0)
    whole in one shard: the samples one DDP process trains on every epoch, so each process builds and caches
    the graphs of its own shard only (a reshuffled split would have every process build every graph)."""
    if world < 1:
        raise ValueError(f"world must be >= 1, got {world}")
    ids = np.asarray(ids)
    order = np.random.default_rng(seed).permutation(len(ids))
    # units in a seeded order: each group once (at its first member), each ungrouped index alone
    unit = np.where(ids[order] >= 0, ids[order], -1 - order)
    _, first, inverse, sizes = np.unique(unit, return_index=True, return_inverse=True, return_counts=True)
    rank_of_unit = np.argsort(np.argsort(first))  # units ranked by where they first appear
    size_in_order = sizes[np.argsort(first)]
    middle = np.cumsum(size_in_order) - size_in_order / 2  # where each unit's middle falls in the order
    shard_of_unit = np.minimum((middle * world / max(len(ids), 1)).astype(np.int64), world - 1)
    shard = np.empty(len(ids), dtype=np.int64)
    shard[order] = shard_of_unit[rank_of_unit[inverse]]
    return [np.flatnonzero(shard == r) for r in range(world)]
