"""Validation at the exporters' boundary and atomic writing of files whose format follows the extension.

Every writer checks, before any work: the extension, that the output folder can be written, then
the arrays: ``frames`` (T, N, 3) finite, ``faces`` (F, 3) integer indices in [0, N), optional body
frames (T, Vb, 3) with the same T, UVs (N, 2), normals (N, 3) or (T, N, 3), and ``metadata`` (a dict
of JSON values). Problems raise :class:`ExportError` (a ``ValueError``) with a one-line message.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write, check_writable_folder


class ExportError(ValueError):
    """Input an exporter cannot write; the one-line message says what to fix."""


def _to_numpy(x: Any, name: str) -> np.ndarray:
    """``np.asarray`` that also takes torch tensors (on any device); ragged input is an ExportError naming ``name``."""
    if hasattr(x, "detach") and hasattr(x, "cpu"):
        x = x.detach().cpu().numpy()
    try:
        return np.asarray(x)
    except (TypeError, ValueError, OverflowError) as exc:
        text = str(exc).strip().splitlines()
        raise ExportError(f"{name}: not a numeric array ({text[0] if text else type(exc).__name__})") from None


def check_extension(path: str | os.PathLike, supported: tuple[str, ...], what: str) -> tuple[Path, str]:
    """Check that the extension is one ``what`` writes -> (path, extension)."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in supported:
        got = repr(ext) if ext else "a file without an extension"
        raise ExportError(f"{p}: {what} cannot write {got}; use one of {', '.join(supported)}")
    return p, ext


def check_output(path: str | os.PathLike, supported: tuple[str, ...], what: str) -> tuple[Path, str]:
    """Check the extension and that the output folder is (or can be made) writable -> (path, extension)."""
    p, ext = check_extension(path, supported, what)
    check_writable_folder(p.parent, label=str(p))
    return p, ext


