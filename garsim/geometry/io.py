"""Triangle-mesh I/O that preserves vertex order, with validation: OBJ read and written here (vectorised, no
trimesh import: a cold ``garsim drape`` is faster by its ~0.5 s), glTF read by :mod:`garsim.geometry.gltf_scene`, the
other formats through trimesh.

Every mesh that enters garsim goes through :func:`validate_mesh`, which either returns clean
``float32 (V, 3)`` vertices and ``int64 (F, 3)`` faces or raises a one-line :class:`MeshError`
saying what is wrong and how to fix it.

Checks (errors): no vertices, no faces, NaN/inf coordinates, face indices out of range,
degenerate faces (a repeated vertex index, or zero area).
Repairs (documented, silent): polygons with more than three corners are triangulated
(trimesh does it on load for OBJ/PLY/OFF; :func:`validate_mesh` fan-triangulates an
``(F, k > 3)`` face array); unreferenced vertices are kept, so indices never shift.

Vertex order: OBJ vertices are kept in file order; other files are read with ``process=False`` (no merging, no
reordering); an OBJ the vectorised reader cannot take (odd tokens) goes to trimesh with ``maintain_order=True``.
Relative (negative) indices, a UTF-8 byte-order mark and ``\\r`` line ends read as in a plain file (``obj_bytes``). A
glTF is read as it shows, by :mod:`garsim.geometry.gltf_scene` (node transforms, skins and morph-target weights
applied; its meshes in depth-first node order); :func:`load_mesh_animation` samples its animation. A USD stage is
read by :mod:`garsim.geometry.usd_stage` (every mesh at the earliest time, skins applied, in traversal order) in its
own declared axis and unit (``usd_stage.read_usd_mesh(..., z_up_metres=True)`` converts).
STL stores a triangle soup without shared vertices; it is merged on load (the order is then the order of first
appearance) and cannot round-trip vertex order.

Surface attributes: :func:`load_mesh_with_attributes` also returns a :class:`MeshAttributes`: an OBJ's texture
coordinates (``vt``) and normals (``vn``) with their own per-corner indices (UV seams, hard edges: more ``vt`` than
``v``), or a GLB's / PLY's per-vertex UVs. ``save_mesh(..., attributes=...)`` writes them back: OBJ with the same
``vt``/``vn`` lists and face indices, GLB/PLY per-vertex UVs when the UVs have no seams (OFF/STL have no UVs).
:meth:`MeshAttributes.recompute_normals` re-derives the normals of a moved mesh, split where the input's were.

Axes: garsim works in metres with Z up and the body facing -Y. glTF and Blender's importers use
Y up; ``save_mesh(..., y_up=True)`` rotates Z-up -> Y-up ((x, y, z) -> (x, z, -y), so the body
faces +Z as glTF expects) and ``load_mesh(..., y_up=True)`` rotates back.
"""

from __future__ import annotations

import io
import itertools
import json
import logging
import os
import re
import sys
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.gltf_scene import GltfError, GltfScene
from garsim.geometry.mesh import face_areas

log = logging.getLogger(__name__)

USD_EXTENSIONS: tuple[str, ...] = (".usd", ".usda", ".usdc", ".usdz")
SUPPORTED_EXTENSIONS: tuple[str, ...] = (".obj", ".ply", ".glb", ".gltf", ".off", ".stl", *USD_EXTENSIONS)
"""File types :func:`load_mesh` reads; :func:`save_mesh` writes all but ``.gltf`` and USD (``garsim.export`` writes
USD)."""
_READ_ONLY: tuple[str, ...] = (".gltf", *USD_EXTENSIONS)

DEGENERATE_AREA_RTOL = 1e-12
"""A face is degenerate when its area is below this times the squared bounding-box diagonal."""

# Z-up (garsim) -> Y-up (glTF/Blender): rotate -90 degrees about X.
_Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


class MeshError(ValueError):
    """A mesh (file or arrays) that garsim cannot use; the message says what to fix."""


def z_up_to_y_up(vertices: np.ndarray) -> np.ndarray:
    """Rotate Z-up points to Y-up ((x, y, z) -> (x, z, -y)); the body's front -Y becomes +Z."""
    v = np.asarray(vertices)
    return (v @ _Z_TO_Y.T).astype(v.dtype, copy=False)


def y_up_to_z_up(vertices: np.ndarray) -> np.ndarray:
    """Inverse of :func:`z_up_to_y_up` ((x, y, z) -> (x, -z, y))."""
    v = np.asarray(vertices)
    return (v @ _Z_TO_Y).astype(v.dtype, copy=False)


UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}
"""Length units accepted at the API boundary (metres per unit)."""


def to_internal(vertices: np.ndarray, up: str = "z", units: str = "m") -> np.ndarray:
    """User coordinates (``up`` axis, ``units``) -> garsim's (metres, Z up), float64."""
    if up not in ("z", "y"):
        raise ValueError(f"up must be 'z' or 'y', got {up!r}")
    if units not in UNITS:
        raise ValueError(f"units must be one of {', '.join(UNITS)}, got {units!r}")
    v = np.asarray(vertices, dtype=np.float64) * UNITS[units]
    return y_up_to_z_up(v) if up == "y" else v


def from_internal(vertices: np.ndarray, up: str = "z", units: str = "m") -> np.ndarray:
    """Inverse of :func:`to_internal` (garsim's metres, Z up -> the user's axis and units)."""
    v = z_up_to_y_up(np.asarray(vertices, dtype=np.float64)) if up == "y" else np.asarray(vertices, dtype=np.float64)
    return v / UNITS[units]


