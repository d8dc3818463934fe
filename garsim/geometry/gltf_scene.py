"""A glTF 2.0 scene's meshes as they show: node hierarchy, skins, morph targets and animations evaluated to world-space
vertices, at rest or sampled over an animation (numpy, json and struct only).

What a viewer shows is what this returns: every triangle primitive of every mesh node of the default scene, in
depth-first node order (children in their listed order; each primitive's vertices in file order, concatenated), with

- the node's world transform (``matrix``, or ``translation`` / ``rotation`` / ``scale``, parents first), a mirroring
  one (negative determinant at rest) reversing the triangles' winding as the specification says;
- morph targets blended by the node's ``weights`` (else the mesh's; animated ``weights`` override both);
- a skin as the specification defines it: each vertex moved by the weighted sum of its joints' matrices
  ``world(joint) @ inverseBindMatrix`` (``JOINTS_n`` / ``WEIGHTS_n``, weights renormalised to sum to one), the
  skinned node's own transform ignored;
- animation channels on ``translation``, ``rotation`` (shortest-arc slerp), ``scale`` and ``weights``, with
  ``STEP``, ``LINEAR`` and ``CUBICSPLINE`` samplers, held at their first and last keys outside their range.

Triangle strips and fans lose the degenerate triangles that stitch them; a primitive without ``TEXCOORD_0`` in a file
whose other primitives have one gets (0, 0). Accessors may be strided, normalised integers or sparse. Buffers come
from the GLB's binary chunk, base64 ``data:`` URIs, or files beside a ``.gltf`` (never from the network); quantised
attributes (``KHR_mesh_quantization``) are read as numbers. Geometry the reader cannot decode (Draco or meshopt
compression, GPU instancing: an ``extensionsRequired`` entry) is refused by name. Coordinates are returned as stored:
glTF's Y-up metres (:func:`garsim.geometry.io.y_up_to_z_up` turns them to garsim's axes).
"""

from __future__ import annotations

import base64
import json
import struct
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

import numpy as np

_DTYPES = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORMALISED_MAX = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_HARMLESS_PREFIXES = ("KHR_materials_", "KHR_texture_", "EXT_texture_", "KHR_lights_punctual", "KHR_mesh_quantization")
"""Required extensions this reader can take: those that change only how surfaces look, and quantised attributes
(integer positions, morph targets and UVs, read as numbers)."""


class GltfError(ValueError):
    """A glTF file this reader cannot evaluate; the message says why."""


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _read_container(path: Path) -> tuple[dict, bytes]:
    """(the JSON document, the GLB's binary chunk, empty for a .gltf) of a glTF file; GltfError for one that is not."""
    data = path.read_bytes()
    if path.suffix.lower() == ".gltf":
        try:
            doc = json.loads(data)
        except ValueError as exc:
            raise GltfError(f"{path}: not a glTF document ({_first_line(exc)})") from None
        if not isinstance(doc, dict):
            raise GltfError(f"{path}: not a glTF document (the JSON is not an object)")
        return doc, b""
    if len(data) < 20:
        raise GltfError(f"{path}: not a GLB file (too short)")
    magic, version, total = struct.unpack_from("<III", data, 0)
    if magic != 0x46546C67 or version != 2:
        raise GltfError(f"{path}: not a glTF 2.0 binary (.glb)")
    if total > len(data):
        raise GltfError(f"{path}: truncated GLB ({len(data)} of {total} bytes)")
    json_len, _ = struct.unpack_from("<II", data, 12)
    try:
        doc = json.loads(data[20 : 20 + json_len])
    except ValueError as exc:
        raise GltfError(f"{path}: the GLB's JSON chunk does not parse ({_first_line(exc)})") from None
    chunk = b""
    if 28 + json_len <= len(data):
        bin_len, _ = struct.unpack_from("<II", data, 20 + json_len)
        chunk = data[28 + json_len : 28 + json_len + bin_len]
    return doc, chunk


