"""glTF 2.0 (.glb binary, or .gltf with an embedded base64 buffer) with morph-target animation.

Each mesh (garment, optional body) stores frame 0 as its base POSITION and one morph target per
frame k holding ``frame_k - frame_0`` (target 0 is all zeros). One animation drives every mesh's
``weights`` with a one-hot sampler: at time k / fps only target k has weight 1, so frame k is shown
exactly (STEP holds it until the next key; LINEAR blends neighbouring frames in between).
Vertex order is kept; per-vertex UVs go to TEXCOORD_0 (v flipped to glTF's top-left origin) and
normals to NORMAL (per-frame normals as NORMAL morph targets). Target names are stored in
``mesh.extras.targetNames`` (Blender names the shape keys after them). The document's ``extras``
hold ``fps``, ``frames``, ``up`` and ``metersPerUnit``; caller ``metadata`` (which model, smoothing, ...)
goes to ``asset.extras.garsim`` and, so that trimesh (``scene.metadata``) and Blender (scene custom
properties) show it, to ``scenes[0].extras.garsim`` as well.

Written with numpy + json + struct only. Viewers differ in how many morph targets they animate
(Blender imports all of them as shape keys; some web viewers cap active targets); keep previews short.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.export._common import ExportError, check_animation, check_fps, check_output
from garsim.geometry.io import z_up_to_y_up

GLTF_EXTENSIONS: tuple[str, ...] = (".glb", ".gltf")

_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_GLB_MAGIC, _CHUNK_JSON, _CHUNK_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


class _Builder:
    """Accumulates the binary buffer, buffer views and accessors of one glTF document."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []
        self.offset = 0
        self.buffer_views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, array: np.ndarray, kind: str, target: int | None = None, bounds: bool = False) -> int:
        """Append ``array`` (float32 or uint32; 4-byte aligned) as a buffer view + accessor -> accessor index."""
        a = np.ascontiguousarray(array, dtype="<f4" if array.dtype.kind == "f" else "<u4")
        data = a.tobytes()
        view: dict[str, Any] = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.buffer_views.append(view)
        self.chunks.append(data)
        self.offset += len(data)  # every component is 4 bytes, so offsets stay aligned
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[kind]
        acc: dict[str, Any] = {
            "bufferView": len(self.buffer_views) - 1,
            "componentType": _FLOAT if a.dtype.kind == "f" else _UINT,
            "count": int(a.size // width),
            "type": kind,
        }
        if bounds:
            flat = a.reshape(-1, width)
            acc["min"] = [float(x) for x in flat.min(axis=0)]
            acc["max"] = [float(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def blob(self) -> bytes:
        return b"".join(self.chunks)


def _add_mesh(
    b: _Builder,
    name: str,
    frames: np.ndarray,
    faces: np.ndarray,
    uvs: np.ndarray | None,
    normals: np.ndarray | None,
    material: int,
) -> dict:
    base = frames[0]
    attributes = {"POSITION": b.add(base, "VEC3", _ARRAY_BUFFER, bounds=True)}
    if normals is not None:
        attributes["NORMAL"] = b.add(normals if normals.ndim == 2 else normals[0], "VEC3", _ARRAY_BUFFER)
    if uvs is not None:
        attributes["TEXCOORD_0"] = b.add(np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], axis=1), "VEC2", _ARRAY_BUFFER)
    targets = []
    base64_ = base.astype(np.float64)
    for k in range(len(frames)):
        # the difference in float64, rounded once: base + target reproduces frame k to float32 rounding
        t = {
            "POSITION": b.add((frames[k].astype(np.float64) - base64_).astype(np.float32), "VEC3", _ARRAY_BUFFER, True)
        }
        if normals is not None and normals.ndim == 3:
            t["NORMAL"] = b.add(normals[k].astype(np.float64) - normals[0], "VEC3", _ARRAY_BUFFER)
        targets.append(t)
    primitive = {
        "attributes": attributes,
        "indices": b.add(faces.astype(np.uint32).ravel(), "SCALAR", _ELEMENT_ARRAY_BUFFER),
        "mode": 4,
        "material": material,
        "targets": targets,
    }
    return {
        "name": name,
        "primitives": [primitive],
        "weights": [0.0] * len(frames),
        "extras": {"targetNames": [f"frame_{k:04d}" for k in range(len(frames))]},
    }


def _glb(doc: dict, blob: bytes) -> bytes:
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(js) + 8 + len(blob)
    return b"".join(
        [
            struct.pack("<III", _GLB_MAGIC, 2, total),
            struct.pack("<II", len(js), _CHUNK_JSON),
            js,
            struct.pack("<II", len(blob), _CHUNK_BIN),
            blob,
        ]
    )


def write_gltf_animation(
    path: str | os.PathLike,
    frames: Any,
    faces: Any,
    body_frames: Any = None,
    body_faces: Any = None,
    fps: float = 30,
    uvs: Any = None,
    y_up: bool = True,
    normals: Any = None,
    interpolation: str = "LINEAR",
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write a garment sequence (and optional body) as a morph-target-animated glTF; returns the path.

    ``frames`` (T, N, 3) and ``body_frames`` (T, Vb, 3) in garsim's Z-up metres; ``y_up=True``
    rotates to glTF's Y up ((x, y, z) -> (x, z, -y)). ``uvs`` (N, 2), ``normals`` (N, 3) or (T, N, 3)
    belong to the garment. ``interpolation``: "LINEAR" or "STEP"; both show frame k exactly at k / fps.
    ``.glb`` is one binary file; ``.gltf`` embeds the buffer as base64. ``metadata``: a JSON-serialisable
    dict stored as ``asset.extras.garsim`` (and ``scenes[0].extras.garsim``).
    """
    p, ext = check_output(path, GLTF_EXTENSIONS, "write_gltf_animation")
    a = check_animation(frames, faces, body_frames, body_faces, uvs, normals, metadata)
    fps = check_fps(fps)
    interp = str(interpolation).upper()
    if interp not in ("LINEAR", "STEP"):
        raise ExportError(f"interpolation must be 'LINEAR' or 'STEP', got {interpolation!r}")
    v, f, body, u, n, meta = a.frames, a.faces, a.body, a.uvs, a.normals, a.metadata
    if y_up:
        v = z_up_to_y_up(v)
        n = None if n is None else z_up_to_y_up(n)
        body = None if body is None else (z_up_to_y_up(body[0]), body[1])

    b = _Builder()
    materials = [
        {
            "name": "garment",
            "doubleSided": True,
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.23, 0.46, 0.69, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 0.9,
            },
        },
    ]
    meshes = [_add_mesh(b, "Garment", v, f, u, n, material=0)]
    if body is not None:
        materials.append(
            {
                "name": "body",
                "doubleSided": False,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.78, 0.78, 0.78, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.8,
                },
            }
        )
        meshes.append(_add_mesh(b, "Body", body[0], body[1], None, None, material=1))
    num = v.shape[0]
    times = b.add(np.arange(num, dtype=np.float32) / np.float32(fps), "SCALAR", bounds=True)
    weights = b.add(np.eye(num, dtype=np.float32).ravel(), "SCALAR")
    nodes = [{"name": m["name"], "mesh": i} for i, m in enumerate(meshes)]
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "garsim.export"},
        "scene": 0,
        "scenes": [{"name": "Scene", "nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "animations": [
            {
                "name": "drape",
                # one sampler per channel (they share the time and weight accessors)
                "samplers": [{"input": times, "output": weights, "interpolation": interp} for _ in nodes],
                "channels": [{"sampler": i, "target": {"node": i, "path": "weights"}} for i in range(len(nodes))],
            }
        ],
        "accessors": b.accessors,
        "bufferViews": b.buffer_views,
        "buffers": [{"byteLength": b.offset}],
        "extras": {"fps": fps, "frames": num, "up": "Y" if y_up else "Z", "metersPerUnit": 1.0},
    }
    if meta is not None:
        doc["asset"]["extras"] = {"garsim": meta}
        doc["scenes"][0]["extras"] = {"garsim": meta}
    blob = b.blob()
    if ext == ".glb":
        data = _glb(doc, blob)
    else:
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")
        data = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    return atomic_write_bytes(p, data)