def triangulate_polygons(faces: np.ndarray) -> np.ndarray:
    """Fan-triangulate an (F, k >= 3) polygon array into (F * (k - 2), 3) triangles, face by face."""
    f = np.asarray(faces)
    k = f.shape[1]
    if k == 3:
        return f
    fans = [f[:, [0, j, j + 1]] for j in range(1, k - 1)]
    return np.stack(fans, axis=1).reshape(-1, 3)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _as_array(x: Any, name: str, what: str) -> np.ndarray:
    """``np.asarray`` that turns ragged or unconvertible input into a MeshError."""
    try:
        return np.asarray(x)
    except (TypeError, ValueError, OverflowError) as exc:
        raise MeshError(f"{name}: {what} ({_first_line(exc)})") from None


def zero_area_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) mask of the faces whose area is below ``DEGENERATE_AREA_RTOL`` x the squared bounding-box diagonal."""
    v = np.asarray(vertices, np.float64)
    area2 = 2.0 * face_areas(v, np.asarray(faces, np.int64))
    diag2 = float(np.sum((v.max(axis=0) - v.min(axis=0)) ** 2))
    return area2 <= 2.0 * DEGENERATE_AREA_RTOL * max(diag2, 1e-30)


def validate_mesh(vertices: Any, faces: Any, name: str = "mesh") -> tuple[np.ndarray, np.ndarray]:
    """Check and normalise a triangle mesh -> (float32 (V, 3) vertices, int64 (F, 3) faces).

    Raises :class:`MeshError` naming ``name`` for: no vertices/faces, wrong shapes, NaN/inf
    coordinates, out-of-range indices, degenerate faces. ``(F, k > 3)`` polygons are fan-triangulated.
    """
    raw = _as_array(vertices, name, "vertices are not a numeric (V, 3) array")
    if raw.dtype.kind not in "biufO":  # complex, dates, strings: nothing to measure in metres
        raise MeshError(f"{name}: vertices must be real numbers, got dtype {raw.dtype}")
    try:
        v = raw.astype(np.float64)
    except (TypeError, ValueError, OverflowError) as exc:
        raise MeshError(f"{name}: vertices are not a numeric (V, 3) array ({_first_line(exc)})") from None
    if v.size == 0:
        raise MeshError(f"{name}: the mesh has no vertices; check the file is a non-empty triangle mesh")
    if v.ndim != 2 or v.shape[1] != 3:
        raise MeshError(f"{name}: vertices must have shape (V, 3), got {v.shape}")
    with np.errstate(over="ignore", invalid="ignore"):  # float32 overflow is reported as inf just below
        bad = ~np.isfinite(v.astype(np.float32)).all(axis=1)
    if bad.any():
        first = np.flatnonzero(bad)[:5].tolist()
        raise MeshError(
            f"{name}: {int(bad.sum())} vertices have NaN/inf coordinates (or beyond float32 range; first indices "
            f"{first}); fix or remove them before loading"
        )
    f = _as_array(faces, name, "faces are not an integer (F, 3) array")
    if f.size == 0:
        raise MeshError(f"{name}: the mesh has no faces (a point cloud?); garsim needs a triangle mesh")
    if f.ndim != 2:
        raise MeshError(
            f"{name}: faces must be an (F, 3) integer array (mixed polygon sizes are not supported), "
            f"got shape {f.shape}"
        )
    if f.dtype == object:  # e.g. Python ints in an object array; None or text is not an index
        try:
            f = f.astype(np.float64)
        except (TypeError, ValueError, OverflowError):
            raise MeshError(f"{name}: face indices must be integers, got {f.dtype} values") from None
    if f.dtype.kind not in "iuf":  # bool, complex, dates, strings
        raise MeshError(f"{name}: face indices must be integers, got dtype {f.dtype}")
    if f.dtype.kind == "f" and (not np.all(np.isfinite(f)) or not np.all(f == np.round(f))):
        raise MeshError(f"{name}: face indices must be integers")
    if f.shape[1] < 3:
        raise MeshError(f"{name}: faces must have at least 3 corners, got shape {f.shape}")
    oob = (f < 0) | (f >= len(v))  # before the int64 cast, so huge indices are not wrapped
    if oob.any():
        rows = np.flatnonzero(oob.any(axis=1))
        first = (
            [int(i) if abs(i) < 2**63 else i for i in f[rows[0]].tolist()]
            if f.dtype.kind == "f"
            else f[rows[0]].tolist()
        )
        raise MeshError(
            f"{name}: {len(rows)} faces reference vertices outside [0, {len(v) - 1}] (first face {int(rows[0])}: "
            f"{first}); the face indices do not match the vertex list"
        )
    f = f.astype(np.int64)
    f = triangulate_polygons(f)
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    if repeated.any():
        rows = np.flatnonzero(repeated)
        raise MeshError(
            f"{name}: {len(rows)} degenerate faces repeat a vertex index (first face {int(rows[0])}: "
            f"{f[rows[0]].tolist()}); remove them (e.g. trimesh's update_faces(nondegenerate_faces()))"
        )
    zero = zero_area_faces(v, f)
    if zero.any():
        rows = np.flatnonzero(zero)
        raise MeshError(
            f"{name}: {len(rows)} degenerate faces have zero area (first face {int(rows[0])}: "
            f"{f[rows[0]].tolist()}); remove collapsed or collinear triangles"
        )
    return v.astype(np.float32), f


def _check_path(path: str | os.PathLike, writing: bool) -> tuple[Path, str]:
    p = Path(path)
    ext = p.suffix.lower()
    allowed = tuple(e for e in SUPPORTED_EXTENSIONS if not (writing and e in _READ_ONLY))
    if ext not in allowed:
        verb = "write" if writing else "read"
        raise MeshError(f"{p}: cannot {verb} {ext or 'files without an extension'!r}; use one of {', '.join(allowed)}")
    if not writing:
        try:
            if not p.exists():
                raise MeshError(f"{p}: no such file")
            if p.is_dir():
                raise MeshError(f"{p}: is a directory, expected a mesh file")
            if p.stat().st_size == 0:
                raise MeshError(f"{p}: the file is empty; re-export the mesh")
        except (OSError, ValueError) as exc:  # permissions, a NUL byte or an over-long name
            if isinstance(exc, MeshError):
                raise
            raise MeshError(f"{p!s:.200}: cannot read the file ({_first_line(exc)})") from None
    return p, ext


_OBJ_NEEDS = {b"v": "3 coordinates", b"vn": "3 normal components", b"f": "3 vertex indices"}


def _numbers(fields: list[bytes]) -> bool:
    try:
        [float(x) for x in fields]
    except ValueError:
        return False
    return True


def _obj_candidate_lines(data: bytes) -> np.ndarray:
    """Start offsets of the lines worth a closer look: 'v' / 'vn' / 'f' lines with fewer than 4 tokens or a
    comment, and the last line. Vectorised (a few ms for a 100k-line file; a Python loop over every line
    would add a third to trimesh's own parse time)."""
    a = np.frombuffer(data, dtype=np.uint8)
    starts = np.concatenate(([0], np.flatnonzero(a == 10) + 1))
    starts = starts[starts < len(a)]
    space = (a == 32) | ((a >= 9) & (a <= 13))
    token_start = ~space & np.concatenate(([True], space[:-1]))
    tokens = np.add.reduceat(token_start.astype(np.int32), starts)
    comment = np.add.reduceat((a == 35).astype(np.int32), starts) > 0
    lead = np.flatnonzero(~((a == 32) | (a == 9) | (a == 11) | (a == 12)))  # a line's kind starts after its indent
    head = lead[np.minimum(np.searchsorted(lead, starts), len(lead) - 1)] if len(lead) else starts
    first, second = a[head], a[np.minimum(head + 1, len(a) - 1)]
    vf = ((first == ord("v")) & (second != ord("t")) & (second != ord("p"))) | (first == ord("f"))
    pick = vf & ((tokens < 4) | comment)
    pick[-1] = True
    return starts[pick]


_OBJ_V = re.compile(rb"^[ \t\x0b\x0c]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.M)  # indented lines count too
_OBJ_F = re.compile(rb"^[ \t\x0b\x0c]*f[ \t]+([^\r\n#]*)", re.M)


def fan_corners(sizes: np.ndarray) -> np.ndarray:
    """(T, 3) indices into the flat corner list of polygons with ``sizes`` (each >= 3) corners, fan-triangulated in
    order: a k-corner polygon gives the k - 2 triangles (0, j, j + 1)."""
    start = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    fans = sizes - 2
    face_of = np.repeat(np.arange(len(sizes)), fans)
    j = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans) + 1  # 1 .. k-2 within each face
    base = start[face_of]
    return np.stack([base, base + j, base + j + 1], axis=1)


def _read_obj_fast(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """(vertices, fan-triangulated faces) of a plain OBJ (``obj_bytes``' line ends), vectorised (no trimesh import,
    ~10x faster to read), or None when the file needs the general reader: corners without a vertex index, or tokens
    that are not numbers. Faces with k corners give k - 2 triangles, in file order; a negative (relative) index
    counts back from the 'v' lines above its face."""
    try:
        vertices = np.array(_OBJ_V.findall(data), dtype=np.float64).reshape(-1, 3)
        lines = [line.split() for line in _OBJ_F.findall(data)]
        lines = [line for line in lines if len(line) >= 3]
        if not lines:
            return None
        corners = b" ".join(b" ".join(line) for line in lines)
        # keep each corner's vertex index: drop "/vt/vn" tails
        flat = np.array(re.sub(rb"/[^ ]*", b"", corners).split(), dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    if flat.size == 0 or (flat == 0).any():
        return None
    if flat.min() < 0:  # relative indices (-1: the last 'v' line above the face): the attribute reader resolves them
        faces = _obj_corners(_obj_plain_text(data))[:, :, 0]
        return None if len(faces) == 0 or faces.min() < 0 else (vertices, faces)
    sizes = np.fromiter((len(line) for line in lines), dtype=np.int64, count=len(lines))
    return vertices, flat[fan_corners(sizes)] - 1


def _read_file(p: Path) -> bytes:
    """The bytes of ``p``; a read error is a MeshError."""
    try:
        return p.read_bytes()
    except OSError as exc:
        raise MeshError(f"{p}: cannot read the file ({_first_line(exc)})") from None


def natural_order(paths: Iterable[Path]) -> list[Path]:
    """``paths`` sorted by name with runs of digits compared as numbers (``frame_2`` before ``frame_10``, as frame
    numbers without zero padding mean), case-insensitively; ties by the plain name."""

    def key(p: Path) -> tuple[list[tuple[int, int | str]], str]:
        return [(1, int(t)) if t.isdigit() else (0, t.lower()) for t in re.split(r"(\d+)", p.name)], p.name

    return sorted(paths, key=key)


_BOM = b"\xef\xbb\xbf"


def obj_bytes(data: bytes) -> bytes:
    """An OBJ file's bytes as the readers take them: a UTF-8 byte-order mark dropped (else the first 'v' line is not
    seen and every index shifts by one) and ``\\r\\n`` or old Mac ``\\r`` line ends made ``\\n``."""
    if data.startswith(_BOM):
        data = data[len(_BOM) :]
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return data


def _check_obj_lines(p: Path, data: bytes) -> None:
    """Refuse OBJ 'v' / 'vn' / 'f' lines with fewer than 3 fields, which trimesh would silently drop or misread.

    An incomplete last line (too few fields, or a number cut short) means the file was cut off: the message
    says it is truncated."""
    data = data.rstrip()
    if not data:
        return
    for start in _obj_candidate_lines(data).tolist():
        end = data.find(b"\n", start)
        is_last = end < 0
        line = data[start:] if is_last else data[start:end]
        fields = (line.split(b"#", 1)[0] if b"#" in line else line).split()
        kind = fields[0] if fields else b""
        if kind not in _OBJ_NEEDS:  # vt, vp, ...
            continue
        if len(fields) >= 4 and (not is_last or kind == b"f" or _numbers(fields[1:4])):
            continue
        n = data.count(b"\n", 0, start) + 1
        shown = line.decode("utf-8", errors="replace").strip()[:60]
        need = _OBJ_NEEDS[kind]
        if is_last:
            raise MeshError(
                f"{p}: the file is truncated: its last line {n} {shown!r} is incomplete "
                f"(a '{kind.decode()}' line needs {need}); re-export the mesh"
            )
        raise MeshError(f"{p}: line {n} {shown!r} is malformed: a '{kind.decode()}' line needs {need}")


def _check_obj_numbers(p: Path, data: bytes) -> None:
    """Raise MeshError naming the first 'v' line whose coordinates are not numbers (e.g. decimal commas)."""
    for match in _OBJ_V.finditer(data):  # only after a failed read: the loop ends at the first bad line
        if not _numbers(list(match.groups())):
            line = data[match.start() : data.find(b"\n", match.start()) % (len(data) + 1)]
            shown = line.decode("utf-8", errors="replace").strip()[:60]
            n = data.count(b"\n", 0, match.start()) + 1
            raise MeshError(f"{p}: line {n} {shown!r} is malformed: a 'v' line needs 3 numbers (with decimal points)")


@dataclass(frozen=True)
class MeshAttributes:
    """Texture coordinates and normals of a triangle mesh, each list with its own (F, 3) corner indices.

    ``uvs`` (K, 2) float64 and ``uv_faces`` (F, 3) int64: corner j of face i has UV ``uvs[uv_faces[i, j]]``, in
    the order of the mesh's (triangulated) faces; K may exceed the vertex count (UV seams). Likewise ``normals``
    (M, 3) and ``normal_faces`` (F, 3). Each list and its indices are both None or both set. Per-vertex
    attributes have ``uv_faces`` (or ``normal_faces``) equal to the mesh's faces. An OBJ's ``vt`` w component is
    not kept.
    """

    uvs: np.ndarray | None = None
    uv_faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    normal_faces: np.ndarray | None = None

    @property
    def empty(self) -> bool:
        return self.uvs is None and self.normals is None

    def check(self, num_faces: int, name: str = "attributes") -> MeshAttributes:
        """Raise :class:`MeshError` unless every list is finite and its indices are (num_faces, 3) and in range."""
        for what, values, idx, width in (
            ("UVs", self.uvs, self.uv_faces, 2),
            ("normals", self.normals, self.normal_faces, 3),
        ):
            if (values is None) != (idx is None):
                raise MeshError(f"{name}: {what} and their face indices go together; give both or neither")
            if values is None:
                continue
            if values.ndim != 2 or values.shape[1] != width or not np.isfinite(values).all():
                raise MeshError(f"{name}: {what} must be finite, shape (K, {width}), got {values.shape}")
            if idx.shape != (num_faces, 3):
                raise MeshError(
                    f"{name}: {what} face indices have shape {idx.shape}; the mesh has {num_faces} triangles"
                )
            if idx.size and (idx.min() < 0 or idx.max() >= len(values)):
                raise MeshError(f"{name}: {what} face indices outside [0, {len(values) - 1}]")
        return self

    def vertex_uvs(self, faces: np.ndarray, num_vertices: int) -> np.ndarray | None:
        """(N, 2) one UV per vertex (0 for a vertex no face uses), or None: no UVs, or seams (a vertex with two)."""
        if self.uvs is None:
            return None
        f, t = np.asarray(faces).ravel(), self.uv_faces.ravel()
        per = np.zeros(num_vertices, dtype=np.int64)
        used = np.zeros(num_vertices, dtype=bool)
        per[f], used[f] = t, True
        if not np.array_equal(self.uvs[per[f]], self.uvs[t]):
            return None
        out = self.uvs[per]
        out[~used] = 0.0
        return out

    def recompute_normals(self, vertices: np.ndarray, faces: np.ndarray) -> MeshAttributes:
        """These attributes with the normals of the mesh moved to ``vertices``: each normal the area-weighted mean
        of the face normals at the corners that use it (normals split at hard edges stay split), oriented as the
        old ones (flipped when they mostly disagree). A normal no corner uses keeps its value."""
        if self.normals is None:
            return self
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces)
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        idx, w = self.normal_faces.ravel(), np.repeat(fn, 3, axis=0)
        acc = np.stack([np.bincount(idx, weights=w[:, c], minlength=len(self.normals)) for c in range(3)], axis=1)
        length = np.linalg.norm(acc, axis=1)
        ok = length > 0
        new = np.array(self.normals, dtype=np.float64)
        new[ok] = acc[ok] / length[ok, None]
        if np.sum(new[ok] * self.normals[ok]) < 0:  # the old normals pointed the other way round the winding
            new[ok] *= -1.0
        return replace(self, normals=new)

    def rotated(self, rotate: Any) -> MeshAttributes:
        """The normals turned by ``rotate`` (e.g. :func:`z_up_to_y_up`) as the vertices are; UVs unchanged."""
        return self if self.normals is None else replace(self, normals=rotate(self.normals))


_OBJ_LINE = rb"\n[ \t\x0b\x0c]*"  # a line's start in _obj_plain_text, up to its first field
_OBJ_KIND = re.compile(_OBJ_LINE + rb"(vt|vn|v|f)(?!\S)")
_OBJ_FACE = re.compile(_OBJ_LINE + rb"f(?!\S)([^\n]*)")
_OBJ_NUMBERS = {b"vt": (1, 2), b"vn": (3, 3)}
"""Attribute line kind -> (numbers it needs, numbers kept): a ``vt`` w and a second ``vt`` number are optional."""
_OBJ_VALUES = {
    kind: re.compile(_OBJ_LINE + kind + rb"(?!\S)" + rb"[ \t\x0b\x0c]*(\S*)" * keep)
    for kind, (_, keep) in _OBJ_NUMBERS.items()
}


def _obj_plain_text(data: bytes) -> bytes:
    """OBJ text for the attribute patterns: ``\\n`` line ends only (the lines ``bytes.splitlines`` sees), comments
    removed, and a leading ``\\n`` so that every line starts after one (a literal the regex engine finds fast)."""
    data = obj_bytes(data)
    return b"\n" + (re.sub(rb"#[^\n]*", b"", data) if b"#" in data else data)


def _parses(field: bytes, dtype: type) -> bool:
    """Whether one OBJ field casts to ``dtype``."""
    try:
        np.array(field).astype(dtype)
    except (ValueError, OverflowError):
        return False
    return True


def _parse_fields(fields: np.ndarray, dtype: type) -> tuple[np.ndarray, np.ndarray]:
    """A bytes array of OBJ fields (empty read as 0) -> (the numbers as ``dtype``, mask of the fields that parse);
    vectorised, field by field (Python's ``int``/``float`` rules, as numpy's cast) only when some field does not."""
    padded = np.where(fields == b"", b"0", fields)
    try:
        return padded.astype(dtype), np.ones(fields.shape, dtype=bool)
    except (ValueError, OverflowError):
        ok = np.array([_parses(x, dtype) for x in padded.ravel()], dtype=bool).reshape(fields.shape)
        values = np.zeros(fields.shape, dtype=dtype)
        values[ok] = padded[ok].astype(dtype)
        return values, ok


def _obj_values(text: bytes, kind: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The (K, keep) float64 rows of the ``vt`` or ``vn`` lines (absent optional numbers 0) and the (K,) mask of the
    malformed ones: too few numbers, or one that does not parse or is not finite."""
    need, keep = _OBJ_NUMBERS[kind]
    fields = np.array(_OBJ_VALUES[kind].findall(text), dtype=bytes).reshape(-1, keep)
    values, ok = _parse_fields(fields, np.float64)
    return values, (fields[:, need - 1] == b"") | ~(ok & np.isfinite(values)).all(axis=1)


def _check_obj_values(text: bytes, bad: dict[bytes, np.ndarray], p: Path) -> None:
    """Raise MeshError for the first malformed ``vt``/``vn`` line in the file (``bad``: each kind's malformed rows)."""
    starts = {
        kind: next(itertools.islice(_OBJ_VALUES[kind].finditer(text), int(np.argmax(rows)), None)).start()
        for kind, rows in bad.items()
        if rows.any()
    }
    if not starts:
        return
    kind = min(starts, key=starts.__getitem__)
    start = starts[kind] + 1  # past the newline the match starts with
    end = text.find(b"\n", start)
    shown = b" ".join(text[start : end if end >= 0 else None].split()[1:]).decode("utf-8", errors="replace")[:60]
    lineno = text.count(b"\n", 0, start)
    k = kind.decode()
    raise MeshError(
        f"{p}: line {lineno} '{k} {shown}' is malformed: a '{k}' line needs {_OBJ_NUMBERS[kind][0]} finite numbers"
    )


def _obj_corners(text: bytes) -> np.ndarray:
    """(T, 3 corners, v/vt/vn) 0-based indices of the fan-triangulated ``f`` lines, -1 where a corner has no such
    index; a negative index counts back from the lines read so far. Lines with fewer than 3 corners, or a corner
    that is not integers, are skipped (the mesh reader has already read or refused them)."""
    rests = _OBJ_FACE.findall(text)
    sizes = np.fromiter((len(r.split()) for r in rests), dtype=np.int64, count=len(rests))
    heads, rest = [], np.array(b" ".join(rests).split(), dtype=bytes)
    for _ in range(3):  # "v/vt/vn" -> v, vt, vn (each possibly empty; a 4th field and beyond dropped)
        head, _, rest = np.moveaxis(np.char.partition(rest, b"/"), -1, 0)
        heads.append(head)
    fields = np.stack(heads, axis=1)
    raw, ok = _parse_fields(fields, np.int64)
    line_of = np.repeat(np.arange(len(rests)), sizes)
    good = (sizes >= 3) & (np.bincount(line_of, weights=~ok.all(axis=1), minlength=len(rests)) == 0)
    absent = fields == b""
    if (raw[~absent] <= 0).any():  # relative indices: count the v/vt/vn lines above each f line
        kinds = np.array(_OBJ_KIND.findall(text))
        seen = np.stack([np.cumsum(kinds == k) for k in (b"v", b"vt", b"vn")], axis=1)[kinds == b"f"]
        raw = np.where(raw > 0, raw, seen[line_of] + raw + 1)
    idx = np.where(absent, -1, raw - 1)
    return idx[good[line_of]][fan_corners(sizes[good])]


def _corner_map(src: np.ndarray, dst: np.ndarray) -> np.ndarray | None:
    """For each corner of ``dst`` (F, 3), the flat index of the same corner in ``src``: the two hold the same
    triangles up to row order and a cyclic turn of each row (trimesh triangulates quads in its own order); None
    when they do not."""
    if src.shape != dst.shape:
        return None
    if np.array_equal(src, dst):
        return np.arange(src.size).reshape(src.shape)

    def canonical(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cols = (np.argmin(a, axis=1)[:, None] + np.arange(3)) % 3
        return np.take_along_axis(a, cols, axis=1), cols

    cs, cols_s = canonical(src)
    cd, cols_d = canonical(dst)
    rows_s, rows_d = np.lexsort(cs.T[::-1]), np.lexsort(cd.T[::-1])
    if not np.array_equal(cs[rows_s], cd[rows_d]):
        return None
    out = np.empty(dst.shape, dtype=np.int64)
    out[rows_d[:, None], cols_d[rows_d]] = rows_s[:, None] * 3 + cols_s[rows_s]
    return out


def _read_obj_attributes(data: bytes, p: Path, faces: np.ndarray) -> MeshAttributes:
    """The ``vt``/``vn`` lists of an OBJ (its bytes ``data``) and their corner indices, fan-triangulated and matched
    to ``faces`` (the mesh reader's triangles of the same file). Raises MeshError for malformed or out-of-range
    ``vt``/``vn`` data."""
    if b"vt" not in data and b"vn" not in data:
        return MeshAttributes()
    text = _obj_plain_text(data)
    (uvs, bad_uvs), (normals, bad_normals) = _obj_values(text, b"vt"), _obj_values(text, b"vn")
    _check_obj_values(text, {b"vt": bad_uvs, b"vn": bad_normals}, p)
    c = _obj_corners(text)
    if not len(c):
        return MeshAttributes()
    where = _corner_map(c[:, :, 0], faces)
    if where is None:
        log.warning("%s: the faces' texture/normal indices could not be matched to the triangles; dropped", p)
        return MeshAttributes()
    out: dict[str, np.ndarray | None] = {}
    for name, values, col in (("uv", uvs, 1), ("normal", normals, 2)):
        idx = c[:, :, col].reshape(-1)[where]
        out[name], out[name + "_faces"] = None, None
        if not len(values) or (idx < 0).all():
            continue
        kind = "vt" if col == 1 else "vn"
        if (idx < 0).any():
            log.warning("%s: some faces have no '%s' indices; the file's %ss are dropped", p, kind, name)
            continue
        if idx.max() >= len(values):
            row = int(np.flatnonzero((idx >= len(values)).any(axis=1))[0])
            raise MeshError(
                f"{p}: face {row} references '{kind}' {int(idx[row].max()) + 1} but the file has {len(values)} "
                f"'{kind}' lines; the face indices do not match the {name} list"
            )
        out[name], out[name + "_faces"] = values, idx
    return MeshAttributes(out["uv"], out["uv_faces"], out["normal"], out["normal_faces"])


def _load(path: str | os.PathLike, y_up: bool, attributes: bool) -> tuple[np.ndarray, np.ndarray, MeshAttributes]:
    p, ext = _check_path(path, writing=False)
    kwargs: dict[str, Any] = {"process": False}
    plain, data = None, b""
    if ext == ".obj":
        data = obj_bytes(_read_file(p))
        _check_obj_lines(p, data)
        kwargs.update(maintain_order=True, skip_materials=True)
        plain = _read_obj_fast(data)
    elif ext in (".glb", ".gltf"):
        scene = _gltf_scene(p)
        plain = scene.vertices(), scene.faces
    elif ext in USD_EXTENSIONS:
        from garsim.geometry.usd_stage import read_usd_mesh

        *plain, usd_attrs = read_usd_mesh(p)
    if plain is not None:
        loaded, (vertices, faces) = None, plain
        if faces.size and faces.max() >= len(vertices):
            raise MeshError(
                f"{p}: could not parse the {ext} file: face index {int(faces.max()) + 1} but only {len(vertices)} "
                "vertices (faces reference vertices that do not exist)"
            )
    else:
        import trimesh

        try:
            with warnings.catch_warnings():  # trimesh's UV un-merging warns on faces without texture indices
                warnings.simplefilter("ignore", RuntimeWarning)
                source = (io.BytesIO(data), "obj") if ext == ".obj" else (str(p), None)  # OBJ: the normalised bytes
                loaded = trimesh.load(source[0], file_type=source[1], force="mesh", **kwargs)
        except Exception as exc:  # noqa: BLE001 - trimesh raises many types on malformed files
            if ext == ".obj":
                _check_obj_numbers(p, data)
            detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            if isinstance(exc, IndexError):
                detail += " (faces reference vertices that do not exist)"
            raise MeshError(f"{p}: could not parse the {ext} file: {detail}") from None
        vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))))
        faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3), dtype=np.int64)))
    if len(faces) == 0:
        raise MeshError(
            f"{p}: no triangle faces found (the file has no vertices, or only points); garsim needs a triangle mesh"
        )
    if ext == ".stl" and len(faces):
        # STL is a triangle soup: merge identical corners so the mesh is connected.
        uniq, inverse = np.unique(vertices, axis=0, return_inverse=True)
        first = np.full(len(uniq), len(vertices))
        np.minimum.at(first, inverse.ravel(), np.arange(len(vertices)))
        order = np.argsort(first)  # order of first appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        vertices, faces = uniq[order], rank[inverse.ravel()][faces]
    v, f = validate_mesh(vertices, faces, name=str(p))
    attrs = MeshAttributes()
    if attributes and ext == ".obj":
        attrs = _read_obj_attributes(data, p, f)
    elif attributes and ext in USD_EXTENSIONS:
        attrs = usd_attrs.check(len(f), str(p))
    elif attributes and ext in (".glb", ".gltf"):
        attrs = _gltf_uvs(scene.uvs, f)
    elif attributes and ext != ".stl":
        uv = getattr(getattr(loaded, "visual", None), "uv", None)
        if uv is not None and np.shape(uv) == (len(v), 2) and np.isfinite(uv).all():
            attrs = MeshAttributes(uvs=np.asarray(uv, dtype=np.float64), uv_faces=f.copy())
    if y_up:
        v = y_up_to_z_up(v)
        attrs = attrs.rotated(y_up_to_z_up)
    return v, f, attrs


