"""Training augmentations: random garment remeshing (issue 9, "random garment remeshing and resolution") and
left-right mirroring.

The simulator samples every garment on one mesh per instance and the store keeps two resolutions of it (``full``
and the ~4x decimated ``low``), so a network trained on them sees only two mesh densities per garment. A remeshed
variant decimates the full-resolution garment to a random vertex count between the low level's and
``max_fraction`` x the full one's (``garsim.garments.remesh.decimate``: borders kept, every coarse vertex on the
full surface) and carries the ground truth and the prior through the same barycentric map, the pins from the
nearest original vertex: the same simulated surfaces, sampled by another mesh. The body is unchanged.

A variant is a pure function of (seed, the sample's name, the variant number): it does not depend on the order of
the training list, and the same run rebuilds the same variants. ``RemeshAugmented`` builds one whenever it is
indexed and keeps none: ``GraphDataset`` caches each sample's graph (the one copy a run holds), so a variant is built
once per run. Validation is never augmented (only training samples
are wrapped, by ``garsim train --remesh-copies N``).

Mirroring (``garsim train --mirror``): every training sample (remeshed variants included) also enters mirrored
left to right (``mirror_sample``). The network is equivariant to turns about the vertical by construction, but not
to reflections, and the simulator is symmetric under them: a mirrored sample is exact new ground truth (the
left and right of the pose swapped), at no simulation cost.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Sequence
from typing import overload

import numpy as np

from garsim.data.sample import Sample
from garsim.garments.garment import Garment
from garsim.garments.remesh import BarycentricMap, decimate, transfer_barycentric
from garsim.geometry.cache import ContentCache, content_key
from garsim.model.inputs import body_yaw_frame
from garsim.train.pairs import MIRROR_SUFFIX, pair_keys

MAX_FRACTION = 0.7
"""Largest variant as a share of the full resolution's vertices (near 1 a variant is the full mesh again)."""
LOW_FRACTION = 0.25
"""Smallest variant's share of the full vertices when no low level is known (the store's ~4x decimation)."""


def variant_rng(seed: int, name: str, variant: int) -> np.random.Generator:
    """The generator of one variant: a stable function of (seed, sample name, variant), not of list order."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, zlib.crc32(name.encode("utf-8")), int(variant)])


def remesh_sample(sample: Sample, ratio: float) -> tuple[Sample, BarycentricMap]:
    """``sample`` (a full-resolution one) with its garment decimated to ~``ratio`` of its faces: template, prior and
    target carried through the decimation's barycentric map, pins from the nearest original vertex."""
    if sample.target is None:
        raise ValueError(f"sample {sample.meta.get('name', '')!r} has no target: a training variant needs ground truth")
    garment = Garment(sample.garment, sample.garment_faces, sample.pinned, sample.garment_type, {})
    low, mapping = decimate(garment, ratio=ratio)
    prior = transfer_barycentric(sample.prior.astype(np.float64), mapping).astype(np.float32)
    target = transfer_barycentric(sample.target.astype(np.float64), mapping).astype(np.float32)
    return (
        dataclasses.replace(
            sample,
            garment=low.vertices,
            garment_faces=low.faces,
            pinned=low.pinned,
            prior=prior,
            target=target,
            meta=dict(sample.meta),
        ),
        mapping,
    )


def remesh_variant(
    sample: Sample,
    variant: int,
    seed: int = 0,
    min_vertices: int | None = None,
    max_fraction: float = MAX_FRACTION,
) -> Sample:
    """Variant ``variant`` of a full-resolution training sample: a vertex count drawn uniformly between
    ``min_vertices`` (the low level's count; default ``LOW_FRACTION`` x full) and ``max_fraction`` x full, the
    garment decimated to it (``remesh_sample``). Deterministic in (seed, sample name, variant)."""
    name = str(sample.meta.get("name", ""))
    n = len(sample.garment)
    lo = int(min_vertices) if min_vertices else round(LOW_FRACTION * n)
    hi = max(lo, round(max_fraction * n))
    count = int(variant_rng(seed, name, variant).integers(lo, hi + 1))
    ratio = min(1.0, count / n)  # decimate counts faces; a closed-ish mesh has ~2x faces as vertices either way
    out, _ = remesh_sample(sample, ratio)
    out.meta.update(
        name=f"{name}~remesh{variant}",
        remesh={"variant": int(variant), "ratio": ratio, "source_vertices": n, "vertices": len(out.garment)},
    )
    return out


class _LazySamples(Sequence[Sample]):
    """A sequence of samples built when indexed (``_item``), with list-like indexing and bounds."""

    def _item(self, i: int) -> Sample:
        raise NotImplementedError

    @overload
    def __getitem__(self, i: int) -> Sample: ...
    @overload
    def __getitem__(self, i: slice) -> list[Sample]: ...
    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(f"index {i} out of range for {len(self)} samples")
        return self._item(i)


