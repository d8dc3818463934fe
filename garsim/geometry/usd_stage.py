"""A USD stage's mesh as it shows over time (usd-core, imported on first use): time-sampled points through the prims'
transforms, or a mesh bound to a UsdSkel skeleton skinned by USD's own skinning at each of its animation's time
codes; points in the stage's declared axis and unit, converted to garsim's Z-up metres by the caller's choice."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from garsim.geometry.io import MeshError, triangulate_polygons, y_up_to_z_up

USD_EXTENSIONS: tuple[str, ...] = (".usd", ".usda", ".usdc", ".usdz")


def open_stage(path: str | Path) -> tuple[Any, dict[str, Any]]:
    """(the stage, its meshes by prim name in traversal order); MeshError for an unreadable stage or one without a
    mesh."""
    from pxr import Usd, UsdGeom

    p = Path(path)
    if not p.is_file():
        raise MeshError(f"{p}: no such file")
    try:
        stage = Usd.Stage.Open(str(p))
    except Exception as exc:  # noqa: BLE001 - pxr raises its own Tf.ErrorException
        raise MeshError(f"{p}: not a readable USD stage ({str(exc).strip().splitlines()[-1][:200]})") from None
    meshes = {prim.GetName(): prim for prim in stage.Traverse() if prim.IsA(UsdGeom.Mesh)}
    if not meshes:
        raise MeshError(f"{p}: the stage holds no mesh")
    return stage, meshes


def to_z_up_metres(stage: Any, points: np.ndarray) -> np.ndarray:
    """Points in the stage's declared upAxis and metersPerUnit -> garsim's Z-up metres."""
    from pxr import UsdGeom

    v = np.asarray(points, dtype=np.float64) * float(UsdGeom.GetStageMetersPerUnit(stage))
    return y_up_to_z_up(v) if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else v


def _faces(mesh: Any, name: str) -> np.ndarray:
    counts, indices = mesh.GetFaceVertexCountsAttr().Get(), mesh.GetFaceVertexIndicesAttr().Get()
    if counts is None or indices is None:
        raise MeshError(f"{name}: {mesh.GetPath()} has no faces (faceVertexCounts / faceVertexIndices)")
    counts, indices = np.asarray(counts), np.asarray(indices, dtype=np.int64)
    if len(counts) == 0 or (counts != counts[0]).any() or counts[0] < 3:
        raise MeshError(f"{name}: {mesh.GetPath()} is not a mesh of triangles (or of one polygon size)")
    return triangulate_polygons(indices.reshape(-1, int(counts[0])))


def _skinning(prim: Any) -> tuple[Any, Any, Any] | None:
    """(skinning query, skeleton query, skeleton prim) of a mesh bound to an animated UsdSkel skeleton, else None."""
    from pxr import Usd, UsdSkel

    root = prim.GetParent()
    while root and not root.IsA(UsdSkel.Root):
        root = root.GetParent()
    if not root or not root.IsValid():
        return None
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(root), Usd.TraverseInstanceProxies())
    skin = cache.GetSkinningQuery(prim)
    skeleton = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    if not skin or not skin.HasJointInfluences() or not skeleton:
        return None
    return skin, cache.GetSkelQuery(skeleton), skeleton.GetPrim()


def mesh_frames(stage: Any, prim: Any, name: str) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """(T, V, 3) points of a mesh in the stage's frame at each time code of its animation (a skin's or its points'
    time samples; one frame at the default time when neither is animated), (F, 3) triangles, the time codes."""
    from pxr import Usd, UsdGeom, Vt

    mesh = UsdGeom.Mesh(prim)
    points = mesh.GetPointsAttr()
    rest = np.asarray(points.Get(Usd.TimeCode.Default()) or points.Get(Usd.TimeCode.EarliestTime()), dtype=np.float64)
    skinned = _skinning(prim)
    frames = []
    if skinned is not None:
        skin, skel_query, skel_prim = skinned
        if skin.HasBlendShapes():
            raise MeshError(f"{name}: {prim.GetPath()} has UsdSkel blend shapes (not applied); bake them")
        anim = skel_query.GetAnimQuery()
        times = list(anim.GetJointTransformTimeSamples()) if anim else []
        for t in times or [None]:
            code = Usd.TimeCode.Default() if t is None else Usd.TimeCode(t)
            p = np.asarray(points.Get(code) or rest, dtype=np.float64)
            out = Vt.Vec3fArray.FromNumpy(p.astype(np.float32))
            if not skin.ComputeSkinnedPoints(skel_query.ComputeSkinningTransforms(code), out, code):
                raise MeshError(f"{name}: USD could not skin {prim.GetPath()} at time {t}")
            world = np.asarray(UsdGeom.Xformable(skel_prim).ComputeLocalToWorldTransform(code), dtype=np.float64)
            frames.append(np.asarray(out, dtype=np.float64) @ world[:3, :3] + world[3, :3])  # row vectors: p @ M
    else:
        times = list(points.GetTimeSamples())
        for t in times or [None]:  # through the prim's and its parents' transforms at that time
            code = Usd.TimeCode.Default() if t is None else Usd.TimeCode(t)
            world = np.asarray(mesh.ComputeLocalToWorldTransform(code), dtype=np.float64)
            p = np.asarray(points.Get(code), dtype=np.float64)
            frames.append(p @ world[:3, :3] + world[3, :3])
    return np.stack(frames), _faces(mesh, name), [float(t) for t in times]


def load_usd_animation(path: str | Path, mesh: str | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """A USD stage's animated mesh (the prim named ``mesh``; default ``Body`` if there is one, else the only mesh) ->
    (frames (T, V, 3) in Z-up metres, faces, time codes per second)."""
    p = Path(path)
    stage, meshes = open_stage(p)
    if mesh is None:
        if "Body" in meshes:
            mesh = "Body"
        elif len(meshes) == 1:
            mesh = next(iter(meshes))
        else:
            raise MeshError(f"{p}: the stage holds several meshes ({', '.join(meshes)}); name the body's prim")
    if mesh not in meshes:
        raise MeshError(f"{p}: no mesh {mesh!r}; the stage has {', '.join(map(repr, meshes))}")
    frames, faces, _ = mesh_frames(stage, meshes[mesh], p.name)
    if not np.isfinite(frames).all():
        raise MeshError(f"{p}: the mesh {mesh!r} has non-finite points")
    return to_z_up_metres(stage, frames).astype(np.float32), faces, float(stage.GetTimeCodesPerSecond())
