"""On-disk dataset store: one compressed ``.npz`` per simulated sequence + a JSONL manifest.

Layout of a dataset folder::

    manifest.jsonl        one line per stored sequence: id, file, sha256, bytes, split, type, fabric, ...
    rejected.jsonl        sequences the simulator rejected, with the reason (skipped on resume)
    body_faces/<key>.npy  body faces, stored once per body topology
    sequences/<id>.npz    arrays of one sequence (no pickle; metadata as a JSON string)

A sequence holds one garment instance on one body: the canonical body, the settled template,
and K stored frames (target body, LBS prior, ground truth), at full and at low resolution.
Every write is atomic (temp file + rename); the manifest is appended by one writer.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.data.sample import Sample

MANIFEST = "manifest.jsonl"
SPLITS: tuple[str, ...] = ("train", "test", "ood")
REJECTED = "rejected.jsonl"
RESOLUTIONS = ("full", "low")
ENTRY_KEYS = ("id", "file", "sha256", "bytes", "split", "garment_type", "fabric", "body_faces")
"""Keys every manifest line must hold for its sequence to be read and verified."""


class StoreError(RuntimeError):
    """A dataset folder or file is missing, truncated or corrupt."""


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


@dataclass
class GarmentLevel:
    """One resolution of a sequence's garment: template, faces, pins, and per-frame prior / truth."""

    template: np.ndarray  # (N, 3) settled on the canonical body
    faces: np.ndarray  # (F, 3)
    pinned: np.ndarray  # (N,) bool
    priors: np.ndarray  # (K, N, 3)
    targets: np.ndarray  # (K, N, 3)


@dataclass
class SequenceRecord:
    """A simulated sequence: one garment on one body, K stored frames, full + low resolution."""

    seq_id: str
    split: str
    garment_type: str
    fabric: str
    body_canonical: np.ndarray  # (Vb, 3)
    body_targets: np.ndarray  # (K, Vb, 3)
    body_faces: np.ndarray  # (Fb, 3)
    frames: np.ndarray  # (K,) frame index of each stored frame
    levels: dict[str, GarmentLevel]
    meta: dict[str, Any] = field(default_factory=dict)

    def samples(self, resolution: str = "low") -> list[Sample]:
        """The K model samples of this sequence at one resolution."""
        if resolution not in self.levels:
            raise ValueError(
                f"sequence {self.seq_id} has no {resolution!r} resolution (it holds {sorted(self.levels)})"
            )
        lv = self.levels[resolution]
        modes = self.meta.get("pose_modes") or []  # per stored frame: how its target pose was sampled
        return [
            Sample(
                body_canonical=self.body_canonical,
                body_target=self.body_targets[k],
                body_faces=self.body_faces,
                garment=lv.template,
                garment_faces=lv.faces,
                pinned=lv.pinned,
                prior=lv.priors[k],
                target=lv.targets[k],
                fabric=self.fabric,
                fabric_values=self.meta.get("fabric_values"),
                garment_type=self.garment_type,
                meta={
                    **self.meta,
                    "seq_id": self.seq_id,
                    "frame": int(self.frames[k]),
                    "split": self.split,
                    "name": f"{self.seq_id}@{int(self.frames[k])}",
                    **({"pose_mode": modes[k]} if len(modes) == len(self.frames) else {}),
                },
            )
            for k in range(len(self.frames))
        ]


def faces_key(faces: np.ndarray) -> str:
    """Short content hash naming a body topology."""
    return hashlib.sha256(np.ascontiguousarray(faces, dtype=np.int64).tobytes()).hexdigest()[:16]


