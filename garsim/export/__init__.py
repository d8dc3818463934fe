"""Animation exporters: take a draped garment sequence into Blender, USD and glTF tools.

``frames`` are (T, N, 3) garment vertex positions in garsim's convention (metres, Z up), ``faces``
(F, 3) triangles; a body can come along as ``body_frames`` (T, Vb, 3) + ``body_faces``. Vertex
order is kept in every format. Files are written atomically; bad input raises :class:`ExportError`
(a ``ValueError``) before anything is written.

``metadata`` (a JSON-serialisable dict: which model made the drape, temporal smoothing, ...) is stored
where each format keeps such data: glTF ``asset.extras.garsim`` (and ``scenes[0].extras.garsim``), USD
root-layer ``customLayerData["garsim"]`` (JSON text), PC2 a ``# garsim {json}`` comment line in the OBJ
beside the cache; MP4/GIF previews carry none.

========================  ===============================================================
``.glb`` / ``.gltf``      :func:`write_gltf_animation` - morph target per frame, Y up
``.usd/.usda/.usdc``      :func:`write_usd_animation` - time-sampled points, Z up, metres
``.pc2``                  :func:`write_pc2_animation` - cache + frame-0 OBJ (Blender Mesh Cache)
``.mp4`` / ``.gif``       :func:`write_preview` - rendered preview clip
========================  ===============================================================
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from garsim.export._common import ExportError, check_extension
from garsim.export.gltf import GLTF_EXTENSIONS, write_gltf_animation
from garsim.export.pc2 import (
    PC2_EXTENSIONS,
    pc2_files,
    read_pc2,
    write_obj,
    write_obj_sequence,
    write_pc2,
    write_pc2_animation,
)
from garsim.export.usd import USD_EXTENSIONS, write_usd_animation
from garsim.export.video import VIDEO_EXTENSIONS, write_preview

SUPPORTED_EXTENSIONS: tuple[str, ...] = GLTF_EXTENSIONS + USD_EXTENSIONS + PC2_EXTENSIONS + VIDEO_EXTENSIONS

__all__ = [
    "ExportError",
    "SUPPORTED_EXTENSIONS",
    "animation_files",
    "export_animation",
    "read_pc2",
    "write_gltf_animation",
    "write_obj",
    "write_obj_sequence",
    "write_pc2",
    "write_pc2_animation",
    "write_preview",
    "write_usd_animation",
]


def animation_files(path: str | os.PathLike, with_body: bool = False) -> list[Path]:
    """The files ``export_animation(path, ...)`` writes, main first (for checks before any work)."""
    p = Path(path)
    return pc2_files(p, with_body) if p.suffix.lower() == ".pc2" else [p]


def export_animation(
    path: str | os.PathLike,
    frames: Any,
    faces: Any,
    metadata: Mapping[str, Any] | None = None,
    **kw: Any,
) -> list[Path]:
    """Write a garment animation in the format named by ``path``'s extension -> the files written (main first).

    Keyword arguments go to the writer (``body_frames``, ``body_faces``, ``fps``, ``uvs``, ...).
    ``metadata``: a JSON-serialisable dict (e.g. ``{"model": ..., "temporal_smoothing_frames": ...}``),
    checked (by the writer, with the rest of the input) before anything is written and stored where the format
    keeps such data (see the module docstring); MP4/GIF previews carry none.
    ``.pc2`` also writes ``<stem>.obj`` (frame 0, the mesh to attach the cache to; ``uvs``/``normals``
    go there) and, with a body, ``<stem>_body.pc2`` + ``<stem>_body.obj``; ``fps`` is ignored for PC2.
    """
    p, ext = check_extension(path, SUPPORTED_EXTENSIONS, "export_animation")
    if ext in GLTF_EXTENSIONS:
        return [write_gltf_animation(p, frames, faces, metadata=metadata, **kw)]
    if ext in USD_EXTENSIONS:
        return [write_usd_animation(p, frames, faces, metadata=metadata, **kw)]
    if ext in VIDEO_EXTENSIONS:
        return [write_preview(p, frames, faces, metadata=metadata, **kw)]
    return write_pc2_animation(p, frames, faces, metadata=metadata, **kw)