class RemeshAugmented(_LazySamples):
    """The training samples followed by ``copies`` remeshed variants of each source, built when indexed (not kept:
    ``GraphDataset`` caches their graphs).

    ``sources`` are the full-resolution samples to remesh (any sequence; one variant set per source) and
    ``min_vertices`` their low level's vertex counts (None: ``LOW_FRACTION`` x full). Index ``i < len(originals)``
    is ``originals[i]``; the rest are variant ``v`` of source ``s`` at ``len(originals) + s * copies + v``."""

    def __init__(
        self,
        originals: Sequence[Sample],
        sources: Sequence[Sample],
        copies: int,
        seed: int = 0,
        min_vertices: Sequence[int | None] | None = None,
        max_fraction: float = MAX_FRACTION,
    ) -> None:
        if copies < 0:
            raise ValueError(f"remesh copies must be >= 0, got {copies}")
        if min_vertices is not None and len(min_vertices) != len(sources):
            raise ValueError(f"{len(min_vertices)} vertex counts for {len(sources)} sources")
        self.originals = originals
        self.sources = sources
        self.copies = int(copies)
        self.seed = int(seed)
        self.min_vertices = list(min_vertices) if min_vertices is not None else [None] * len(sources)
        self.max_fraction = max_fraction

    def __len__(self) -> int:
        return len(self.originals) + len(self.sources) * self.copies

    def _item(self, i: int) -> Sample:
        if i < len(self.originals):
            return self.originals[i]
        s, v = divmod(i - len(self.originals), self.copies)
        return remesh_variant(self.sources[s], v, self.seed, self.min_vertices[s], self.max_fraction)

    def pair_keys(self) -> list[str | None]:
        """The originals' paired-fabric keys; a remeshed variant is in no group (``train.pairs``)."""
        return pair_keys(self.originals) + [None] * (len(self) - len(self.originals))


def remesh_augmented(
    originals: Sequence[Sample], full: Sequence[Sample], copies: int, seed: int = 0, max_fraction: float = MAX_FRACTION
) -> Sequence[Sample]:
    """``originals`` (training samples at any resolution) plus ``copies`` remeshed variants of every sample of
    ``full`` (the same training samples at full resolution), paired by name: a variant's smallest size is the
    vertex count of the original of the same name when it is coarser (the low level), else ``LOW_FRACTION`` x full.
    ``copies == 0`` returns ``originals`` unchanged."""
    if copies == 0:
        return originals
    coarse: dict[str, int] = {}
    for s in originals:
        name = str(s.meta.get("name", ""))
        coarse[name] = min(coarse.get(name, len(s.garment)), len(s.garment))
    mins = []
    for s in full:
        m = coarse.get(str(s.meta.get("name", "")))
        mins.append(m if m is not None and m < len(s.garment) else None)
    return RemeshAugmented(originals, list(full), copies, seed, mins, max_fraction)


def mirror_sample(sample: Sample) -> Sample:
    """``sample`` reflected left-to-right: every position (bodies, template, prior, truth) mirrored in the vertical
    plane through the canonical body's centroid across its lateral axis (``model.inputs.body_yaw_frame``'s X), and
    every face's winding reversed so that normals stay outward. Cloth physics (gravity, stretch, bending, contact)
    is symmetric under this reflection, so the mirrored ground truth is the simulator's answer for the mirrored
    scene: an exact second sample, with the left and right of every pose swapped."""
    centre = np.asarray(sample.body_canonical, dtype=np.float64).mean(axis=0)
    lateral = body_yaw_frame(sample.body_canonical)[0]  # unit X axis of the body frame, horizontal

    def reflect(points: np.ndarray | None) -> np.ndarray | None:
        if points is None:
            return None
        p = np.asarray(points, dtype=np.float64)
        return (p - 2.0 * ((p - centre) @ lateral)[:, None] * lateral).astype(points.dtype)

    name = str(sample.meta.get("name", ""))
    return dataclasses.replace(
        sample,
        body_canonical=reflect(sample.body_canonical),
        body_target=reflect(sample.body_target),
        body_faces=_reversed_faces(sample.body_faces),
        garment=reflect(sample.garment),
        garment_faces=np.ascontiguousarray(sample.garment_faces[:, ::-1]),
        prior=reflect(sample.prior),
        target=reflect(sample.target),
        meta={**sample.meta, "name": f"{name}~mirror", "mirror": True},
    )


_REVERSED = ContentCache(4, scope="body")
"""Reversed body faces, one copy per topology (keyed by content: the store loads a new faces array per sample)."""


def _reversed_faces(faces: np.ndarray) -> np.ndarray:
    """``faces`` with reversed winding, shared by every sample of one body topology."""
    return _REVERSED.get(content_key(faces), lambda: np.ascontiguousarray(faces[:, ::-1]))


class MirrorAugmented(_LazySamples):
    """``samples`` followed by the mirror image of each (``mirror_sample``), built when indexed."""

    def __init__(self, samples: Sequence[Sample]) -> None:
        self.samples = samples

    def __len__(self) -> int:
        return 2 * len(self.samples)

    def _item(self, i: int) -> Sample:
        n = len(self.samples)
        return self.samples[i] if i < n else mirror_sample(self.samples[i - n])

    def pair_keys(self) -> list[str | None]:
        """The samples' paired-fabric keys, then their mirror images' (``pair_key`` of ``mirror_sample``)."""
        keys = pair_keys(self.samples)
        return keys + [None if k is None else k + MIRROR_SUFFIX for k in keys]
