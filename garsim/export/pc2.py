"""Point Cache 2 (.pc2, Blender / 3ds Max) and OBJ sequences.

PC2 layout (little-endian): ``char[12] 'POINTCACHE2\\0'``, ``int32 version = 1``, ``int32 numPoints``,
``float32 startFrame``, ``float32 sampleRate``, ``int32 numSamples``, then ``numSamples * numPoints``
float32 xyz triples, frame by frame, in vertex order.

In Blender: import the frame-0 OBJ written next to the cache (keep the vertex order; garsim is Z up,
so import with Up = Z, Forward = Y, or the cache and the mesh disagree), add a *Mesh Cache* modifier,
format PC2, and point it at the .pc2 file.

PC2 has no room for metadata: :func:`write_obj` (and so the frame-0 OBJ that
:func:`garsim.export.export_animation` writes beside a cache) stores a caller's ``metadata`` dict as one
comment line ``# garsim {...json...}`` after the ``# garsim export`` header; OBJ readers skip comments.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.export._common import (
    Animation,
    ExportError,
    check_animation,
    check_frames,
    check_output,
    check_writable_folder,
    metadata_json,
)
from garsim.geometry.io import OBJ_METADATA_PREFIX, MeshAttributes, obj_text

PC2_MAGIC = b"POINTCACHE2\0"
PC2_HEADER = struct.Struct("<12siiffi")  # 32 bytes
PC2_EXTENSIONS: tuple[str, ...] = (".pc2",)


def _check_timing(start: Any, rate: Any) -> tuple[float, float]:
    """(start frame, sample rate) of a cache: finite, and the rate positive."""
    try:
        values = float(start), float(rate)
    except (TypeError, ValueError):
        values = (np.nan, np.nan)
    if not (np.isfinite(values[0]) and np.isfinite(values[1]) and values[1] > 0):
        raise ExportError(f"PC2 cache: start must be a finite number and rate a positive one, got {start!r}, {rate!r}")
    return values


def _pc2_bytes(frames: np.ndarray, start: float, rate: float) -> bytes:
    """A PC2 file of checked (T, N, 3) frames."""
    header = PC2_HEADER.pack(PC2_MAGIC, 1, frames.shape[1], start, rate, frames.shape[0])
    return header + np.ascontiguousarray(frames, dtype="<f4").tobytes()


def write_pc2(path: str | os.PathLike, frames: Any, start: float = 0.0, rate: float = 1.0) -> Path:
    """Write (T, N, 3) vertex positions as a PC2 point cache; ``start`` frame, ``rate`` = sampleRate field.

    ``rate`` is the frame step between samples (1.0: one sample per frame), as Blender writes it.
    """
    p, _ = check_output(path, PC2_EXTENSIONS, "write_pc2")
    v = check_frames(frames)
    return atomic_write_bytes(p, _pc2_bytes(v, *_check_timing(start, rate)))


def pc2_files(path: str | os.PathLike, with_body: bool = False) -> list[Path]:
    """The files :func:`write_pc2_animation` writes: the cache, its frame-0 OBJ, then the body's two."""
    p = Path(path)
    body = p.with_name(f"{p.stem}_body.pc2")
    return [p, p.with_suffix(".obj")] + ([body, body.with_suffix(".obj")] if with_body else [])


