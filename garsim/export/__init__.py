"""Animation exporters: take a draped garment sequence into Blender, USD and glTF tools.

``frames`` are (T, N, 3) garment vertex positions in garsim's convention (metres, Z up; :func:`export_animation`
also takes Y up and cm or mm, ``up`` / ``units``), ``faces``
(F, 3) triangles; a body can come along as ``body_frames`` (T, Vb, 3) + ``body_faces``. Vertex
order is kept in every format. Files are written atomically; bad input raises :class:`ExportError`
(a ``ValueError``) before anything is written.

``metadata`` (a JSON-serialisable dict: which model made the drape, temporal smoothing, ...) is stored
where each format keeps such data: glTF ``asset.extras.garsim`` (and ``scenes[0].extras.garsim``), USD
root-layer ``customLayerData["garsim"]`` (JSON text), PC2 a ``# garsim {json}`` comment line in the OBJ
beside the cache; MP4/GIF previews carry none.

========================  ===============================================================
``.glb`` / ``.gltf``      :func:`write_gltf_animation` - morph target per frame (a rigged body skinned), Y up
``.usd/.usda/.usdc``      :func:`write_usd_animation` - time-sampled points, up axis and units declared
``.pc2``                  :func:`write_pc2_animation` - cache + frame-0 OBJ (Blender Mesh Cache)
``.mp4`` / ``.gif``       :func:`write_preview` - rendered preview clip
========================  ===============================================================
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from garsim.export._common import ExportError, check_extension
from garsim.export.gltf import GLTF_EXTENSIONS, BodySkin, write_gltf_animation
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
from garsim.geometry.io import UNITS, to_internal

SUPPORTED_EXTENSIONS: tuple[str, ...] = GLTF_EXTENSIONS + USD_EXTENSIONS + PC2_EXTENSIONS + VIDEO_EXTENSIONS

__all__ = [
    "BodySkin",
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
    up: str = "z",
    units: str = "m",
    **kw: Any,
) -> list[Path]:
    """Write a garment animation in the format named by ``path``'s extension -> the files written (main first).

    Keyword arguments go to the writer (``body_frames``, ``body_faces``, ``fps``, ``uvs``, ``normals``, ...);
    ``body_skin`` (a :class:`garsim.export.gltf.BodySkin` in Z-up metres, posing ``body_frames``) makes a glTF's body
    a skinned mesh and is ignored by the other formats.
    ``up`` ('z' or 'y') and ``units`` ('m', 'cm', 'mm'): the axis and length unit of ``frames`` and ``body_frames``
    (a user's, e.g. Blender's Y up): PC2 + OBJ keep them as given, USD declares them (upAxis, metersPerUnit), glTF
    (Y up, metres by its specification) and the previews get them converted.
    ``metadata``: a JSON-serialisable dict (e.g. ``{"model": ..., "temporal_smoothing_frames": ...}``),
    checked (by the writer, with the rest of the input) before anything is written and stored where the format
    keeps such data (see the module docstring); MP4/GIF previews carry none.
    ``.pc2`` also writes ``<stem>.obj`` (frame 0, the mesh to attach the cache to; ``uvs``/``normals``
    go there) and, with a body, ``<stem>_body.pc2`` + ``<stem>_body.obj``; ``fps`` is ignored for PC2.
    """
    p, ext = check_extension(path, SUPPORTED_EXTENSIONS, "export_animation")
    skin = kw.pop("body_skin", None)  # glTF writes a rigged body skinned; the other formats store its frames
    if up not in ("z", "y") or units not in UNITS:
        raise ExportError(f"up must be 'z' or 'y' and units one of {', '.join(UNITS)}, got {up!r} and {units!r}")
    if ext in USD_EXTENSIONS:
        return [write_usd_animation(p, frames, faces, metadata=metadata, up=up, meters_per_unit=UNITS[units], **kw)]
    if ext in GLTF_EXTENSIONS + VIDEO_EXTENSIONS and (up, units) != ("z", "m"):  # to garsim's Z-up metres
        frames = _internal(frames, up, units)
        for key in ("body_frames", "normals"):
            if kw.get(key) is not None:
                kw[key] = _internal(kw[key], up, units if key == "body_frames" else "m")
    if ext in GLTF_EXTENSIONS:
        return [write_gltf_animation(p, frames, faces, metadata=metadata, body_skin=skin, **kw)]
    if ext in VIDEO_EXTENSIONS:
        return [write_preview(p, frames, faces, metadata=metadata, **kw)]
    return write_pc2_animation(p, frames, faces, metadata=metadata, **kw)


def _internal(points: Any, up: str, units: str) -> Any:
    """Points (or normals, with units 'm') in the ``up`` axis and ``units`` -> Z-up metres; what is not a numeric
    array is passed on for the writer's own check to refuse."""
    try:
        a = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        return points
    if a.ndim < 2 or a.shape[-1] != 3:
        return points
    return to_internal(a, up, units)
