"""A glTF document built by hand for tests, independent of garsim's writer: numpy arrays become accessors of one
buffer, written as .glb or as .gltf with an embedded buffer."""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


class Doc:
    """A glTF document built by hand: arrays become accessors of one buffer."""

    def __init__(self) -> None:
        self.doc: dict = {"asset": {"version": "2.0"}, "accessors": [], "bufferViews": [], "nodes": [], "meshes": []}
        self.blob = bytearray()

    def add(self, array, ctype: int = 5126, normalized: bool = False) -> int:
        a = np.asarray(array)
        width = 1 if a.ndim == 1 else a.shape[1]
        dtype = {5126: "<f4", 5125: "<u4", 5123: "<u2", 5122: "<i2", 5121: "u1"}[ctype]
        data = a.astype(dtype).tobytes()
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)})
        self.blob += data
        acc = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": ctype, "count": len(a)}
        acc["type"] = _TYPES[width]
        if normalized:
            acc["normalized"] = True
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def mesh(self, positions, faces, **attributes) -> int:
        prim = {"attributes": {"POSITION": self.add(positions)}, "indices": self.add(np.ravel(faces), 5125)}
        for key, value in attributes.items():
            if key == "targets":
                prim["targets"] = [{"POSITION": self.add(t)} for t in value]
            else:
                prim["attributes"][key] = value
        self.doc["meshes"].append({"primitives": [prim]})
        return len(self.doc["meshes"]) - 1

    def node(self, **fields) -> int:
        self.doc["nodes"].append(fields)
        return len(self.doc["nodes"]) - 1

    def animate(self, channels: list[tuple[int, str, list[float], list, str]]) -> None:
        """channels: (node, path, key times, values per key, interpolation)."""
        anim = {"name": "move", "samplers": [], "channels": []}
        for node, path, times, values, interp in channels:
            out = np.asarray(values, dtype=np.float64)
            anim["samplers"].append(
                {
                    "input": self.add(np.asarray(times)),
                    "output": self.add(out.reshape(-1) if path == "weights" else out),
                    "interpolation": interp,
                }
            )
            anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {"node": node, "path": path}})
        self.doc.setdefault("animations", []).append(anim)

    def write(self, path: Path, scene_nodes: list[int]) -> Path:
        doc = dict(self.doc, scenes=[{"nodes": scene_nodes}], scene=0)
        if path.suffix == ".gltf":
            uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()
            path.write_text(json.dumps(dict(doc, buffers=[{"byteLength": len(self.blob), "uri": uri}])))
            return path
        chunk = json.dumps(dict(doc, buffers=[{"byteLength": len(self.blob)}])).encode()
        chunk += b" " * (-len(chunk) % 4)
        blob = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        total = 12 + 8 + len(chunk) + 8 + len(blob)
        head = struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(chunk), 0x4E4F534A)
        path.write_bytes(head + chunk + struct.pack("<II", len(blob), 0x004E4942) + blob)
        return path


def _quat(r: np.ndarray) -> np.ndarray:
    """(J, 3, 3) rotations -> (J, 4) quaternions (x, y, z, w)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(r).as_quat()


def skinned_body(path: Path, rest, faces, weights, indices, stored, frames, fps: float = 30.0) -> Path:
    """A body skinned by one root joint node per bone: ``rest`` (V, 3) vertices, ``weights`` / ``indices`` (V, K)
    influences, ``stored`` (J, 4, 4) the rigid skinning transforms the file shows at rest, ``frames`` (T, J, 4, 4)
    those of an animation with a key at every k / fps (the inverse bind matrices are the identity)."""
    d = Doc()
    k = indices.shape[1]
    sets = {}
    for s in range(0, k, 4):  # JOINTS_n / WEIGHTS_n in groups of four, zero-padded
        j = np.zeros((len(rest), 4), dtype=np.int64)
        w = np.zeros((len(rest), 4))
        j[:, : min(4, k - s)] = indices[:, s : s + 4]
        w[:, : min(4, k - s)] = weights[:, s : s + 4]
        sets[f"JOINTS_{s // 4}"] = d.add(j, 5123)
        sets[f"WEIGHTS_{s // 4}"] = d.add(w)
    mesh = d.mesh(rest, faces, **sets)
    joints = [
        d.node(translation=m[:3, 3].tolist(), rotation=q.tolist()) for m, q in zip(stored, _quat(stored[:, :3, :3]))
    ]
    d.doc["skins"] = [{"joints": joints}]
    body = d.node(mesh=mesh, skin=0)
    times = (np.arange(len(frames)) / fps).tolist()
    channels = []
    for j, node in enumerate(joints):
        channels.append((node, "translation", times, frames[:, j, :3, 3], "LINEAR"))
        channels.append((node, "rotation", times, _quat(frames[:, j, :3, :3]), "LINEAR"))
    d.animate(channels)
    return d.write(path, [*joints, body])