def _gltf_scene(p: Path) -> GltfScene:
    try:
        return GltfScene.read(p)
    except GltfError as exc:  # its message names the file
        raise MeshError(_first_line(exc)) from None
    except OSError as exc:
        raise MeshError(f"{p}: cannot read the file ({_first_line(exc)})") from None


def load_gltf_mesh(path: str | os.PathLike, mesh: str | None) -> tuple[np.ndarray, np.ndarray, MeshAttributes]:
    """One mesh of a glTF file as stored (``mesh``: its mesh or node name; None: the mesh named ``Body``, else every
    mesh) -> validated (vertices, faces, its UVs in OBJ's convention when it has them)."""
    p, scene, index, faces = _gltf_part(path, mesh)
    v, f = validate_mesh(scene.vertices()[index], faces, name=str(p))
    return v, f, _gltf_uvs(None if scene.uvs is None else scene.uvs[index], f)


def _gltf_part(path: str | os.PathLike, mesh: str | None) -> tuple[Path, GltfScene, np.ndarray, np.ndarray]:
    """(path, scene, the vertex indices and own faces of its mesh ``mesh``) of a .glb / .gltf file."""
    p, ext = _check_path(path, writing=False)
    if ext not in (".glb", ".gltf"):
        raise MeshError(f"{p}: a mesh is picked, or an animation read, from a .glb or .gltf here (USD: usd_stage)")
    scene = _gltf_scene(p)
    try:
        return (p, scene, *scene.mesh_part(mesh))
    except ValueError as exc:
        raise MeshError(_first_line(exc)) from None


