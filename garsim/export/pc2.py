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

from garsim.atomic import atomic_write, atomic_write_bytes
from garsim.export._common import (
    ExportError,
    check_faces,
    check_frames,
    check_metadata,
    check_normals,
    check_output,
    check_uvs,
    check_writable_folder,
    metadata_json,
)
from garsim.geometry.io import MeshAttributes, obj_text

PC2_MAGIC = b"POINTCACHE2\0"
PC2_HEADER = struct.Struct("<12siiffi")  # 32 bytes
PC2_EXTENSIONS: tuple[str, ...] = (".pc2",)


def write_pc2(path: str | os.PathLike, frames: Any, start: float = 0.0, rate: float = 1.0) -> Path:
    """Write (T, N, 3) vertex positions as a PC2 point cache; ``start`` frame, ``rate`` = sampleRate field.

    ``rate`` is the frame step between samples (1.0: one sample per frame), as Blender writes it.
    """
    p, _ = check_output(path, PC2_EXTENSIONS, "write_pc2")
    v = check_frames(frames)
    start, rate = float(start), float(rate)
    if not (np.isfinite(start) and np.isfinite(rate) and rate > 0):
        raise ExportError(f"write_pc2: start must be finite and rate positive, got start={start}, rate={rate}")
    header = PC2_HEADER.pack(PC2_MAGIC, 1, v.shape[1], start, rate, v.shape[0])
    return atomic_write_bytes(p, header + np.ascontiguousarray(v, dtype="<f4").tobytes())


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


OBJ_METADATA_PREFIX = "# garsim "


def _obj_text(
    vertices: np.ndarray,
    faces: np.ndarray,
    uvs: np.ndarray | None,
    normals: np.ndarray | None,
    metadata: dict[str, Any] | None = None,
) -> bytes:
    """OBJ text with one ``v`` (and ``vt``/``vn``) per vertex, in order; faces use 1-based ``v/vt/vn`` indices.

    Validated ``metadata`` becomes the comment line ``# garsim {json}`` right after the header (ASCII JSON
    on one line: ``json.dumps`` escapes newlines and non-ASCII characters).
    """
    per_vertex = MeshAttributes(
        uvs=uvs,
        uv_faces=None if uvs is None else faces,
        normals=normals,
        normal_faces=None if normals is None else faces,
    )
    header = "garsim export"
    if metadata is not None:
        header += "\n" + OBJ_METADATA_PREFIX + metadata_json(metadata)
    return obj_text(vertices, faces, per_vertex, header=header)


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
    v = check_frames(_as_frame_stack(vertices), name="vertices")[0]
    f = check_faces(faces, len(v))
    u = check_uvs(uvs, len(v))
    n = check_normals(normals, 1, len(v))
    meta = check_metadata(metadata)
    return atomic_write_bytes(p, _obj_text(v, f, u, None if n is None else n.reshape(-1, 3), meta))


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
    v = check_frames(frames)
    f = check_faces(faces, v.shape[1])
    u = check_uvs(uvs, v.shape[1])
    n = check_normals(normals, v.shape[0], v.shape[1])
    meta = check_metadata(metadata)
    paths = []
    for k in range(v.shape[0]):
        nk = None if n is None else (n if n.ndim == 2 else n[k])
        text = _obj_text(v[k], f, u, nk, meta)
        paths.append(atomic_write(folder / f"{stem}_{k:04d}.obj", lambda tmp, t=text: Path(tmp).write_bytes(t)))
    return paths
