"""Reader for CLOTH3D sample folders (Bertiche et al., ECCV 2020) -> garsim :class:`Sample` records.

For users who own CLOTH3D and SMPL; nothing is downloaded. A sample folder ``<split>/<sample_id>/`` holds

- ``info.mat``: a MATLAB struct (``poses`` (72, T) SMPL axis-angles, ``shape`` (10,) betas, ``gender``
  (0 female, 1 male), ``trans`` (3, T), ``zrot`` (body yaw, radians) and ``outfit``: one struct per
  garment name with ``fabric``, ``texture``, ...);
- ``<Garment>.obj``: the garment template in CLOTH3D's rest pose;
- ``<Garment>.pc16``: the simulated garment vertices of every frame (Point Cache 2 with float16 data).

Frames and axes, as in the official starter kit (``DataReader/read.py``) and the tools built on it:

- CLOTH3D was simulated in Blender, Z up. The SMPL root rotation stored in ``poses[:3]`` already
  contains the quarter turn about X that takes SMPL's native Y-up frame to Z up (front +Z -> -Y),
  which is exactly :func:`garsim.geometry.io.y_up_to_z_up`. So CLOTH3D bodies and garments are
  already in garsim's axes (Z up, body facing -Y before ``zrot``): no further conversion is applied.
- ``.pc16`` vertices are relative to the SMPL root joint (no ``trans``, no ``zrot``); the starter kit
  adds ``trans[:, t]`` and then rotates by ``zrot`` about Z for absolute positions.
- The rest garment OBJ is stored with ``zrot`` applied; undoing it (rotating by ``-zrot``) puts it on
  the SMPL body in the CLOTH3D rest pose :data:`REST_POSE` (root quarter turn about X, hips spread by
  +-0.15 rad), root joint at the origin.

By default (``world=False``) every array is root-relative and un-rotated: canonical body = SMPL in
the rest pose, template = OBJ rotated by ``-zrot``, target body = SMPL at frame t, target = pc16 frame
t. ``world=True`` places everything as the starter kit's absolute reader does (template as stored;
bodies/targets + ``trans[:, t]`` then rotated by ``zrot``; the canonical body rotated by ``zrot``).

CLOTH3D has no pinned vertices: every sample's pinned mask is all False.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from garsim.atomic import atomic_write_bytes
from garsim.data.sample import FABRICS, GARMENT_TYPES, Sample
from garsim.geometry.io import triangulate_polygons, validate_mesh

PC2_SIGNATURE = b"POINTCACHE2\0"
PC2_HEADER = struct.Struct("<12siiffi")  # signature, version, points, start frame, sample rate, samples
"""Point Cache 2 header: 32 bytes, little-endian."""

GARMENT_TYPE_MAP: dict[str, str] = {
    "Top": "top",
    "Skirt": "skirt",
    "Tshirt": "tshirt",
    "Trousers": "trousers",
    "Dress": "dress",
}
"""CLOTH3D garment names -> garsim garment types (CLOTH3D's ``Jumpsuit`` has no garsim type)."""

REST_POSE = np.zeros(72, dtype=np.float64)
REST_POSE[0] = np.pi / 2  # root: SMPL Y-up -> CLOTH3D/Blender Z-up
REST_POSE[1 * 3 + 2] = 0.15  # left hip, about z
REST_POSE[2 * 3 + 2] = -0.15  # right hip
"""CLOTH3D's rest pose (the pose of every template OBJ): a T-pose, Z up, legs slightly apart."""

SMPL_FILE_NAMES: dict[str, tuple[str, ...]] = {
    "female": (
        "SMPL_FEMALE.pkl",
        "model_f.pkl",
        "basicModel_f_lbs_10_207_0_v1.0.0.pkl",
        "basicmodel_f_lbs_10_207_0_v1.1.0.pkl",
    ),
    "male": (
        "SMPL_MALE.pkl",
        "model_m.pkl",
        "basicmodel_m_lbs_10_207_0_v1.0.0.pkl",
        "basicmodel_m_lbs_10_207_0_v1.1.0.pkl",
    ),
}
"""SMPL model file names looked for (in ``model_path`` or ``model_path/smpl``), per gender."""

BodyModelFn = Callable[[np.ndarray, np.ndarray, np.ndarray, str], tuple[np.ndarray, np.ndarray]]
"""``(betas (10,), pose (72,), trans (3,), gender 'female'|'male') -> (vertices (V, 3), faces (F, 3))``
with the SMPL root joint (pelvis) at ``trans``."""


class Cloth3DError(ValueError):
    """A CLOTH3D folder or file garsim cannot use; the message says what to fix."""


# ---------------------------------------------------------------------------- point caches


def pc16_info(path: str | os.PathLike) -> tuple[int, int]:
    """Validate a ``.pc16`` header and file size -> (number of frames, number of points)."""
    p = Path(path)
    if not p.is_file():
        raise Cloth3DError(f"{p}: vertex cache not found; each CLOTH3D garment needs <Garment>.pc16 beside its OBJ")
    size = p.stat().st_size
    if size < PC2_HEADER.size:
        raise Cloth3DError(f"{p}: truncated vertex cache ({size} bytes, shorter than the 32-byte header)")
    with open(p, "rb") as fh:
        sig, _version, n_points, _start, _rate, n_samples = PC2_HEADER.unpack(fh.read(PC2_HEADER.size))
    if sig != PC2_SIGNATURE:
        raise Cloth3DError(f"{p}: not a Point Cache 2 file (signature {sig!r}, expected {PC2_SIGNATURE!r})")
    if n_points <= 0 or n_samples <= 0:
        raise Cloth3DError(
            f"{p}: header declares {n_samples} frames of {n_points} points; the cache is empty or corrupt"
        )
    expected = PC2_HEADER.size + n_samples * n_points * 3 * 2
    if size != expected:
        kind = "truncated" if size < expected else "oversized"
        raise Cloth3DError(
            f"{p}: {kind} vertex cache: header declares {n_samples} frames x {n_points} points "
            f"({expected} bytes) but the file has {size} bytes; re-extract it from the CLOTH3D archive"
        )
    return n_samples, n_points


def read_pc16(path: str | os.PathLike, frames: Iterable[int] | None = None) -> np.ndarray:
    """Read a ``.pc16`` vertex cache -> float32 (T, N, 3) (all frames, or ``frames`` in that order)."""
    n_samples, n_points = pc16_info(path)
    data = np.memmap(Path(path), dtype="<f2", mode="r", offset=PC2_HEADER.size, shape=(n_samples, n_points, 3))
    try:
        if frames is None:
            return np.array(data, dtype=np.float32)
        return np.array(data[_check_frames(frames, n_samples, str(path))], dtype=np.float32)
    finally:
        del data


def write_pc16(path: str | os.PathLike, frames: np.ndarray, start_frame: float = 0.0, sample_rate: float = 1.0) -> Path:
    """Write (T, N, 3) vertex positions as a ``.pc16`` cache (float16 data), atomically."""
    v = np.asarray(frames, dtype=np.float64)
    if v.ndim != 3 or v.shape[2] != 3 or v.shape[0] == 0 or v.shape[1] == 0:
        raise Cloth3DError(f"write_pc16: frames must have shape (T, N, 3) with T, N > 0, got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise Cloth3DError("write_pc16: frames contain NaN or inf")
    if np.abs(v).max() > np.finfo(np.float16).max:
        raise Cloth3DError("write_pc16: values exceed the float16 range (|x| > 65504); store root-relative positions")
    header = PC2_HEADER.pack(PC2_SIGNATURE, 1, v.shape[1], float(start_frame), float(sample_rate), v.shape[0])
    return atomic_write_bytes(path, header + v.astype("<f2").tobytes())


def _check_frames(frames: Iterable[int], n: int, what: str) -> np.ndarray:
    idx = np.asarray(list(frames), dtype=np.int64).reshape(-1)
    bad = idx[(idx < 0) | (idx >= n)]
    if len(bad):
        raise Cloth3DError(f"{what}: frame {int(bad[0])} out of range; it has frames 0..{n - 1}")
    return idx


# ---------------------------------------------------------------------------- info.mat and OBJ


def _to_python(value: Any) -> Any:
    """Turn scipy's mat_struct (nested) into dicts; leave arrays and scalars alone."""
    from scipy.io.matlab import mat_struct

    if isinstance(value, mat_struct):
        return {name: _to_python(getattr(value, name)) for name in value._fieldnames}
    if isinstance(value, np.ndarray) and value.dtype == object:
        return [_to_python(v) for v in value.ravel()]
    return value


def read_info(folder: str | os.PathLike) -> dict[str, Any]:
    """Load ``info.mat`` as nested dicts (``scipy.io.loadmat(struct_as_record=False, squeeze_me=True)``)."""
    import scipy.io

    p = Path(folder) / "info.mat"
    if not p.is_file():
        raise Cloth3DError(f"{Path(folder)}: no info.mat; pass a CLOTH3D sample folder (<split>/<sample_id>/)")
    try:
        raw = scipy.io.loadmat(str(p), struct_as_record=False, squeeze_me=True)
    except (ValueError, TypeError, OSError, EOFError, scipy.io.matlab.MatReadError) as exc:
        raise Cloth3DError(f"{p}: could not read the MATLAB file ({type(exc).__name__}: {exc})") from None
    info = {k: _to_python(v) for k, v in raw.items() if not k.startswith("__")}
    missing = [k for k in ("poses", "shape", "gender", "trans", "outfit") if k not in info]
    if missing:
        raise Cloth3DError(f"{p}: missing fields {missing}; is this a CLOTH3D info.mat?")
    if not isinstance(info["outfit"], dict):
        raise Cloth3DError(f"{p}: 'outfit' is not a struct of garments")
    return info


def list_garments(folder: str | os.PathLike) -> list[str]:
    """Garment names of a sample (the fields of ``info.mat``'s ``outfit``, e.g. ``['Top', 'Skirt']``)."""
    return list(read_info(folder)["outfit"].keys())


def read_obj(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read an OBJ's ``v`` and ``f`` records in file order -> validated (float32 (V, 3), int64 (F, 3)).

    Vertex order and count are exactly the file's (``vt``/``vn`` never split vertices), as the vertex
    cache requires; quads and polygons are fan-triangulated.
    """
    p = Path(path)
    if not p.is_file():
        raise Cloth3DError(f"{p}: garment OBJ not found; each CLOTH3D garment needs <Garment>.obj")
    verts: list[str] = []
    faces: list[list[int]] = []
    with open(p, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append(line[2:])
            elif line.startswith("f "):
                faces.append([int(tok.split("/")[0]) for tok in line[2:].split()])
    try:
        v = np.array(" ".join(verts).split(), dtype=np.float64)
        v = v.reshape(len(verts), -1)[:, :3] if verts else np.zeros((0, 3))
    except ValueError:
        raise Cloth3DError(f"{p}: malformed 'v' lines (each needs three numbers)") from None
    by_len: dict[int, list[list[int]]] = {}
    for f in faces:
        by_len.setdefault(len(f), []).append(f)
    if any(k < 3 for k in by_len):
        raise Cloth3DError(f"{p}: a face has fewer than three corners")
    tris = [triangulate_polygons(np.array(fs, dtype=np.int64)) for _, fs in sorted(by_len.items())]
    f_arr = np.concatenate(tris) if tris else np.zeros((0, 3), dtype=np.int64)
    f_arr = np.where(f_arr < 0, f_arr + len(v), f_arr - 1)  # OBJ is 1-based; negatives count from the end
    return validate_mesh(v, f_arr, name=str(p))


# ---------------------------------------------------------------------------- SMPL


def _find_smpl_file(model_path: Path, gender: str) -> Path | None:
    for folder in (model_path, model_path / "smpl"):
        for name in SMPL_FILE_NAMES[gender]:
            if (folder / name).is_file():
                return folder / name
    return None


class SmplBodyModel:
    """Default ``body_model``: SMPL through the optional ``smplx`` package, from user-supplied .pkl files.

    Never downloads. ``model_path`` is a folder holding ``SMPL_FEMALE.pkl`` / ``SMPL_MALE.pkl`` (or the
    starter kit's ``model_f.pkl`` / ``model_m.pkl``, or SMPL's ``basicmodel_*`` names), directly or in
    ``smpl/``. Returns vertices with the root joint at ``trans``.
    """

    def __init__(self, model_path: str | os.PathLike) -> None:
        self.model_path = Path(model_path)
        self._models: dict[str, Any] = {}

    def _model(self, gender: str) -> Any:
        if gender in self._models:
            return self._models[gender]
        if gender not in SMPL_FILE_NAMES:
            raise Cloth3DError(f"unknown SMPL gender {gender!r}; use 'female' or 'male'")
        file = _find_smpl_file(self.model_path, gender) if self.model_path.is_dir() else None
        if file is None:
            names = " or ".join(SMPL_FILE_NAMES[gender][:2])
            raise Cloth3DError(
                f"SMPL model files not found in {self.model_path}: put {names} there (or in its smpl/ "
                "subfolder); SMPL is licensed, get it from https://smpl.is.tue.mpg.de (garsim never downloads it)"
            )
        try:
            import smplx
        except ImportError:
            raise Cloth3DError(
                "the CLOTH3D reader's SMPL body needs the optional 'smplx' package: pip install smplx "
                "(or pass body_model= your own SMPL callable)"
            ) from None
        self._models[gender] = smplx.SMPL(model_path=str(file), gender=gender, batch_size=1)
        return self._models[gender]

    def __call__(
        self, betas: np.ndarray, pose: np.ndarray, trans: np.ndarray, gender: str
    ) -> tuple[np.ndarray, np.ndarray]:
        """SMPL vertices (6890, 3) with the root joint at ``trans``, and faces (13776, 3)."""
        import torch

        model = self._model(gender)
        pose_t = torch.as_tensor(np.asarray(pose, dtype=np.float32).reshape(1, 72))
        with torch.no_grad():
            out = model(
                betas=torch.as_tensor(np.asarray(betas, dtype=np.float32).reshape(1, -1)[:, :10]),
                global_orient=pose_t[:, :3],
                body_pose=pose_t[:, 3:],
                transl=torch.zeros(1, 3),
            )
        v = out.vertices[0].numpy().astype(np.float64)
        root = out.joints[0, 0].numpy().astype(np.float64)
        return (v - root + np.asarray(trans, dtype=np.float64)), np.asarray(model.faces, dtype=np.int64)


# ---------------------------------------------------------------------------- samples


def _z_rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _per_frame(arr: Any, rows: int, name: str, where: Path) -> np.ndarray:
    a = np.asarray(arr, dtype=np.float64)
    if a.ndim == 1:  # squeeze_me turns a one-frame (rows, 1) array into (rows,)
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] != rows:
        raise Cloth3DError(f"{where}: '{name}' has shape {a.shape}, expected ({rows}, T)")
    if not np.all(np.isfinite(a)):
        raise Cloth3DError(f"{where}: '{name}' contains NaN or inf")
    return a


def _body(
    body_model: BodyModelFn, betas: np.ndarray, pose: np.ndarray, trans: np.ndarray, gender: str, what: str
) -> tuple[np.ndarray, np.ndarray]:
    v, f = body_model(betas, pose, trans, gender)
    v = np.asarray(v, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
        raise Cloth3DError(f"body_model returned invalid vertices for the {what} (shape {v.shape}, or NaN/inf)")
    return v, np.asarray(f, dtype=np.int64)


def read_cloth3d_sample(
    folder: str | os.PathLike,
    garment: str,
    frames: Iterable[int] | None = None,
    body_model: BodyModelFn | None = None,
    *,
    model_path: str | os.PathLike | None = None,
    world: bool = False,
) -> list[Sample]:
    """Read one garment of a CLOTH3D sample folder -> one garsim :class:`Sample` per frame.

    ``frames`` defaults to every frame; ``body_model`` (see :data:`BodyModelFn`) defaults to
    :class:`SmplBodyModel` over ``model_path``. See the module docstring for frames and axes.
    """
    from garsim.bodies.prior import rigfree_prior

    folder = Path(folder)
    if not folder.is_dir():
        raise Cloth3DError(f"{folder}: not a folder; pass a CLOTH3D sample folder (<split>/<sample_id>/)")
    info = read_info(folder)
    info_path = folder / "info.mat"
    outfit = info["outfit"]
    if garment not in outfit:
        raise Cloth3DError(f"{folder}: no garment {garment!r} in info.mat; this sample has {list(outfit)}")
    if garment not in GARMENT_TYPE_MAP:
        raise Cloth3DError(
            f"CLOTH3D garment {garment!r} has no garsim type; supported: {sorted(GARMENT_TYPE_MAP)} "
            f"(garsim types {GARMENT_TYPES})"
        )
    g_info = outfit[garment] if isinstance(outfit[garment], dict) else {}
    fabric = str(g_info.get("fabric", "")).strip().lower()
    if fabric not in FABRICS:
        raise Cloth3DError(f"{info_path}: garment {garment!r} has fabric {fabric!r}; expected one of {FABRICS}")

    if body_model is None:
        if model_path is None:
            raise Cloth3DError(
                "read_cloth3d_sample needs a body: pass model_path= (a folder with SMPL's .pkl files, used "
                "through the optional smplx package) or body_model= (your own SMPL callable)"
            )
        body_model = SmplBodyModel(model_path)

    poses = _per_frame(info["poses"], 72, "poses", info_path)
    trans = _per_frame(info["trans"], 3, "trans", info_path)
    betas = np.asarray(info["shape"], dtype=np.float64).reshape(-1)
    if betas.size < 10 or not np.all(np.isfinite(betas)):
        raise Cloth3DError(f"{info_path}: 'shape' must hold 10 finite SMPL betas, got {betas.size} values")
    betas = betas[:10]
    gender = "male" if int(np.asarray(info["gender"]).reshape(-1)[0]) else "female"
    zrot = float(np.asarray(info.get("zrot", 0.0), dtype=np.float64).reshape(-1)[0])
    rz = _z_rotation(zrot)

    tpl, tpl_faces = read_obj(folder / f"{garment}.obj")
    cache_path = folder / f"{garment}.pc16"
    n_cache, n_points = pc16_info(cache_path)
    if n_points != len(tpl):
        raise Cloth3DError(
            f"{cache_path}: the cache has {n_points} points but {garment}.obj has {len(tpl)} vertices; "
            "the OBJ and its cache must come from the same CLOTH3D sample"
        )
    n_frames = min(n_cache, poses.shape[1])
    if trans.shape[1] not in (1, poses.shape[1]):
        raise Cloth3DError(f"{info_path}: 'trans' has {trans.shape[1]} frames but 'poses' has {poses.shape[1]}")
    idx = (
        np.arange(n_frames)
        if frames is None
        else _check_frames(frames, n_frames, f"{folder} ({n_cache} cached frames, {poses.shape[1]} poses)")
    )
    targets = read_pc16(cache_path, idx).astype(np.float64)
    nan_frames = idx[~np.all(np.isfinite(targets), axis=(1, 2))]
    if len(nan_frames):
        raise Cloth3DError(f"{cache_path}: frame {int(nan_frames[0])} contains NaN or inf; skip it with frames=")

    zero = np.zeros(3)
    canon, body_faces = _body(body_model, betas, REST_POSE, zero, gender, "rest pose")
    if world:
        template, canon = tpl.astype(np.float64), canon @ rz.T
    else:
        template = tpl.astype(np.float64) @ rz  # rows: R(zrot)^T v, undoing the zrot baked into the OBJ
    template32 = template.astype(np.float32)
    canon32 = canon.astype(np.float32)

    samples: list[Sample] = []
    for t, target in zip(idx.tolist(), targets):
        tr = trans[:, t if trans.shape[1] > 1 else 0]
        body_t, _ = _body(body_model, betas, poses[:, t], tr if world else zero, gender, f"frame {t}")
        if body_t.shape != canon.shape:
            raise Cloth3DError(f"body_model returned {body_t.shape} vertices at frame {t}, {canon.shape} at rest")
        if world:
            body_t, target = body_t @ rz.T, (target + tr) @ rz.T
        body_t32 = body_t.astype(np.float32)
        samples.append(
            Sample(
                body_canonical=canon32,
                body_target=body_t32,
                body_faces=body_faces,
                garment=template32,
                garment_faces=tpl_faces,
                pinned=np.zeros(len(template32), dtype=bool),
                prior=rigfree_prior(template32, canon32, body_t32, body_faces),
                fabric=fabric,
                garment_type=GARMENT_TYPE_MAP[garment],
                target=target.astype(np.float32),
                meta={
                    "source": "cloth3d",
                    "sample": folder.name,
                    "garment": garment,
                    "frame": int(t),
                    "gender": gender,
                    "betas": betas.tolist(),
                    "pose": poses[:, t].tolist(),
                    "trans": tr.tolist(),
                    "zrot": zrot,
                    "world": bool(world),
                },
            )
        )
    return samples