def _gltf_uvs(uvs: np.ndarray | None, faces: np.ndarray) -> MeshAttributes:
    """A glTF's per-vertex TEXCOORD_0 as attributes in OBJ's convention (glTF's v runs down the image, OBJ's up)."""
    if uvs is None:
        return MeshAttributes()
    return MeshAttributes(uvs=np.asarray(uvs, dtype=np.float64) * [1.0, -1.0] + [0.0, 1.0], uv_faces=faces.copy())


def load_mesh_animation(
    path: str | os.PathLike,
    fps: float | None,
    animation: int | str | None = None,
    y_up: bool = False,
    mesh: str | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """An animated glTF (skin, morph-target weights or node motion) sampled at ``fps`` from its first to its last
    key -> (float32 frames (T, V, 3), faces); ``fps`` None, or a file without animation: its one frame as stored.
    ``animation``: index or name (default the first); ``mesh``: the body's mesh or node name (default the mesh
    named ``Body`` if there is one, else every mesh, in :func:`load_mesh`'s order)."""
    p, scene, index, faces = _gltf_part(path, mesh)
    try:
        if animation is not None:
            scene.animation_index(animation)  # raises for a file without it
        frames = scene.frames(fps, animation) if fps is not None and scene.animations else scene.vertices()[None]
    except ValueError as exc:
        raise MeshError(_first_line(exc)) from None
    frames = frames[:, index]
    _, faces = validate_mesh(frames[0], faces, name=str(p))
    if not np.isfinite(frames).all():
        raise MeshError(f"{p}: the animation gives non-finite vertex positions (broken keys or matrices)")
    frames = frames.astype(np.float32)
    return (y_up_to_z_up(frames) if y_up else frames), faces


def load_mesh(path: str | os.PathLike, y_up: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh (OBJ/PLY/GLB/glTF/OFF/STL/USD) in file order -> validated (vertices, faces), in the
    file's coordinates (a USD stage's in its declared axis and unit).

    ``y_up=True`` converts a Y-up file (glTF/Blender) to garsim's Z-up.
    """
    v, f, _ = _load(path, y_up, attributes=False)
    return v, f


def load_mesh_with_attributes(
    path: str | os.PathLike, y_up: bool = False
) -> tuple[np.ndarray, np.ndarray, MeshAttributes]:
    """:func:`load_mesh` plus the file's UVs and normals (:class:`MeshAttributes`, empty when it has none): an
    OBJ's ``vt``/``vn`` with their per-corner indices (seams kept), a GLB's or PLY's per-vertex UVs."""
    return _load(path, y_up, attributes=True)


def _as_rgba_uint8(colors: Any, n: int) -> np.ndarray:
    c = np.asarray(colors)
    if c.ndim == 1 and c.shape[0] in (3, 4):
        c = np.broadcast_to(c, (n, c.shape[0]))
    if c.ndim != 2 or c.shape[0] != n or c.shape[1] not in (3, 4):
        raise MeshError(f"vertex_colors must have shape ({n}, 3) or ({n}, 4), got {c.shape}")
    if np.issubdtype(c.dtype, np.floating):
        if not np.isfinite(c).all() or c.min() < 0.0 or c.max() > 1.0:
            raise MeshError("float vertex_colors must be finite and in [0, 1] (or pass uint8 in [0, 255])")
        c = np.round(c * 255.0)
    c = c.astype(np.uint8)
    if c.shape[1] == 3:
        c = np.concatenate([c, np.full((n, 1), 255, dtype=np.uint8)], axis=1)
    return c


def _obj_rows(buf: Any, prefix: str, values: np.ndarray) -> None:
    """``prefix x y ...`` lines: float64 at full precision (the shortest text that reads back to the same number,
    so a file's UVs round-trip exactly), float32 with 9 significant digits (exact for float32)."""
    if values.dtype == np.float64:
        buf.writelines(f"{prefix} {' '.join(map(repr, row))}\n" for row in values.tolist())
    else:
        np.savetxt(buf, values, fmt=" ".join([prefix] + ["%.9g"] * values.shape[1]))


def obj_text(
    vertices: np.ndarray,
    faces: np.ndarray,
    attributes: MeshAttributes | None = None,
    vertex_colors: np.ndarray | None = None,
    header: str = "garsim",
) -> bytes:
    """OBJ text: one ``v`` per vertex in order (``v x y z r g b`` with colours), the ``vt``/``vn`` lists, and
    ``f v/vt/vn`` corners with 1-based indices. Arrays are taken as validated (:func:`save_mesh` checks them)."""
    import io

    buf = io.StringIO()
    buf.write(f"# {header}\n")
    v = np.asarray(vertices)
    if vertex_colors is not None:
        v = np.concatenate([v.astype(np.float64), np.asarray(vertex_colors)[:, :3] / 255.0], axis=1)
        np.savetxt(buf, v, fmt="v %.9g %.9g %.9g %.6g %.6g %.6g")
    else:
        _obj_rows(buf, "v", v)
    a = attributes or MeshAttributes()
    columns = [np.asarray(faces) + 1]
    if a.uvs is not None:
        _obj_rows(buf, "vt", a.uvs)
        columns.append(a.uv_faces + 1)
    if a.normals is not None:
        _obj_rows(buf, "vn", a.normals)
        columns.append(a.normal_faces + 1)
    corner = {1: "%d", 2: "%d/%d" if a.uvs is not None else "%d//%d", 3: "%d/%d/%d"}[len(columns)]
    np.savetxt(buf, np.stack(columns, axis=2).reshape(len(columns[0]), -1), fmt="f " + " ".join([corner] * 3))
    return buf.getvalue().encode("ascii")


OBJ_METADATA_PREFIX = "# garsim "


def read_obj_metadata(path: str | os.PathLike) -> dict[str, Any]:
    """The ``# garsim {json}`` metadata line of an OBJ written by garsim (``{}`` when the file has none)."""
    prefix = OBJ_METADATA_PREFIX.encode() + b"{"
    with open(path, "rb") as f:
        for line in itertools.islice(f, 4):  # the header's comment lines come first
            if line.startswith(prefix):
                try:
                    meta = json.loads(line[len(prefix) - 1 :])
                except ValueError:
                    return {}
                return meta if isinstance(meta, dict) else {}
    return {}


def save_mesh(
    path: str | os.PathLike,
    vertices: np.ndarray,
    faces: np.ndarray,
    vertex_colors: np.ndarray | None = None,
    y_up: bool = False,
    attributes: MeshAttributes | None = None,
    metadata: dict[str, Any] | None = None,
) -> Path:
    """Write a validated mesh atomically (temp file + rename) in vertex order; returns the path.

    ``vertex_colors``: (V, 3|4) floats in [0, 1] or uint8. ``y_up=True`` rotates Z-up -> Y-up (the vertices and
    the attributes' normals). ``attributes`` (:class:`MeshAttributes`, e.g. from :func:`load_mesh_with_attributes`):
    OBJ gets the same UV and normal lists and corner indices; GLB and PLY get per-vertex UVs when the UVs have no
    seams (with seams a warning says to write OBJ) and vertex colours, if given, take their place; OFF and STL
    have no UVs. ``metadata`` (OBJ only): a JSON dict written as the comment line ``# garsim {json}``
    (:func:`read_obj_metadata`; e.g. the axis and units the vertices are in, which ``garsim view`` reads).
    """
    p, ext = _check_path(path, writing=True)
    v, f = validate_mesh(vertices, faces, name=str(p))
    attrs = attributes.check(len(f), name=str(p)) if attributes is not None and not attributes.empty else None
    colors = None if vertex_colors is None else _as_rgba_uint8(vertex_colors, len(v))
    if y_up:
        v = z_up_to_y_up(v)
        attrs = attrs.rotated(z_up_to_y_up) if attrs is not None else None
    if ext == ".obj":
        header = "garsim" if not metadata else "garsim\n" + OBJ_METADATA_PREFIX + json.dumps(metadata, allow_nan=False)
        return atomic_write_bytes(p, obj_text(v, f, attrs, colors, header=header))
    import trimesh

    mesh = trimesh.Trimesh(vertices=v.astype(np.float64), faces=f, process=False, validate=False)
    uv = attrs.vertex_uvs(f, len(v)) if attrs is not None and ext in (".glb", ".ply") else None
    if attrs is not None and attrs.uvs is not None and uv is None and ext in (".glb", ".ply"):
        log.warning(
            "%s: the UVs have seams (a vertex with two UVs), which %s stores per vertex: dropped; "
            "write .obj to keep them",
            p,
            ext,
        )
    if colors is not None:
        mesh.visual = trimesh.visual.ColorVisuals(mesh=mesh, vertex_colors=colors)
    elif uv is not None:
        mesh.visual = trimesh.visual.TextureVisuals(uv=uv)
    data = mesh.export(file_type=ext[1:])
    return atomic_write_bytes(p, data.encode("utf-8") if isinstance(data, str) else data)


_VALIDATED = ContentCache(8, scope="garment")  # validated meshes (garments and bodies)


def _validated(vertices: Any, faces: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``validate_mesh`` cached by content (bodies are passed again with every garment); read-only arrays."""
    try:
        key = content_key(np.asarray(vertices), np.asarray(faces))
    except (TypeError, ValueError):  # ragged input: let validate_mesh say what is wrong
        return validate_mesh(vertices, faces, name=name)

    def check() -> tuple[np.ndarray, np.ndarray]:
        v, f = validate_mesh(vertices, faces, name=name)
        v.setflags(write=False)
        f.setflags(write=False)
        return v, f

    return _VALIDATED.get(key, check)


def as_mesh(obj: Any, name: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Validated (vertices, faces) from a path, a (vertices, faces) pair, or any object with ``.vertices``/``.faces``.

    Accepts ``trimesh.Trimesh``, a ``trimesh.Scene`` (geometries concatenated), garsim's ``Garment``.
    """
    if isinstance(obj, (str, os.PathLike)):
        return load_mesh(obj)
    label = name or type(obj).__name__
    trimesh = sys.modules.get("trimesh")  # a Scene can only come from an imported trimesh: no import here
    if trimesh is not None and isinstance(obj, trimesh.Scene):
        obj = obj.to_mesh() if hasattr(obj, "to_mesh") else obj.dump(concatenate=True)
    if isinstance(obj, (tuple, list)):
        if obj and all(isinstance(o, (str, os.PathLike)) for o in obj):
            raise MeshError(
                f"{label}: got {len(obj)} file paths where one mesh goes; give one (several target bodies: "
                "GarSim.drape_sequence, or the CLI's --target with a folder)"
            )
        if len(obj) != 2:
            raise MeshError(f"{label}: expected a (vertices, faces) pair, got a sequence of length {len(obj)}")
        return _validated(obj[0], obj[1], name or "mesh")
    if hasattr(obj, "vertices") and hasattr(obj, "faces"):
        return _validated(obj.vertices, obj.faces, label)
    raise MeshError(
        f"cannot read a mesh from a {type(obj).__name__}; "
        "pass a file path, a (vertices, faces) pair or a trimesh.Trimesh"
    )
