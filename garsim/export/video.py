"""Preview videos (.mp4 via imageio-ffmpeg, .gif via imageio) rendered with garsim's numpy z-buffer.

Every kept frame is rendered by :func:`garsim.geometry.render.render_image` (body grey, garment
blue) with one fixed camera for the whole clip, framed on the bounding box of all frames. Long
sequences are subsampled evenly to at most ``max_frames`` images; the clip keeps the sequence's
duration (T / fps), so the video's frame rate drops accordingly. Previews carry no metadata: the
``metadata`` keyword is validated (like every exporter's) and otherwise ignored.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from garsim.export._common import ExportError, atomic_write_ext, check_animation, check_fps, check_output

VIDEO_EXTENSIONS: tuple[str, ...] = (".mp4", ".gif")
GARMENT_COLOR = "#3b75af"
BODY_COLOR = "#c8c8c8"


def _anchor(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A mesh that only frames the camera: the 8 corners of a box, one zero-area face the rasteriser skips."""
    lo, hi = points.min(axis=0).astype(np.float64), points.max(axis=0).astype(np.float64)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return corners, np.zeros((1, 3), dtype=np.int64)


def _frame_indices(num_frames: int, max_frames: int) -> np.ndarray:
    if num_frames <= max_frames:
        return np.arange(num_frames)
    return np.unique(np.round(np.linspace(0, num_frames - 1, max_frames)).astype(np.int64))


def _fit(img: np.ndarray, height: int, width: int, background: float = 255) -> np.ndarray:
    """Pad (or crop) an image to exactly (height, width) with the background colour."""
    out = np.full((height, width, 3), background, dtype=np.uint8)
    h, w = min(height, img.shape[0]), min(width, img.shape[1])
    out[:h, :w] = img[:h, :w]
    return out


def write_preview(
    path: str | os.PathLike,
    frames: Any,
    faces: Any,
    body_frames: Any = None,
    body_faces: Any = None,
    fps: float = 15,
    size: int = 320,
    views: Sequence[str | float] = ("front",),
    max_frames: int = 120,
    uvs: Any = None,
    normals: Any = None,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Render a short preview clip of a garment sequence (and optional body) to .mp4 or .gif; returns the path.

    ``size``: image height in pixels (width follows the framing and the number of ``views``).
    ``uvs``/``normals`` are accepted for a uniform :func:`garsim.export.export_animation` call and ignored
    (the renderer shades with its own smooth normals). ``metadata`` is checked like every exporter's and
    ignored: MP4/GIF previews carry none (keep it in the GLB/USD/PC2 export beside them).
    """
    from garsim.geometry.render import render_image

    p, ext = check_output(path, VIDEO_EXTENSIONS, "write_preview")
    a = check_animation(frames, faces, body_frames, body_faces, metadata=metadata)  # uvs/normals: not drawn
    fps = check_fps(fps)
    if int(size) < 16:
        raise ExportError(f"size must be at least 16 pixels, got {size}")
    if int(max_frames) < 1:
        raise ExportError(f"max_frames must be at least 1, got {max_frames}")
    del uvs, normals
    v, f, body = a.frames, a.faces, a.body
    views = [views] if isinstance(views, (str, int, float)) else list(views)

    keep = _frame_indices(v.shape[0], int(max_frames))
    everything = (
        v[keep].reshape(-1, 3)
        if body is None
        else np.concatenate([v[keep].reshape(-1, 3), body[0][keep].reshape(-1, 3)])
    )
    anchor = _anchor(everything)
    images = []
    for k in keep:
        meshes: list[Any] = [anchor]
        colors: list[Any] = ["white"]
        if body is not None:
            meshes.append((body[0][k], body[1]))
            colors.append(BODY_COLOR)
        meshes.append((v[k], f))
        colors.append(GARMENT_COLOR)
        img = render_image(meshes, views=views, colors=colors, size=int(size))
        images.append(np.round(np.clip(img, 0.0, 1.0) * 255).astype(np.uint8))
    block = 16 if ext == ".mp4" else 1  # H.264 / yuv420p wants even sizes; 16 avoids imageio's rescale
    height = -(-max(im.shape[0] for im in images) // block) * block
    width = -(-max(im.shape[1] for im in images) // block) * block
    images = [_fit(im, height, width) for im in images]
    out_fps = fps * len(keep) / v.shape[0]  # keep the sequence's duration

    def write(tmp: str) -> None:
        import imageio.v2 as iio

        if ext == ".gif":
            iio.mimwrite(tmp, images, format="GIF", duration=1000.0 / out_fps, loop=0)
        else:
            with iio.get_writer(
                tmp,
                format="FFMPEG",
                mode="I",
                fps=out_fps,
                codec="libx264",
                pixelformat="yuv420p",
                macro_block_size=16,
                quality=7,
                ffmpeg_log_level="error",
            ) as writer:
                for im in images:
                    writer.append_data(im)

    return atomic_write_ext(p, write)