def _buffer(path: Path, doc: dict, index: int, glb_chunk: bytes) -> bytes:
    """Buffer ``index``: the GLB chunk (no uri), a base64 data URI, or a file next to ``path``."""
    buf = doc["buffers"][index]
    uri = buf.get("uri")
    if uri is None:
        if path.suffix.lower() != ".glb":
            raise GltfError(f"{path}: buffer {index} has no uri (only a .glb carries its buffer inside)")
        return glb_chunk
    if uri.startswith("data:"):
        try:
            return base64.b64decode(uri.split(",", 1)[1])
        except (IndexError, ValueError) as exc:
            raise GltfError(f"{path}: buffer {index}'s data URI does not decode ({_first_line(exc)})") from None
    if "://" in uri:
        raise GltfError(f"{path}: buffer {index} is at {uri}; garsim reads no network: download it beside the file")
    source = path.parent / unquote(uri)
    try:
        return source.read_bytes()
    except OSError as exc:
        raise GltfError(f"{path}: its buffer file {source} cannot be read ({_first_line(exc)})") from None


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """(T, 4) quaternions (x, y, z, w; normalised here) -> (T, 3, 3) rotation matrices."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q).as_matrix()


@dataclass
class _Channel:
    node: int
    path: str  # translation | rotation | scale | weights
    times: np.ndarray  # (K,)
    values: np.ndarray  # (K, n) or, CUBICSPLINE, (K, 3, n): in-tangent, value, out-tangent
    interpolation: str

    def sample(self, t: np.ndarray) -> np.ndarray:
        """The channel's value at each of the (T,) times -> (T, n)."""
        keys = self.times
        cubic = self.interpolation == "CUBICSPLINE"
        points = self.values[:, 1] if cubic else self.values
        if len(keys) == 1:
            return np.repeat(points[:1], len(t), axis=0)
        tc = np.clip(t, keys[0], keys[-1])
        k = np.clip(np.searchsorted(keys, tc, side="right") - 1, 0, len(keys) - 2)
        dt = keys[k + 1] - keys[k]
        u = np.where(dt > 0, (tc - keys[k]) / np.where(dt > 0, dt, 1.0), 0.0)
        if self.interpolation == "STEP":
            return np.where((tc >= keys[-1])[:, None], points[-1], points[k])
        if cubic:
            u2, u3 = u * u, u * u * u
            h = [2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2]
            out = (
                h[0][:, None] * points[k]
                + (h[1] * dt)[:, None] * self.values[k, 2]
                + h[2][:, None] * points[k + 1]
                + (h[3] * dt)[:, None] * self.values[k + 1, 0]
            )
            if self.path == "rotation":
                out /= np.linalg.norm(out, axis=-1, keepdims=True)
            return out
        if self.path == "rotation":  # shortest-arc slerp between the keys
            from scipy.spatial.transform import Rotation, Slerp

            return Slerp(keys, Rotation.from_quat(points))(tc).as_quat()
        return points[k] + u[:, None] * (points[k + 1] - points[k])


@dataclass
class _Primitive:
    positions: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) local indices
    targets: np.ndarray  # (M, V, 3) morph target position deltas
    joints: np.ndarray | None  # (V, K) joint slots of the skin
    weights: np.ndarray | None  # (V, K), rows summing to one
    uvs: np.ndarray | None  # (V, 2) TEXCOORD_0


@dataclass
class GltfInstance:
    """One mesh node of the scene: which node and mesh, and its primitives' vertex range in the scene's arrays."""

    node: int
    mesh: int
    name: str
    start: int
    stop: int