def check_frames(frames: Any, name: str = "frames") -> np.ndarray:
    """(T, N, 3) finite float32 vertex positions, T >= 1, N >= 1."""
    a = _to_numpy(frames, name)
    if a.dtype.kind not in "iuf":
        raise ExportError(f"{name}: must be real numbers, got dtype {a.dtype}")
    if a.ndim == 2 and a.shape[-1] == 3:
        raise ExportError(f"{name}: expected (T, N, 3) frames, got one frame {a.shape}; pass frames[None] for a still")
    if a.ndim != 3 or a.shape[2] != 3:
        raise ExportError(f"{name}: expected shape (T, N, 3), got {a.shape}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise ExportError(f"{name}: empty, shape {a.shape}; need at least one frame of one vertex")
    with np.errstate(over="ignore", invalid="ignore"):
        a = a.astype(np.float32)
    bad = ~np.isfinite(a).all(axis=2)
    if bad.any():
        t, i = (int(x[0]) for x in np.nonzero(bad))
        raise ExportError(
            f"{name}: {int(bad.sum())} vertex positions are NaN/inf or beyond float32 range "
            f"(first: frame {t}, vertex {i})"
        )
    return a


def check_faces(faces: Any, num_vertices: int, name: str = "faces") -> np.ndarray:
    """(F, 3) int64 triangle indices in [0, num_vertices), F >= 1."""
    f = _to_numpy(faces, name)
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
        raise ExportError(f"{name}: expected a non-empty (F, 3) triangle index array, got shape {f.shape}")
    if f.dtype.kind == "f":
        if not np.isfinite(f).all() or not np.all(f == np.round(f)):
            raise ExportError(f"{name}: face indices must be integers")
    elif f.dtype.kind not in "iu":
        raise ExportError(f"{name}: face indices must be integers, got dtype {f.dtype}")
    oob = (f < 0) | (f >= num_vertices)
    if oob.any():
        row = int(np.flatnonzero(oob.any(axis=1))[0])
        raise ExportError(
            f"{name}: indices outside [0, {num_vertices - 1}] (first face {row}: {f[row].tolist()}); "
            "faces do not match the vertices"
        )
    return f.astype(np.int64)


def check_body(body_frames: Any, body_faces: Any, num_frames: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Validated (body frames (T, Vb, 3), body faces) or None; both or neither must be given, with the garment's T."""
    if body_frames is None and body_faces is None:
        return None
    if body_frames is None or body_faces is None:
        raise ExportError("body_frames and body_faces go together; pass both or neither")
    bv = check_frames(body_frames, name="body_frames")
    if bv.shape[0] != num_frames:
        raise ExportError(f"body_frames: {bv.shape[0]} frames but the garment has {num_frames}; they must match")
    return bv, check_faces(body_faces, bv.shape[1], name="body_faces")


def _per_vertex(x: Any, name: str, shapes: tuple[tuple[int, ...], ...], expected: str) -> np.ndarray | None:
    """Optional per-vertex data: finite float32 of one of ``shapes`` (``expected`` says which), or None."""
    if x is None:
        return None
    a = _to_numpy(x, name)
    if a.dtype.kind not in "iuf" or a.shape not in shapes:
        raise ExportError(f"{name}: expected {expected}, got {a.shape} {a.dtype}")
    a = a.astype(np.float32)
    if not np.isfinite(a).all():
        raise ExportError(f"{name}: contain NaN/inf")
    return a


def check_uvs(uvs: Any, num_vertices: int) -> np.ndarray | None:
    """(N, 2) finite float32 per-vertex UVs, or None."""
    return _per_vertex(uvs, "uvs", ((num_vertices, 2),), f"one (u, v) per vertex, shape ({num_vertices}, 2)")


def check_normals(normals: Any, num_frames: int, num_vertices: int) -> np.ndarray | None:
    """Per-vertex normals, (N, 3) static or (T, N, 3) per frame, finite float32, or None."""
    shapes = ((num_vertices, 3), (num_frames, num_vertices, 3))
    return _per_vertex(normals, "normals", shapes, f"({num_vertices}, 3) or ({num_frames}, {num_vertices}, 3)")


def check_fps(fps: Any) -> float:
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise ExportError(f"fps must be a positive number, got {fps!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise ExportError(f"fps must be a positive number, got {fps!r}")
    return value


def _json_value(x: Any, where: str) -> Any:
    """``x`` as plain JSON data (dict/list/str/int/float/bool/None); numpy scalars become Python numbers."""
    if isinstance(x, np.generic) and x.dtype.kind in "biuf":
        x = x.item()
    if x is None or isinstance(x, (str, bool, int)):
        return x
    if isinstance(x, float):
        if not math.isfinite(x):
            raise ExportError(f"{where}: {x!r} is not valid JSON; use a finite number, a string or None")
        return x
    if isinstance(x, Mapping):
        out = {}
        for key, value in x.items():
            if not isinstance(key, str):
                raise ExportError(f"{where}: keys must be strings, got {type(key).__name__} {key!r}")
            out[key] = _json_value(value, f"{where}[{key!r}]")
        return out
    if isinstance(x, (list, tuple)):
        return [_json_value(value, f"{where}[{i}]") for i, value in enumerate(x)]
    raise ExportError(
        f"{where}: type {type(x).__name__} is not JSON-serialisable; use dicts, lists, strings, numbers, bools or None"
    )


def check_metadata(metadata: Any) -> dict[str, Any] | None:
    """A JSON-serialisable dict (copied as plain dict/list/str/number/bool/None values), or None.

    Tuples become lists and numpy scalars Python numbers; anything else JSON cannot hold (sets, arrays,
    objects, NaN/inf, non-string keys) raises :class:`ExportError` naming the offending entry.
    """
    if metadata is None:
        return None
    if not isinstance(metadata, Mapping):
        raise ExportError(f"metadata must be a dict of JSON values, got {type(metadata).__name__}")
    try:
        return _json_value(metadata, "metadata")
    except RecursionError:
        raise ExportError("metadata is nested too deeply or contains itself; pass a plain JSON-like dict") from None


@dataclass(frozen=True)
class Animation:
    """An exporter's checked input (:func:`check_animation`): garment frames (T, N, 3) float32 and faces (F, 3)
    int64, the optional body (frames (T, Vb, 3), faces), per-vertex UVs (N, 2), normals (N, 3) or (T, N, 3), and
    JSON metadata."""

    frames: np.ndarray
    faces: np.ndarray
    body: tuple[np.ndarray, np.ndarray] | None = None
    uvs: np.ndarray | None = None
    normals: np.ndarray | None = None
    metadata: dict[str, Any] | None = None


def check_animation(
    frames: Any,
    faces: Any,
    body_frames: Any = None,
    body_faces: Any = None,
    uvs: Any = None,
    normals: Any = None,
    metadata: Mapping[str, Any] | None = None,
    name: str = "frames",
) -> Animation:
    """Every exporter's input checks, once: frames (named ``name`` in messages), faces, body, UVs, normals, metadata."""
    v = check_frames(frames, name=name)
    return Animation(
        frames=v,
        faces=check_faces(faces, v.shape[1]),
        body=check_body(body_frames, body_faces, v.shape[0]),
        uvs=check_uvs(uvs, v.shape[1]),
        normals=check_normals(normals, v.shape[0], v.shape[1]),
        metadata=check_metadata(metadata),
    )


def metadata_json(metadata: Mapping[str, Any]) -> str:
    """Compact one-line ASCII JSON of validated metadata (keys in the given order)."""
    return json.dumps(metadata, separators=(",", ":"), allow_nan=False)


def atomic_write_ext(path: Path, write: Callable[[str], None]) -> Path:
    """Atomic write for libraries that pick the format from the file name (USD, ffmpeg).

    ``write`` receives a temp path in the target folder that ends with the target's extension; the
    result is fsynced and renamed over ``path`` (via :func:`garsim.atomic.atomic_write`).
    """
    ext = path.suffix

    def fill(tmp: str) -> None:
        named = tmp + ext
        try:
            write(named)
            os.replace(named, tmp)
        finally:
            if os.path.exists(named):
                os.unlink(named)

    return atomic_write(path, fill)
