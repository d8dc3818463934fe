"""glTF 2.0 (.glb binary, or .gltf with an embedded base64 buffer) with morph-target animation (and, for a rigged
body, skinning).

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

A body given with its rig (:class:`BodySkin`: Anny's rest mesh, weights and per-frame bone transforms) is written
instead as a mesh skinned to one root joint node per bone (no inverse bind matrices: a joint's transform is its bone's
skinning transform), animated by the joints' translation and rotation: Blender imports an armature with the action.

Written with numpy + json + struct (and scipy for the joints' quaternions). Viewers differ in how many morph targets
they animate (Blender imports all of them as shape keys; some web viewers cap active targets); keep previews short.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.export._common import ExportError, check_animation, check_fps, check_output
from garsim.geometry.io import z_up_to_y_up

GLTF_EXTENSIONS: tuple[str, ...] = (".glb", ".gltf")

_COMPONENT_TYPES = {"f4": 5126, "u4": 5125, "u2": 5123, "u1": 5121}
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_GLB_MAGIC, _CHUNK_JSON, _CHUNK_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


class _Builder:
    """Accumulates the binary buffer, buffer views and accessors of one glTF document."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []
        self.offset = 0
        self.buffer_views: list[dict] = []
        self.accessors: list[dict] = []

    def add(
        self, array: np.ndarray, kind: str, target: int | None = None, bounds: bool = False, dtype: str | None = None
    ) -> int:
        """Append ``array`` (float32 or uint32, else as ``dtype``: "u1" or "<u2") as a buffer view + accessor ->
        accessor index; every view starts 4-byte aligned."""
        dtype = dtype or ("<f4" if array.dtype.kind == "f" else "<u4")
        a = np.ascontiguousarray(array, dtype=dtype)
        data = a.tobytes()
        view: dict[str, Any] = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.buffer_views.append(view)
        data += b"\0" * (-len(data) % 4)
        self.chunks.append(data)
        self.offset += len(data)
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[kind]
        acc: dict[str, Any] = {
            "bufferView": len(self.buffer_views) - 1,
            "componentType": _COMPONENT_TYPES[a.dtype.str.lstrip("<|")],
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


@dataclass(frozen=True)
class BodySkin:
    """A body that linear blend skinning poses (Anny's rig): ``rest`` (V, 3) vertices, ``weights`` / ``indices``
    (V, K) influences, ``transforms`` (T, J, 4, 4) rigid per-bone skinning transforms of each frame (rest -> posed),
    all in garsim's Z-up metres; ``names`` the J bones. :func:`write_gltf_animation` writes such a body as a mesh
    skinned to one joint node per bone (a few kB per frame where morph targets take 12 bytes per vertex and frame)."""

    rest: np.ndarray
    weights: np.ndarray
    indices: np.ndarray
    transforms: np.ndarray
    names: tuple[str, ...] = ()
    stored: np.ndarray | None = None
    """(J, 4, 4) the bones' transforms the file shows without its animation (the canonical pose the garment was
    draped in, so that the file can be its own canonical body); None: the first frame's."""

    def frames(self) -> np.ndarray:
        """(T, V, 3) posed vertices: sum_k w_k T_{j_k} rest."""
        from garsim.geometry.skinning import apply_transforms, blended_transforms, dense_weights

        rest = np.asarray(self.rest, dtype=np.float64)
        transforms = np.asarray(self.transforms, dtype=np.float64)
        dense = dense_weights(np.asarray(self.indices), np.asarray(self.weights), transforms.shape[1])
        return np.stack([apply_transforms(rest, blended_transforms(dense, t)) for t in transforms])


def _check_skin(skin: BodySkin, body: tuple[np.ndarray, np.ndarray] | None) -> None:
    """The skin must reproduce the body frames it stands for (rigid transforms, matching shapes)."""
    if body is None:
        raise ExportError("body_skin needs body_frames and body_faces (the frames it poses and the body's faces)")
    t = np.asarray(skin.transforms, dtype=np.float64)
    n = len(skin.rest)
    if (
        t.ndim != 4
        or t.shape[0] != len(body[0])
        or t.shape[2:] != (4, 4)
        or np.shape(skin.weights) != np.shape(skin.indices)
        or np.shape(skin.weights)[0] != n
        or n != body[0].shape[1]
    ):
        raise ExportError(
            f"body_skin: transforms {t.shape}, rest {np.shape(skin.rest)}, weights {np.shape(skin.weights)}, "
            f"indices {np.shape(skin.indices)} do not fit {body[0].shape[0]} body frames of {body[0].shape[1]} vertices"
        )
    if skin.stored is not None:
        if np.shape(skin.stored) != t.shape[1:]:
            raise ExportError(f"body_skin: stored {np.shape(skin.stored)} does not match the transforms' {t.shape[1:]}")
        t = np.concatenate([t, np.asarray(skin.stored, dtype=np.float64)[None]])
    r = t[..., :3, :3]
    if np.abs(r @ np.swapaxes(r, -1, -2) - np.eye(3)).max() > 1e-4:
        raise ExportError("body_skin: the bone transforms are not rigid (a glTF joint stores rotation and translation)")
    gap = float(np.abs(skin.frames() - body[0]).max())
    if gap > 1e-4:
        raise ExportError(f"body_skin: the skinned body lies up to {gap * 1000:.2f} mm from body_frames; pass its own")


def _add_skinned_body(b: _Builder, skin: BodySkin, faces: np.ndarray, y_up: bool, material: int) -> tuple[dict, list]:
    """The body mesh (rest POSITION, JOINTS_n / WEIGHTS_n in sets of four) and its joint nodes' per-frame
    (translation, quaternion) pairs, both turned Y up with ``y_up``."""
    from scipy.spatial.transform import Rotation

    c = z_up_to_y_up(np.eye(3)).T if y_up else np.eye(3)  # column vectors: p' = c p
    rest = np.asarray(skin.rest, dtype=np.float64) @ c.T
    t = np.asarray(skin.transforms, dtype=np.float64)
    if skin.stored is not None:  # the stored pose first, then the frames
        t = np.concatenate([np.asarray(skin.stored, dtype=np.float64)[None], t])
    rot = c @ t[..., :3, :3] @ c.T  # the same motion in the file's axes
    trans = t[..., :3, 3] @ c.T
    quats = Rotation.from_matrix(rot.reshape(-1, 3, 3)).as_quat().reshape(*rot.shape[:2], 4)  # (x, y, z, w)
    k = np.shape(skin.indices)[1]
    sets = -(-k // 4)
    small = t.shape[1] <= 256  # joint slots as bytes when they fit (glTF allows unsigned byte or short)
    joints = np.zeros((len(rest), 4 * sets), dtype=np.uint8 if small else np.uint16)
    weights = np.zeros((len(rest), 4 * sets), dtype=np.float32)
    joints[:, :k] = skin.indices
    weights[:, :k] = skin.weights
    attributes = {"POSITION": b.add(rest, "VEC3", _ARRAY_BUFFER, bounds=True)}
    for s in range(sets):
        attributes[f"JOINTS_{s}"] = b.add(joints[:, 4 * s : 4 * s + 4], "VEC4", _ARRAY_BUFFER, dtype=joints.dtype.str)
        attributes[f"WEIGHTS_{s}"] = b.add(weights[:, 4 * s : 4 * s + 4], "VEC4", _ARRAY_BUFFER)
    primitive = {
        "attributes": attributes,
        "indices": b.add(faces.astype(np.uint32).ravel(), "SCALAR", _ELEMENT_ARRAY_BUFFER),
        "mode": 4,
        "material": material,
    }
    first = 1 if skin.stored is not None else 0  # the frames' keys; the node itself keeps row 0
    return {"name": "Body", "primitives": [primitive]}, [
        (trans[0, j], quats[0, j], trans[first:, j], quats[first:, j]) for j in range(t.shape[1])
    ]


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
    body_skin: BodySkin | None = None,
) -> Path:
    """Write a garment sequence (and optional body) as a morph-target-animated glTF; returns the path.

    ``frames`` (T, N, 3) and ``body_frames`` (T, Vb, 3) in garsim's Z-up metres; ``y_up=True``
    rotates to glTF's Y up ((x, y, z) -> (x, z, -y)). ``uvs`` (N, 2), ``normals`` (N, 3) or (T, N, 3)
    belong to the garment. ``interpolation``: "LINEAR" or "STEP"; both show frame k exactly at k / fps.
    ``.glb`` is one binary file; ``.gltf`` embeds the buffer as base64. ``metadata``: a JSON-serialisable
    dict stored as ``asset.extras.garsim`` (and ``scenes[0].extras.garsim``). ``body_skin``: the body's rig
    (:class:`BodySkin`, which must pose ``body_frames``): the body is written skinned to one joint per bone, animated
    by the joints' translation and rotation, instead of one morph target per frame.
    """
    p, ext = check_output(path, GLTF_EXTENSIONS, "write_gltf_animation")
    a = check_animation(frames, faces, body_frames, body_faces, uvs, normals, metadata)
    fps = check_fps(fps)
    interp = str(interpolation).upper()
    if interp not in ("LINEAR", "STEP"):
        raise ExportError(f"interpolation must be 'LINEAR' or 'STEP', got {interpolation!r}")
    v, f, body, u, n, meta = a.frames, a.faces, a.body, a.uvs, a.normals, a.metadata
    if body_skin is not None:
        _check_skin(body_skin, body)
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
        if body_skin is None:
            meshes.append(_add_mesh(b, "Body", body[0], body[1], None, None, material=1))
        else:
            mesh, motion = _add_skinned_body(b, body_skin, body[1], y_up, material=1)
            meshes.append(mesh)
    num = v.shape[0]
    times = b.add(np.arange(num, dtype=np.float32) / np.float32(fps), "SCALAR", bounds=True)
    weights = b.add(np.eye(num, dtype=np.float32).ravel(), "SCALAR")
    nodes: list[dict[str, Any]] = [{"name": m["name"], "mesh": i} for i, m in enumerate(meshes)]
    morphed = [i for i, m in enumerate(meshes) if "weights" in m]
    # one sampler per channel (the morph channels share the time and weight accessors)
    samplers = [{"input": times, "output": weights, "interpolation": interp} for _ in morphed]
    channels = [{"sampler": k, "target": {"node": i, "path": "weights"}} for k, i in enumerate(morphed)]
    skins = []
    if body is not None and body_skin is not None:
        names = body_skin.names or tuple(f"bone_{j}" for j in range(len(motion)))
        first = len(nodes)
        for j, (t0, q0, translation, rotation) in enumerate(motion):
            nodes.append({"name": str(names[j]), "translation": t0.tolist(), "rotation": q0.tolist()})
            for path, values in (("translation", translation), ("rotation", rotation)):
                kind = "VEC3" if path == "translation" else "VEC4"
                samplers.append(
                    {"input": times, "output": b.add(values.astype(np.float32), kind), "interpolation": interp}
                )
                channels.append({"sampler": len(samplers) - 1, "target": {"node": first + j, "path": path}})
        nodes[1]["skin"] = 0
        skins = [{"name": "Body", "joints": list(range(first, len(nodes)))}]
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "garsim.export"},
        "scene": 0,
        "scenes": [{"name": "Scene", "nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "animations": [{"name": "drape", "samplers": samplers, "channels": channels}],
        "accessors": b.accessors,
        "bufferViews": b.buffer_views,
        "buffers": [{"byteLength": b.offset}],
        "extras": {"fps": fps, "frames": num, "up": "Y" if y_up else "Z", "metersPerUnit": 1.0},
    }
    if skins:
        doc["skins"] = skins
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
