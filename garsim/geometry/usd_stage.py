"""A USD stage's mesh as it shows over time (usd-core, imported on first use): time-sampled points through the prims'
transforms, or a mesh bound to a UsdSkel skeleton skinned by USD's own skinning at each of its animation's time
codes; points in the stage's declared axis and unit, converted to garsim's Z-up metres by the caller's choice."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from garsim.geometry.io import USD_EXTENSIONS, MeshError, triangulate_polygons, y_up_to_z_up

__all__ = ["USD_EXTENSIONS", "by_name", "load_usd_animation", "mesh_frames", "open_stage", "read_usd_mesh"]


def open_stage(path: str | Path) -> tuple[Any, list[Any]]:
    """(the stage, its mesh prims in traversal order); MeshError for an unreadable stage or one without a mesh."""
    from pxr import Usd, UsdGeom

    p = Path(path)
    if not p.is_file():
        raise MeshError(f"{p}: no such file")
    try:
        stage = Usd.Stage.Open(str(p))
    except Exception as exc:  # noqa: BLE001 - pxr raises its own Tf.ErrorException
        raise MeshError(f"{p}: not a readable USD stage ({str(exc).strip().splitlines()[-1][:200]})") from None
    meshes = [prim for prim in stage.Traverse() if prim.IsA(UsdGeom.Mesh)]
    if not meshes:
        raise MeshError(f"{p}: the stage holds no mesh")
    return stage, meshes


def by_name(prims: list[Any]) -> dict[str, Any]:
    """Mesh prims by their name (the first of a name in traversal order)."""
    out: dict[str, Any] = {}
    for prim in prims:
        out.setdefault(prim.GetName(), prim)
    return out


def to_z_up_metres(stage: Any, points: np.ndarray) -> np.ndarray:
    """Points in the stage's declared upAxis and metersPerUnit -> garsim's Z-up metres."""
    from pxr import UsdGeom

    v = np.asarray(points, dtype=np.float64) * float(UsdGeom.GetStageMetersPerUnit(stage))
    return y_up_to_z_up(v) if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else v


def _faces(mesh: Any, name: str) -> np.ndarray:
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(mesh)
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


def _world_points(prim: Any, skinned: tuple[Any, Any, Any] | None, code: Any, name: str) -> np.ndarray:
    """(V, 3) points of a mesh in the stage's frame at one time code: skinned by UsdSkel through the skeleton's
    transform, else through the prim's and its parents' transforms."""
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh(prim)
    value = mesh.GetPointsAttr().Get(code)
    if value is None or len(value) == 0:
        raise MeshError(f"{name}: {prim.GetPath()} has no points at time {code}")
    xformable = UsdGeom.Xformable(prim if skinned is None else skinned[2])
    world = np.asarray(xformable.ComputeLocalToWorldTransform(code), dtype=np.float64)  # row vectors: p @ M
    p = np.asarray(value, dtype=np.float64)
    if skinned is not None:
        skin, skel_query, _ = skinned
        out = Vt.Vec3fArray.FromNumpy(p.astype(np.float32))
        if not skin.ComputeSkinnedPoints(skel_query.ComputeSkinningTransforms(code), out, code):
            raise MeshError(f"{name}: USD could not skin {prim.GetPath()} at time {code}")
        p = np.asarray(out, dtype=np.float64)
    return p @ world[:3, :3] + world[3, :3]


def _skinned_checked(prim: Any, name: str) -> tuple[Any, Any, Any] | None:
    skinned = _skinning(prim)
    if skinned is not None and skinned[0].HasBlendShapes():
        raise MeshError(f"{name}: {prim.GetPath()} has UsdSkel blend shapes (not applied); bake them")
    return skinned


def mesh_frames(stage: Any, prim: Any, name: str) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """(T, V, 3) points of a mesh in the stage's frame at each time code of its animation (a skin's or its points'
    time samples; one frame at the earliest time when neither is animated), (F, 3) triangles, the time codes."""
    from pxr import Usd, UsdGeom

    skinned = _skinned_checked(prim, name)
    if skinned is not None:
        anim = skinned[1].GetAnimQuery()
        times = list(anim.GetJointTransformTimeSamples()) if anim else []
    else:
        times = list(UsdGeom.Mesh(prim).GetPointsAttr().GetTimeSamples())
    codes = [Usd.TimeCode(t) for t in times] or [Usd.TimeCode.EarliestTime()]
    frames = np.stack([_world_points(prim, skinned, code, name) for code in codes])
    return frames, _faces(UsdGeom.Mesh(prim), name), [float(t) for t in times]


def read_usd_mesh(path: str | Path, z_up_metres: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Every mesh of a USD stage as it shows at its earliest time (skins applied), concatenated in traversal order ->
    (vertices, faces): in the stage's own axis and unit, or in garsim's Z-up metres with ``z_up_metres``."""
    from pxr import Usd

    p = Path(path)
    stage, meshes = open_stage(p)
    vertices, faces, offset = [], [], 0
    for prim in meshes:
        v = _world_points(prim, _skinned_checked(prim, p.name), Usd.TimeCode.EarliestTime(), p.name)
        faces.append(_faces(prim, p.name) + offset)
        vertices.append(v)
        offset += len(v)
    v = np.concatenate(vertices)
    return (to_z_up_metres(stage, v) if z_up_metres else v), np.concatenate(faces)


def load_usd_animation(path: str | Path, mesh: str | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """A USD stage's animated mesh (the prim named ``mesh``; default ``Body`` if there is one, else the only mesh) ->
    (frames (T, V, 3) in Z-up metres, faces, time codes per second)."""
    p = Path(path)
    stage, prims = open_stage(p)
    meshes = by_name(prims)
    if mesh is None:
        if "Body" in meshes:
            mesh = "Body"
        elif len(meshes) == 1:
            mesh = next(iter(meshes))
        else:
            raise MeshError(
                f"{p}: the stage holds several meshes ({', '.join(meshes)}); name the body's prim (CLI: --animation)"
            )
    if mesh not in meshes:
        raise MeshError(f"{p}: no mesh {mesh!r}; the stage has {', '.join(map(repr, meshes))}")
    frames, faces, _ = mesh_frames(stage, meshes[mesh], p.name)
    if not np.isfinite(frames).all():
        raise MeshError(f"{p}: the mesh {mesh!r} has non-finite points")
    return to_z_up_metres(stage, frames).astype(np.float32), faces, float(stage.GetTimeCodesPerSecond())