class DatasetStore:
    """Read and write a dataset folder (see module docstring)."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)

    # -- writing -------------------------------------------------------------------------
    def write_sequence(self, rec: SequenceRecord) -> dict[str, Any]:
        """Write a sequence file atomically and return its manifest entry (not yet appended)."""
        key = faces_key(rec.body_faces)
        faces_path = self.root / "body_faces" / f"{key}.npy"
        if not faces_path.exists():
            buf = io.BytesIO()
            np.save(buf, np.ascontiguousarray(rec.body_faces, dtype=np.int64), allow_pickle=False)
            atomic_write_bytes(faces_path, buf.getvalue())
        arrays: dict[str, np.ndarray] = {
            "body_canonical": rec.body_canonical.astype(np.float32),
            "body_targets": rec.body_targets.astype(np.float32),
            "frames": rec.frames.astype(np.int64),
            "meta": np.frombuffer(json.dumps(rec.meta).encode(), dtype=np.uint8),
        }
        for res, lv in rec.levels.items():
            arrays[f"{res}/template"] = lv.template.astype(np.float32)
            arrays[f"{res}/faces"] = lv.faces.astype(np.int64)
            arrays[f"{res}/pinned"] = lv.pinned.astype(bool)
            arrays[f"{res}/priors"] = lv.priors.astype(np.float32)
            arrays[f"{res}/targets"] = lv.targets.astype(np.float32)
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        data = buf.getvalue()
        rel = f"sequences/{rec.seq_id}.npz"
        atomic_write_bytes(self.root / rel, data)
        return {
            "id": rec.seq_id,
            "file": rel,
            "sha256": hashlib.sha256(data).hexdigest(),
            "bytes": len(data),
            "split": rec.split,
            "garment_type": rec.garment_type,
            "fabric": rec.fabric,
            "body_faces": key,
            "num_frames": int(len(rec.frames)),
            "num_vertices": {res: int(len(lv.template)) for res, lv in rec.levels.items()},
        }

    def append_manifest(self, entry: dict[str, Any], name: str = MANIFEST) -> None:
        """Append one JSON line (single writer), flushed to disk."""
        self.root.mkdir(parents=True, exist_ok=True)
        with open(self.root / name, "a", encoding="utf-8") as fh:
            fh.write(json.dumps(entry, sort_keys=True) + "\n")
            fh.flush()
            os.fsync(fh.fileno())

    # -- reading -------------------------------------------------------------------------
    def entries(self, name: str = MANIFEST) -> list[dict[str, Any]]:
        """Manifest entries; a torn line (interrupted append) or a line that is not a JSON object is
        ignored here (``verify`` reports them)."""
        path = self.root / name
        if not path.exists():
            return []
        out = []
        for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(entry, dict):
                out.append(entry)
        return out

    def done_ids(self) -> set[str]:
        """Sequence ids already stored or rejected (skipped when resuming)."""
        return {e["id"] for e in self.entries()} | {e["id"] for e in self.entries(REJECTED)}

    def _faces(self, key: str) -> np.ndarray:
        path = self.root / "body_faces" / f"{key}.npy"
        if not path.exists():
            raise StoreError(f"{path} is missing: the dataset folder is incomplete, regenerate it")
        try:
            faces = np.load(path, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - a bad .npy header raises ValueError, TokenError, SyntaxError, ...
            raise StoreError(f"{path} is truncated or corrupt ({type(exc).__name__}: {_one_line(exc)})") from None
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
            raise StoreError(
                f"{path} is corrupt: body faces must be an (F, 3) integer array, got {faces.dtype} {faces.shape}"
            )
        return faces

    def read_sequence(self, entry: dict[str, Any]) -> SequenceRecord:
        missing = [k for k in ENTRY_KEYS if k not in entry]
        if missing:
            raise StoreError(f"{self.root / MANIFEST}: entry {entry.get('id', '?')!r} lacks keys {missing}")
        path = self.root / entry["file"]
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except FileNotFoundError:
            raise StoreError(f"{path} is listed in the manifest but missing") from None
        except Exception as exc:  # noqa: BLE001 - a damaged zip raises BadZipFile, zlib.error, NotImplementedError, ...
            raise StoreError(f"{path} is truncated or corrupt ({type(exc).__name__}: {_one_line(exc)})") from None
        try:
            meta = json.loads(arrays.pop("meta").tobytes().decode())
            levels = {
                res: GarmentLevel(
                    template=arrays[f"{res}/template"],
                    faces=arrays[f"{res}/faces"],
                    pinned=arrays[f"{res}/pinned"],
                    priors=arrays[f"{res}/priors"],
                    targets=arrays[f"{res}/targets"],
                )
                for res in RESOLUTIONS
                if f"{res}/template" in arrays
            }
            body_canonical, body_targets, frames = arrays["body_canonical"], arrays["body_targets"], arrays["frames"]
        except KeyError as exc:
            raise StoreError(f"{path} is corrupt: it lacks the array {exc.args[0]!r}") from None
        except (UnicodeDecodeError, ValueError) as exc:
            raise StoreError(
                f"{path} is corrupt: unreadable metadata ({type(exc).__name__}: {_one_line(exc)})"
            ) from None
        return SequenceRecord(
            seq_id=entry["id"],
            split=entry["split"],
            garment_type=entry["garment_type"],
            fabric=entry["fabric"],
            body_canonical=body_canonical,
            body_targets=body_targets,
            body_faces=self._faces(entry["body_faces"]),
            frames=frames,
            levels=levels,
            meta=meta,
        )

    def _require_manifest(self) -> None:
        """Raise StoreError unless the folder holds a manifest (a dataset that can be read)."""
        if not (self.root / MANIFEST).exists():
            raise StoreError(
                f"{self.root} is not a garsim dataset folder (no {MANIFEST}); "
                "make one with `garsim data generate --out DIR`"
            )

    def sequences(self, split: str | None = None) -> Iterator[SequenceRecord]:
        """The stored sequences (of one split: train, test or ood); a folder without a manifest is refused."""
        self._require_manifest()
        if split is not None and split not in SPLITS:
            raise ValueError(f"split must be one of {', '.join(SPLITS)} (or None: all), got {split!r}")
        for entry in self.entries():
            if split is None or entry["split"] == split:
                yield self.read_sequence(entry)

    def samples(self, split: str | None = None, resolution: str = "low") -> list[Sample]:
        """All samples of a split (all splits when None) at one resolution."""
        if resolution not in RESOLUTIONS:
            raise ValueError(f"resolution must be one of {RESOLUTIONS}, got {resolution!r}")
        return [s for rec in self.sequences(split) for s in rec.samples(resolution)]

    def export_subset(
        self,
        dst: str | os.PathLike,
        ids: list[str],
        frames: int | None = None,
        resolutions: tuple[str, ...] = RESOLUTIONS,
    ) -> DatasetStore:
        """Copy sequences ``ids`` into a new store, keeping the last ``frames`` frames and the given resolutions
        (e.g. a small committed test fixture); the manifest keeps each entry's description (construction, canonical
        pose, paired, phenotype, ...) with the settled count of the frames kept."""
        out = DatasetStore(dst)
        done = out.done_ids()
        by_id = {e["id"]: e for e in self.entries()}
        missing = [i for i in ids if i not in by_id]
        if missing:
            raise StoreError(f"{self.root}: no sequences {missing}")
        for seq_id in ids:
            if seq_id in done:
                continue
            rec = self.read_sequence(by_id[seq_id])
            keep = slice(-frames, None) if frames else slice(None)
            rec.body_targets, rec.frames = rec.body_targets[keep], rec.frames[keep]
            if "settled" in rec.meta:  # per-frame flags (generated data)
                rec.meta = {**rec.meta, "settled": rec.meta["settled"][keep]}
            rec.levels = {
                r: GarmentLevel(lv.template, lv.faces, lv.pinned, lv.priors[keep], lv.targets[keep])
                for r, lv in rec.levels.items()
                if r in resolutions
            }
            entry = out.write_sequence(rec)
            described = {k: v for k, v in by_id[seq_id].items() if k not in entry}
            if "num_settled" in described:
                described["num_settled"] = int(sum(rec.meta.get("settled", [True] * len(rec.frames))))
            out.append_manifest({**described, **entry})
        return out

    # -- inspection ----------------------------------------------------------------------
    def info(self) -> dict[str, Any]:
        """What the dataset holds: samples (settled / dynamic) per split, family, construction, fabric, canonical
        pose; paired-fabric groups; acceptance rate and CPU seconds per family; vertex and phenotype ranges."""
        self._require_manifest()
        entries = self.entries()
        rejected = self.entries(REJECTED)
        samples: Counter[str] = Counter()
        seqs: Counter[str] = Counter()
        for e in entries:
            keys = [f"split={e['split']}", f"family={e['garment_type']}", f"fabric={e['fabric']}"]
            keys += [f"{k}={e[k]}" for k in ("construction", "canonical_pose", "fabric_name") if k in e]
            keys += [f"split={e['split']}/family={e['garment_type']}"]
            for key in keys:
                seqs[key] += 1
                samples[key] += e["num_frames"]
        paired = [e for e in entries if e.get("paired")]
        groups: dict[str, set[str]] = {}
        for e in paired:
            groups.setdefault(e["job"], set()).add(e.get("fabric_name", e["fabric"]))
        # acceptance per family: settled states stored / states attempted (every copy's chain of targets)
        attempted: Counter[str] = Counter()
        stored: Counter[str] = Counter()
        cpu: Counter[str] = Counter()
        jobs: dict[str, set[str]] = {}
        stored_by_id = {e["id"]: e for e in entries}
        rejected_by_id = {e["id"]: e for e in rejected}
        for cid in stored_by_id.keys() | rejected_by_id.keys():
            e, rej = stored_by_id.get(cid), rejected_by_id.get(cid)
            fam = (e or rej).get("garment_type", (e or rej).get("family", "?"))
            jobs.setdefault(fam, set()).add((e or rej).get("job", cid))
            n_stored = e["num_frames"] if e else 0
            attempted[fam] += rej.get("targets", n_stored + 1) if rej else n_stored
            stored[fam] += n_stored
            cpu[fam] += float((e or rej).get("cpu_seconds", 0.0))
        per_family = {
            fam: {
                "jobs": len(jobs[fam]),
                "settled_samples": stored[fam],
                "states_attempted": attempted[fam],
                "acceptance_rate": round(stored[fam] / max(attempted[fam], 1), 3),
                "cpu_seconds": round(cpu[fam], 1),
                "cpu_seconds_per_settled_sample": round(cpu[fam] / max(stored[fam], 1), 2),
            }
            for fam in sorted(jobs)
        }
        verts = [max(e["num_vertices"].values()) for e in entries if e.get("num_vertices")]  # the finest level stored
        phen = [e["phenotype"] for e in entries if "phenotype" in e]
        return {
            "root": str(self.root),
            "sequences": len(entries),
            "samples": sum(e["num_frames"] for e in entries),
            "settled_samples": sum(e.get("num_settled", e["num_frames"]) for e in entries),
            "dynamic_samples": sum(e["num_frames"] - e.get("num_settled", e["num_frames"]) for e in entries),
            "garment_instances": len({e.get("job", e["id"]) for e in entries}),
            "rejected_sequences": len(rejected),
            "rejection_reasons": dict(Counter(e.get("reason", "?") for e in rejected)),
            "paired_groups": sum(len(f) >= 2 for f in groups.values()),
            "paired_complete_groups": sum(len(f) == 4 for f in groups.values()),
            "paired_samples": sum(e["num_frames"] for e in paired),
            "paired_train_samples": sum(e["num_frames"] for e in paired if e["split"] == "train"),
            "per_family": per_family,
            "vertices": {"min": min(verts), "max": max(verts)} if verts else {},
            "phenotype": {k: [min(p[k] for p in phen), max(p[k] for p in phen)] for k in (phen[0] if phen else {})},
            "bytes": sum(e["bytes"] for e in entries),
            "sequences_by": dict(sorted(seqs.items())),
            "samples_by": dict(sorted(samples.items())),
        }

    def verify(self) -> list[str]:
        """Problems found (empty when the store is sound), one line each naming the file: torn or incomplete
        manifest lines, missing, truncated or corrupt sample and body-faces files, and orphans (sample files
        that no manifest line lists, e.g. left by a killed run). Every problem is reported, not just the first."""
        manifest = self.root / MANIFEST
        if not manifest.exists():
            return [f"{manifest} not found: not a garsim dataset folder"]
        problems: list[str] = []
        listed: set[Path] = set()
        faces_checked: set[str] = set()
        lines = manifest.read_text(encoding="utf-8", errors="replace").splitlines()
        for lineno, line in enumerate(lines, 1):
            where = f"{manifest} line {lineno}"
            if not line.strip():
                continue
            try:
                e = json.loads(line)
            except json.JSONDecodeError as exc:
                kind = "torn (an interrupted append?)" if lineno == len(lines) else "not valid JSON"
                problems.append(f"{where}: {kind}: {exc.msg} at column {exc.colno}")
                continue
            if not isinstance(e, dict):
                problems.append(f"{where}: not a JSON object ({type(e).__name__})")
                continue
            where += f" (id {e['id']!r})" if "id" in e else ""
            missing = [k for k in ENTRY_KEYS if k not in e]
            if missing:
                problems.append(f"{where}: missing keys {missing}")
            key = e.get("body_faces")
            if isinstance(key, str) and key not in faces_checked:  # each body topology once
                faces_checked.add(key)
                try:
                    if faces_key(self._faces(key)) != key:
                        problems.append(f"{self.root / 'body_faces' / key}.npy: checksum mismatch (corrupt)")
                except StoreError as exc:
                    problems.append(str(exc))
            if not isinstance(e.get("file"), str):
                if "file" in e:
                    problems.append(f"{where}: 'file' is not a path: {e['file']!r}")
                continue
            path = self.root / e["file"]
            listed.add(path.resolve())
            if not path.is_file():
                problems.append(f"{path}: missing")
                continue
            try:
                data = path.read_bytes()
            except OSError as exc:
                problems.append(f"{path}: unreadable ({type(exc).__name__}: {_one_line(exc)})")
                continue
            if isinstance(e.get("bytes"), int) and len(data) != e["bytes"]:
                kind = "truncated" if len(data) < e["bytes"] else "longer than listed"
                problems.append(f"{path}: {kind} ({len(data)} of {e['bytes']} bytes)")
            elif "sha256" in e and hashlib.sha256(data).hexdigest() != e["sha256"]:
                problems.append(f"{path}: checksum mismatch (corrupt)")
            elif not missing:
                try:
                    self.read_sequence(e)
                except StoreError as exc:
                    problems.append(str(exc))
        seq_dir = self.root / "sequences"
        if seq_dir.is_dir():
            for path in sorted(seq_dir.iterdir()):
                if path.is_file() and path.resolve() not in listed:
                    problems.append(
                        f"orphan: {path}: in sequences/ but listed by no line of {MANIFEST} "
                        "(left by an interrupted run?)"
                    )
        return list(dict.fromkeys(problems))  # a shared corrupt body-faces file is reported once