def write_pc2_animation(
    path: str | os.PathLike,
    frames: Any,
    faces: Any,
    body_frames: Any = None,
    body_faces: Any = None,
    uvs: Any = None,
    normals: Any = None,
    start: float = 0.0,
    rate: float = 1.0,
    fps: float | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> list[Path]:
    """Write the PC2 cache, the frame-0 OBJ to attach it to (``uvs``, ``normals`` and ``metadata`` go there) and,
    with a body, the body's two (:func:`pc2_files`) -> those paths; everything is checked before the first write.
    ``fps`` is ignored: PC2 stores frames, not seconds."""
    del fps
    p, _ = check_output(path, PC2_EXTENSIONS, "write_pc2_animation")
    a = check_animation(frames, faces, body_frames, body_faces, uvs, normals, metadata)
    timing = _check_timing(start, rate)
    parts = [a] if a.body is None else [a, Animation(*a.body)]
    files = pc2_files(p, with_body=a.body is not None)
    for file in files:  # nothing is written when one of the set cannot be
        if file.is_dir():
            raise ExportError(f"write_pc2_animation: {file} is a folder; the PC2 set needs that name for its file")
    data = [blob for part in parts for blob in (_pc2_bytes(part.frames, *timing), _frame_obj(part, 0))]
    return [atomic_write_bytes(file, blob) for file, blob in zip(files, data)]


def read_pc2(path: str | os.PathLike) -> tuple[np.ndarray, float, float]:
    """Read a PC2 file -> (frames float32 (T, N, 3), start frame, sample rate)."""
    data = Path(path).read_bytes()
    if len(data) < PC2_HEADER.size:
        raise ExportError(f"{path}: too short for a PC2 header ({len(data)} bytes)")
    magic, version, num_points, start, rate, num_samples = PC2_HEADER.unpack_from(data)
    if magic != PC2_MAGIC:
        raise ExportError(f"{path}: not a PC2 file (magic {magic!r})")
    if version != 1 or num_points < 0 or num_samples < 0:
        raise ExportError(
            f"{path}: unsupported PC2 header (version {version}, {num_points} points, {num_samples} samples)"
        )
    expected = PC2_HEADER.size + 12 * num_points * num_samples
    if len(data) != expected:
        raise ExportError(
            f"{path}: {len(data)} bytes, the header promises {expected}; the file is truncated or corrupt"
        )
    frames = np.frombuffer(data, dtype="<f4", offset=PC2_HEADER.size).reshape(num_samples, num_points, 3)
    return frames.astype(np.float32), float(start), float(rate)


def _frame_obj(a: Animation, k: int) -> bytes:
    """OBJ text of frame ``k``: one ``v`` (and ``vt``/``vn``) per vertex, in order, faces with 1-based ``v/vt/vn``
    indices, the normals frame ``k``'s when they are per frame.

    Metadata becomes the comment line ``# garsim {json}`` right after the header (ASCII JSON on one line:
    ``json.dumps`` escapes newlines and non-ASCII characters).
    """
    normals = a.normals if a.normals is None or a.normals.ndim == 2 else a.normals[k]
    per_vertex = MeshAttributes(
        uvs=a.uvs,
        uv_faces=None if a.uvs is None else a.faces,
        normals=normals,
        normal_faces=None if normals is None else a.faces,
    )
    header = "garsim export"
    if a.metadata is not None:
        header += "\n" + OBJ_METADATA_PREFIX + metadata_json(a.metadata)
    return obj_text(a.frames[k], a.faces, per_vertex, header=header)


def write_obj(
    path: str | os.PathLike,
    vertices: Any,
    faces: Any,
    uvs: Any = None,
    normals: Any = None,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write one (N, 3) mesh as OBJ in vertex order (per-vertex UVs/normals optional); atomic.

    ``metadata``: a JSON-serialisable dict written as the comment line ``# garsim {json}`` after the header.
    """
    p, _ = check_output(path, (".obj",), "write_obj")
    a = check_animation(_as_frame_stack(vertices), faces, uvs=uvs, normals=normals, metadata=metadata, name="vertices")
    return atomic_write_bytes(p, _frame_obj(a, 0))


def _as_frame_stack(vertices: Any) -> Any:
    a = np.asarray(vertices) if not hasattr(vertices, "detach") else vertices.detach().cpu().numpy()
    return a[None] if a.ndim == 2 else a


def write_obj_sequence(
    folder: str | os.PathLike,
    frames: Any,
    faces: Any,
    uvs: Any = None,
    normals: Any = None,
    stem: str = "garment",
    metadata: Mapping[str, Any] | None = None,
) -> list[Path]:
    """Write ``{stem}_{k:04d}.obj`` for every frame k (vertex order kept) -> the paths, frame order.

    ``normals``: (N, 3) for all frames or (T, N, 3) per frame. For a PC2 workflow import
    ``{stem}_0000.obj`` (the first frame) and attach the cache to it. ``metadata`` goes into every file
    as in :func:`write_obj`.
    """
    if not stem or os.sep in stem or (os.altsep and os.altsep in stem):
        raise ExportError(f"write_obj_sequence: stem must be a plain file name prefix, got {stem!r}")
    folder = check_writable_folder(folder)
    a = check_animation(frames, faces, uvs=uvs, normals=normals, metadata=metadata)
    return [atomic_write_bytes(folder / f"{stem}_{k:04d}.obj", _frame_obj(a, k)) for k in range(len(a.frames))]
