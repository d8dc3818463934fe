"""USD (.usd/.usda/.usdc) export through ``pxr`` (usd-core): time-sampled UsdGeom.Mesh prims.

Stage layout: ``/Scene`` (Xform, default prim) with ``/Scene/Garment`` and, if given, ``/Scene/Body``.
Each mesh has ``points`` (and ``extent``) sampled at time codes 0 .. T-1 (the first frame also as their default
value, for readers of a static mesh), triangle
``faceVertexCounts``/``faceVertexIndices`` (vertex order kept), ``subdivisionScheme = none``, optional
``primvars:st`` (vertex interpolation) and ``normals``. Stage metadata: ``upAxis`` and ``metersPerUnit`` as given
(garsim's Z and 1 by default; the points are written as given, no conversion), ``timeCodesPerSecond =
framesPerSecond = fps``, ``startTimeCode = 0``, ``endTimeCode = T - 1``. ``.usd`` is written as binary crate (usdc).

Caller ``metadata`` (which model, smoothing, ...) goes to the root layer's ``customLayerData`` under
``"garsim"`` as a JSON string (USD dictionaries cannot hold lists or None), read back with
``json.loads(Sdf.Layer.FindOrOpen(path).customLayerData["garsim"])``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from garsim.export._common import (
    ExportError,
    atomic_write_ext,
    check_animation,
    check_fps,
    check_output,
    metadata_json,
)

USD_EXTENSIONS: tuple[str, ...] = (".usd", ".usda", ".usdc")


def _define_mesh(stage: Any, prim_path: str, frames: np.ndarray, faces: np.ndarray, uvs: Any, normals: Any) -> Any:
    from pxr import Sdf, UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, prim_path)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel()))
    # the first frame is also the attributes' default: what a reader that asks for no time (a static mesh) gets
    points = mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(frames[0], dtype=np.float32)))
    extent = mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([frames[0].min(axis=0), frames[0].max(axis=0)])))
    for k in range(len(frames)):
        pts = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(frames[k], dtype=np.float32))
        points.Set(pts, float(k))
        extent.Set(Vt.Vec3fArray.FromNumpy(np.stack([frames[k].min(axis=0), frames[k].max(axis=0)])), float(k))
    if normals is not None:
        attr = mesh.CreateNormalsAttr()
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        if normals.ndim == 2:
            attr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals)))
        else:
            attr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals[0])))
            for k in range(len(normals)):
                attr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals[k])), float(k))
    if uvs is not None:
        st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
        )
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uvs, dtype=np.float32)))
    return mesh


def write_usd_animation(
    path: str | os.PathLike,
    frames: Any,
    faces: Any,
    body_frames: Any = None,
    body_faces: Any = None,
    fps: float = 30,
    uvs: Any = None,
    normals: Any = None,
    metadata: Mapping[str, Any] | None = None,
    up: str = "z",
    meters_per_unit: float = 1.0,
) -> Path:
    """Write a garment sequence (and optional body) as an animated USD stage; returns the path.

    ``frames`` (T, N, 3), Z-up metres by default, written as given: the stage declares ``up`` ('z' or 'y') as its
    upAxis and ``meters_per_unit`` (e.g. 0.01 for centimetres);
    frame k is time code k and plays at ``fps``. ``uvs`` (N, 2) and ``normals`` ((N, 3) or (T, N, 3))
    belong to the garment. ``metadata``: a JSON-serialisable dict, stored as JSON text in the root layer's
    ``customLayerData["garsim"]``.
    """
    p, _ = check_output(path, USD_EXTENSIONS, "write_usd_animation")
    a = check_animation(frames, faces, body_frames, body_faces, uvs, normals, metadata)
    fps = check_fps(fps)
    if up not in ("z", "y") or not (isinstance(meters_per_unit, (int, float)) and meters_per_unit > 0):
        raise ExportError(f"up must be 'z' or 'y' and meters_per_unit > 0, got {up!r} and {meters_per_unit!r}")

    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(float(a.frames.shape[0] - 1))
    root = UsdGeom.Xform.Define(stage, "/Scene")
    stage.SetDefaultPrim(root.GetPrim())
    _define_mesh(stage, "/Scene/Garment", a.frames, a.faces, a.uvs, a.normals)
    if a.body is not None:
        _define_mesh(stage, "/Scene/Body", *a.body, None, None)
    layer = stage.GetRootLayer()
    layer.documentation = "garsim garment animation"
    if a.metadata is not None:
        layer.customLayerData = {"garsim": metadata_json(a.metadata)}

    def write(tmp: str) -> None:
        if not layer.Export(tmp):
            raise OSError(f"USD could not write {tmp}")

    return atomic_write_ext(p, write)