class GltfScene:
    """The meshes of a glTF file's default scene, evaluated at rest or along an animation (see the module doc)."""

    def __init__(self, doc: dict, buffers: list[bytes], name: str = "glTF") -> None:
        self.doc, self.name = doc, name
        self._buffers = buffers
        required = [e for e in doc.get("extensionsRequired") or [] if not str(e).startswith(_HARMLESS_PREFIXES)]
        if required:
            raise GltfError(
                f"{name}: the file needs {', '.join(map(str, required))} (compressed geometry or instancing), which "
                "garsim cannot read; export it without compression"
            )
        self.nodes: list[dict] = doc.get("nodes") or []
        scenes = doc.get("scenes") or []
        roots = scenes[int(doc.get("scene", 0))].get("nodes", []) if scenes else self._root_nodes()
        self._order: list[tuple[int, int]] = []  # (node, parent) depth-first, parents first
        stack = [(int(i), -1) for i in reversed(roots)]
        seen: set[int] = set()
        while stack:
            i, parent = stack.pop()
            if i in seen or not 0 <= i < len(self.nodes):
                raise GltfError(f"{name}: node {i} is listed twice or does not exist (the node tree is broken)")
            seen.add(i)
            self._order.append((i, parent))
            stack.extend((int(c), i) for c in reversed(self.nodes[i].get("children", [])))
        self._in_scene = {i for i, _ in self._order}
        self._prims: list[tuple[int, _Primitive]] = []  # (node, primitive) in scene order
        self.instances: list[GltfInstance] = []
        start = 0
        for i, _ in self._order:
            if "mesh" not in self.nodes[i]:
                continue
            m = int(self.nodes[i]["mesh"])
            mesh = doc["meshes"][m]
            skin = self.nodes[i].get("skin")
            prims = [self._primitive(p, skin is not None) for p in mesh.get("primitives", [])]
            prims = [p for p in prims if p is not None]
            n = sum(len(p.positions) for p in prims)
            self._prims.extend((i, p) for p in prims)
            self.instances.append(
                GltfInstance(i, m, str(mesh.get("name") or self.nodes[i].get("name", "")), start, start + n)
            )
            start += n
        if not self._prims:
            raise GltfError(f"{name}: the scene has no triangle mesh (only points, lines or empty nodes)")
        offsets = np.cumsum([0] + [len(p.positions) for _, p in self._prims])
        rest = self._worlds({}, 1)
        mirrored = [  # a node whose transform mirrors (negative determinant) shows its triangles' other side
            "skin" not in self.nodes[i] and np.linalg.det(rest[i][0, :3, :3]) < 0 for i, _ in self._prims
        ]
        self.faces = np.concatenate(
            [(p.faces[:, ::-1] if flip else p.faces) + o for (_, p), o, flip in zip(self._prims, offsets, mirrored)]
        ).astype(np.int64)
        uv = [p.uvs for _, p in self._prims]
        self.uvs = (  # a primitive without texture coordinates gets (0, 0), as a viewer samples it
            None
            if all(u is None for u in uv)
            else np.concatenate(
                [np.zeros((len(p.positions), 2)) if u is None else u for (_, p), u in zip(self._prims, uv)]
            )
        )
        self.animations: list[str] = [
            str(a.get("name") or f"animation {k}") for k, a in enumerate(doc.get("animations") or [])
        ]

    # ------------------------------------------------------------------ reading

    @classmethod
    def read(cls, path: str | Path) -> GltfScene:
        """Read a .glb or .gltf file (its buffers too)."""
        p = Path(path)
        doc, chunk = _read_container(p)
        buffers = [_buffer(p, doc, k, chunk) for k in range(len(doc.get("buffers") or []))]
        try:
            return cls(doc, buffers, name=str(p))
        except (KeyError, IndexError, TypeError) as exc:
            raise GltfError(f"{p}: the glTF document is malformed ({type(exc).__name__}: {_first_line(exc)})") from None

    def _root_nodes(self) -> list[int]:
        children = {int(c) for n in self.nodes for c in n.get("children", [])}
        return [i for i in range(len(self.nodes)) if i not in children]

    def _accessor(self, index: int) -> np.ndarray:
        """Accessor ``index`` as float64 (normalised integers scaled) or its integers, shape (count, width)."""
        acc = self.doc["accessors"][int(index)]
        ctype = int(acc["componentType"])
        dtype = np.dtype(_DTYPES[ctype])
        width = _WIDTHS[acc["type"]]
        count = int(acc["count"])
        if "bufferView" in acc:
            out = np.array(self._view(acc["bufferView"], acc.get("byteOffset", 0), dtype, count, width))
        else:
            out = np.zeros((count, width), dtype=dtype)
        sparse = acc.get("sparse")
        if sparse:
            n = int(sparse["count"])
            idx = sparse["indices"]
            rows = self._view(
                idx["bufferView"], idx.get("byteOffset", 0), np.dtype(_DTYPES[int(idx["componentType"])]), n, 1
            )
            vals = self._view(sparse["values"]["bufferView"], sparse["values"].get("byteOffset", 0), dtype, n, width)
            out = out.copy()
            out[rows[:, 0].astype(np.int64)] = vals
        if acc.get("normalized") and ctype in _NORMALISED_MAX:
            return np.maximum(out.astype(np.float64) / _NORMALISED_MAX[ctype], -1.0)
        return out.astype(np.float64) if dtype.kind == "f" else out

    def _view(self, view_index: int, offset: int, dtype: np.dtype, count: int, width: int) -> np.ndarray:
        view = self.doc["bufferViews"][int(view_index)]
        blob = self._buffers[int(view.get("buffer", 0))]
        start = int(view.get("byteOffset", 0)) + int(offset)
        stride = int(view.get("byteStride", 0)) or dtype.itemsize * width
        end = start + (count - 1) * stride + dtype.itemsize * width if count else start
        if end > len(blob) or start < 0:
            raise GltfError(f"{self.name}: an accessor reads past the end of its buffer (a truncated file?)")
        return np.ndarray((count, width), dtype=dtype, buffer=blob, offset=start, strides=(stride, dtype.itemsize))

    def _primitive(self, prim: dict, skinned: bool) -> _Primitive | None:
        mode = int(prim.get("mode", 4))
        if mode not in (4, 5, 6):
            return None  # points and lines show no surface
        attrs = prim.get("attributes", {})
        if "POSITION" not in attrs:
            raise GltfError(f"{self.name}: a mesh primitive has no POSITION attribute")
        pos = self._accessor(attrs["POSITION"]).astype(np.float64)  # quantised files store integers
        idx = self._accessor(prim["indices"])[:, 0].astype(np.int64) if "indices" in prim else np.arange(len(pos))
        if mode == 4:
            faces = idx[: len(idx) // 3 * 3].reshape(-1, 3)
        elif mode == 5:  # strip: every other triangle flipped to keep the winding
            k = np.arange(max(len(idx) - 2, 0))
            faces = np.stack([idx[k], idx[k + 1 + k % 2], idx[k + 2 - k % 2]], axis=1)
        else:  # fan around the first index
            k = np.arange(1, max(len(idx) - 1, 1))
            faces = np.stack([np.full(len(k), idx[0]), idx[k], idx[k + 1]], axis=1)
        if mode != 4:  # strips and fans are stitched with triangles that repeat an index: viewers draw nothing there
            faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
        if faces.size and (faces.min() < 0 or faces.max() >= len(pos)):
            raise GltfError(f"{self.name}: a face indexes vertex {int(faces.max())} of {len(pos)}")
        deltas = [
            self._accessor(t["POSITION"]) if "POSITION" in t else np.zeros_like(pos) for t in prim.get("targets", [])
        ]
        targets = np.stack(deltas).astype(np.float64) if deltas else np.zeros((0, len(pos), 3))
        joints = weights = None
        if skinned:
            sets = sorted(int(k.split("_")[1]) for k in attrs if k.startswith("JOINTS_"))
            if not sets or any(f"WEIGHTS_{s}" not in attrs for s in sets):
                raise GltfError(f"{self.name}: a skinned primitive lacks JOINTS_n / WEIGHTS_n attributes")
            joints = np.concatenate([self._accessor(attrs[f"JOINTS_{s}"]) for s in sets], axis=1).astype(np.int64)
            weights = np.concatenate([self._accessor(attrs[f"WEIGHTS_{s}"]) for s in sets], axis=1).astype(np.float64)
            total = weights.sum(axis=1, keepdims=True)
            if np.any(total <= 0):
                raise GltfError(f"{self.name}: a skinned vertex has all-zero joint weights")
            weights = weights / total
        uvs = self._accessor(attrs["TEXCOORD_0"]).astype(np.float64) if "TEXCOORD_0" in attrs else None
        return _Primitive(pos, faces, targets, joints, weights, uvs)

    def mesh_part(self, mesh: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(indices of its vertices in the scene's arrays, its own faces) of the first instance of the mesh named
        ``mesh`` (a mesh's or its node's name); None: the mesh named ``Body`` if there is one, else every mesh."""
        if mesh is None and not any("Body" in (i.name, self.nodes[i.node].get("name")) for i in self.instances):
            return np.arange(self.instances[-1].stop), self.faces
        name = "Body" if mesh is None else mesh
        inst = next((i for i in self.instances if name in (i.name, self.nodes[i.node].get("name"))), None)
        if inst is None:
            names = sorted({i.name for i in self.instances})
            raise GltfError(f"{self.name}: no mesh {name!r}; it has {', '.join(map(repr, names))}")
        return self.instance_part(inst)

    def instance_part(self, inst: GltfInstance) -> tuple[np.ndarray, np.ndarray]:
        """(indices of an instance's vertices in the scene's arrays, its own faces)."""
        own = np.all((self.faces >= inst.start) & (self.faces < inst.stop), axis=1)
        return np.arange(inst.start, inst.stop), self.faces[own] - inst.start

    # ------------------------------------------------------------------ evaluation

    def animation_index(self, animation: int | str | None) -> int:
        """The index of ``animation`` (an index or a name; None: the first); GltfError if it does not exist."""
        if not self.animations:
            raise GltfError(f"{self.name}: the file has no animation")
        if animation is None:
            return 0
        if isinstance(animation, int) or str(animation).isdigit():
            k = int(animation)
            if 0 <= k < len(self.animations):
                return k
        elif str(animation) in self.animations:
            return self.animations.index(str(animation))
        raise GltfError(f"{self.name}: no animation {animation!r}; it has {', '.join(map(repr, self.animations))}")

    def _channels(self, animation: int) -> list[_Channel]:
        anim = self.doc["animations"][animation]
        out = []
        for ch in anim.get("channels", []):
            target = ch.get("target", {})
            if "node" not in target or target.get("path") not in ("translation", "rotation", "scale", "weights"):
                continue  # pointer or other extension targets move no vertex
            if int(target["node"]) not in self._in_scene:
                continue  # a node of another scene: its keys would stretch this scene's clip
            sampler = anim["samplers"][int(ch["sampler"])]
            times = self._accessor(sampler["input"])[:, 0]
            interp = str(sampler.get("interpolation", "LINEAR")).upper()
            values = self._accessor(sampler["output"]).astype(np.float64)
            per_key = 3 if interp == "CUBICSPLINE" else 1
            values = values.reshape(len(times), per_key, -1)
            out.append(
                _Channel(int(target["node"]), target["path"], times, values if per_key == 3 else values[:, 0], interp)
            )
        return out

    def duration(self, animation: int | str | None = None) -> tuple[float, float]:
        """(first, last) key time of an animation, seconds."""
        channels = self._channels(self.animation_index(animation))
        if not channels:
            return 0.0, 0.0
        return min(float(c.times[0]) for c in channels), max(float(c.times[-1]) for c in channels)

    def sample_times(self, fps: float, animation: int | str | None = None) -> np.ndarray:
        """Times from an animation's first to its last key at ``fps`` frames per second (the last key included when
        it falls on a frame)."""
        if not fps > 0:
            raise GltfError(f"frames per second must be > 0, got {fps}")
        t0, t1 = self.duration(animation)
        n = int(np.floor((t1 - t0) * fps + 1e-3)) + 1  # key times are float32: a last key within 1e-3 frame counts
        return t0 + np.arange(n) / float(fps)

    def vertices(self, times: np.ndarray | None = None, animation: int | str | None = None) -> np.ndarray:
        """World-space vertices of every instance, concatenated: (V, 3) at rest (``times`` None: the nodes as stored),
        else (T, V, 3) at each time of ``animation``."""
        rest = times is None
        t = np.zeros(1) if rest else np.asarray(times, dtype=np.float64).reshape(-1)
        channels = [] if rest else self._channels(self.animation_index(animation))
        T = len(t)
        animated: dict[tuple[int, str], np.ndarray] = {(c.node, c.path): c.sample(t) for c in channels}
        world = self._worlds(animated, T)
        frames = []
        for node, prim in self._prims:
            weights = animated.get((node, "weights"))
            if weights is None:
                mesh = self.doc["meshes"][int(self.nodes[node]["mesh"])]
                default = self.nodes[node].get("weights", mesh.get("weights", []))
                weights = np.broadcast_to(np.asarray(default, dtype=np.float64), (T, len(default)))
            p = np.broadcast_to(prim.positions, (T, *prim.positions.shape))
            m = min(len(prim.targets), weights.shape[1])
            if m:
                p = p + np.einsum("tm,mvc->tvc", weights[:, :m], prim.targets[:m])
            skin = self.nodes[node].get("skin")
            if skin is None:
                w = world[node]
                frames.append(np.einsum("tij,tvj->tvi", w[:, :3, :3], p) + w[:, None, :3, 3])
            else:
                frames.append(self._skinned(int(skin), prim, p, world))
        out = np.concatenate(frames, axis=1)
        return out[0] if rest else out

    def _worlds(self, animated: dict[tuple[int, str], np.ndarray], T: int) -> dict[int, np.ndarray]:
        """Every scene node's (T, 4, 4) world matrix, parents first."""
        world: dict[int, np.ndarray] = {}
        for i, parent in self._order:
            world[i] = self._local(i, animated, T) if parent < 0 else world[parent] @ self._local(i, animated, T)
        return world

    def frames(self, fps: float, animation: int | str | None = None) -> np.ndarray:
        """(T, V, 3) vertices sampled at ``fps`` over ``animation`` (default: the first)."""
        return self.vertices(self.sample_times(fps, animation), animation)

    def _local(self, i: int, animated: dict[tuple[int, str], np.ndarray], T: int) -> np.ndarray:
        node = self.nodes[i]
        if "matrix" in node:  # a node with a matrix cannot be animated (glTF 2.0, 5.25)
            m = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # stored column by column
            return np.broadcast_to(m, (T, 4, 4))

        def part(name: str, default: list[float]) -> np.ndarray:
            a = animated.get((i, name))
            return (
                a
                if a is not None
                else np.broadcast_to(np.asarray(node.get(name, default), dtype=np.float64), (T, len(default)))
            )

        m = np.zeros((T, 4, 4))
        m[:, :3, :3] = _quat_matrix(part("rotation", [0.0, 0.0, 0.0, 1.0])) * part("scale", [1.0, 1.0, 1.0])[:, None, :]
        m[:, :3, 3] = part("translation", [0.0, 0.0, 0.0])
        m[:, 3, 3] = 1.0
        return m

    def _skinned(self, skin: int, prim: _Primitive, p: np.ndarray, world: dict[int, np.ndarray]) -> np.ndarray:
        spec = self.doc["skins"][skin]
        joints = [int(j) for j in spec["joints"]]
        missing = [j for j in joints if j not in world]
        if missing:
            raise GltfError(f"{self.name}: skin {skin}'s joint nodes {missing[:5]} are not in the scene")
        if "inverseBindMatrices" in spec:
            ibm = self._accessor(spec["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
        else:
            ibm = np.broadcast_to(np.eye(4), (len(joints), 4, 4))
        if prim.joints.size and prim.joints.max() >= len(joints):
            raise GltfError(
                f"{self.name}: a vertex names joint slot {int(prim.joints.max())} of skin {skin}'s {len(joints)}"
            )
        from garsim.geometry.skinning import apply_transforms, blended_transforms, dense_weights

        mats = np.stack([world[j] for j in joints], axis=1) @ ibm  # (T, J, 4, 4)
        dense = dense_weights(prim.joints, prim.weights, len(joints))
        return np.stack([apply_transforms(p[k], blended_transforms(dense, mats[k])) for k in range(len(p))])
