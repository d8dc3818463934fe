"""Independent readers of garsim's exports for the tests: glTF/GLB parsed from the specification (chunks,
accessors, morph targets), not through garsim's writer code."""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np


def z_up(points: np.ndarray) -> np.ndarray:
    """Undo the exporter's Z-up -> Y-up ((x, y, z) -> (x, z, -y)): (x, y, z) -> (x, -z, y)."""
    return np.stack([points[..., 0], -points[..., 2], points[..., 1]], axis=-1)


def read_gltf(path: Path) -> tuple[dict, bytes]:
    """(JSON document, BIN buffer) of a .glb (checking the chunk layout) or a .gltf with a data URI."""
    data = path.read_bytes()
    if path.suffix == ".gltf":
        doc = json.loads(data)
        uri = doc["buffers"][0]["uri"]
        assert uri.startswith("data:application/octet-stream;base64,")
        return doc, base64.b64decode(uri.split(",", 1)[1])
    magic, version, total = struct.unpack_from("<III", data, 0)
    assert (magic, version, total) == (0x46546C67, 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A and json_len % 4 == 0
    doc = json.loads(data[20 : 20 + json_len])
    bin_len, bin_type = struct.unpack_from("<II", data, 20 + json_len)
    assert bin_type == 0x004E4942 and bin_len % 4 == 0
    assert 28 + json_len + bin_len == len(data)
    blob = data[28 + json_len : 28 + json_len + bin_len]
    assert doc["buffers"][0]["byteLength"] <= bin_len
    return doc, blob


def accessor(doc: dict, blob: bytes, index: int) -> np.ndarray:
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = {5126: "<f4", 5125: "<u4", 5123: "<u2"}[acc["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    assert "byteStride" not in view
    offset = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    a = np.frombuffer(blob, dtype=dtype, count=acc["count"] * width, offset=offset)
    assert a.nbytes <= view["byteLength"]
    return a.reshape(acc["count"], width) if width > 1 else a


def gltf_frames(doc: dict, blob: bytes, name: str) -> dict:
    """Base attributes, faces, and every frame reconstructed as base + morph target k."""
    mesh = next(m for m in doc["meshes"] if m["name"] == name)
    (prim,) = mesh["primitives"]
    attrs = {k: accessor(doc, blob, i) for k, i in prim["attributes"].items()}
    base = attrs["POSITION"]
    frames = np.stack([base + accessor(doc, blob, t["POSITION"]) for t in prim["targets"]])
    out = {"attrs": attrs, "faces": accessor(doc, blob, prim["indices"]).reshape(-1, 3), "frames": frames}
    if "NORMAL" in prim["targets"][0]:
        out["normals"] = np.stack([attrs["NORMAL"] + accessor(doc, blob, t["NORMAL"]) for t in prim["targets"]])
    for t in prim["targets"]:  # glTF requires min/max on POSITION accessors, morph targets included
        acc = doc["accessors"][t["POSITION"]]
        assert "min" in acc and "max" in acc
    return out
