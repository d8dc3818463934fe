"""A USD stage's meshes as usdview shows them (usd-core, imported on first use): points through the prims' transforms,
or skinned by USD's own UsdSkel for a mesh bound to a skeleton; polygons of any size fan-triangulated, their winding
reversed where the mesh is ``leftHanded`` or its transform mirrors; invisible and ``guide`` meshes left out (and
``proxy`` ones where ``render`` ones exist), instanced meshes included. An animation is sampled at a frame rate over
the stage's animated time span (the union of the points', the skeleton's and the transforms' time samples), so a
stage of 24 time codes per second, or with sparse keys, keeps its timing. Points come in the stage's declared axis
and unit (:func:`to_z_up_metres` converts)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from garsim.geometry.io import USD_EXTENSIONS, MeshAttributes, MeshError, fan_corners, y_up_to_z_up

__all__ = [
    "USD_EXTENSIONS",
    "body_prim",
    "load_usd_animation",
    "mesh_frames",
    "open_stage",
    "read_usd_mesh",
    "to_z_up_metres",
]


def open_stage(path: str | Path) -> tuple[Any, list[Any]]:
    """(the stage, its shown mesh prims in traversal order); MeshError for an unreadable stage or one without a
    mesh."""
    from pxr import Usd, UsdGeom

    p = Path(path)
    if not p.is_file():
        raise MeshError(f"{p}: no such file")
    try:
        stage = Usd.Stage.Open(str(p))
    except Exception as exc:  # noqa: BLE001 - pxr raises its own Tf.ErrorException
        raise MeshError(f"{p}: not a readable USD stage ({str(exc).strip().splitlines()[-1][:200]})") from None
    early = Usd.TimeCode.EarliestTime()
    meshes = [
        prim
        for prim in stage.Traverse(Usd.TraverseInstanceProxies())
        if prim.IsA(UsdGeom.Mesh) and UsdGeom.Imageable(prim).ComputeVisibility(early) != UsdGeom.Tokens.invisible
    ]
    purpose = {prim.GetPath(): UsdGeom.Imageable(prim).ComputePurpose() for prim in meshes}
    hidden = {UsdGeom.Tokens.guide}
    if UsdGeom.Tokens.render in purpose.values():
        hidden.add(UsdGeom.Tokens.proxy)  # a render mesh and its stand-in: the render one
    meshes = [prim for prim in meshes if purpose[prim.GetPath()] not in hidden]
    if not meshes:
        raise MeshError(f"{p}: the stage shows no mesh")
    return stage, meshes


def body_prim(path: str | Path, prims: list[Any], mesh: str | None) -> Any:
    """The mesh named ``mesh`` (the first of that name), else ``Body``, else the stage's only mesh."""
    names: dict[str, Any] = {}
    for prim in prims:
        names.setdefault(prim.GetName(), prim)
    if mesh is None:
        if "Body" in names:
            return names["Body"]
        if len(names) == 1:
            return prims[0]
        raise MeshError(
            f"{path}: the stage holds several meshes ({', '.join(names)}); name the body's prim (CLI: --body-mesh)"
        )
    if mesh not in names:
        raise MeshError(f"{path}: no mesh {mesh!r}; the stage has {', '.join(map(repr, names))}")
    return names[mesh]


def to_z_up_metres(stage: Any, points: np.ndarray) -> np.ndarray:
    """Points in the stage's declared upAxis and metersPerUnit -> garsim's Z-up metres."""
    from pxr import UsdGeom

    v = np.asarray(points, dtype=np.float64) * float(UsdGeom.GetStageMetersPerUnit(stage))
    return y_up_to_z_up(v) if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else v


def _skinning(prim: Any) -> tuple[Any, Any, Any] | None:
    """(skinning query, skeleton query, skeleton prim) of a mesh bound to a UsdSkel skeleton, else None."""
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
    if skin.HasBlendShapes():
        raise MeshError(f"{prim.GetPath()} has UsdSkel blend shapes (not applied); bake them")
    return skin, cache.GetSkelQuery(skeleton), skeleton.GetPrim()


def _world(prim: Any, skinned: tuple[Any, Any, Any] | None, code: Any) -> np.ndarray:
    """The (4, 4) row-vector transform that places the mesh's points: the skeleton's for a skinned mesh."""
    from pxr import UsdGeom

    xformable = UsdGeom.Xformable(prim if skinned is None else skinned[2])
    return np.asarray(xformable.ComputeLocalToWorldTransform(code), dtype=np.float64)


def _points(prim: Any, skinned: tuple[Any, Any, Any] | None, code: Any, name: str, rest: bool = False) -> np.ndarray:
    """(V, 3) points of a mesh in the stage's frame at one time code; ``rest``: a skinned mesh in its skeleton's rest
    pose (``restTransforms``), not its animation's."""
    from pxr import UsdGeom, Vt

    value = UsdGeom.Mesh(prim).GetPointsAttr().Get(code)
    if value is None or len(value) == 0:
        raise MeshError(f"{name}: {prim.GetPath()} has no points")
    p = np.asarray(value, dtype=np.float64)
    if skinned is not None:
        skin, skel_query, _ = skinned
        if rest:  # UsdSkel's skinning transforms, inverse(bind) * skel-space joint, with the joints at rest
            at_rest = skel_query.ComputeJointSkelTransforms(code, True)
            bind = skel_query.GetJointWorldBindTransforms()
            xforms = Vt.Matrix4dArray([b.GetInverse() * j for b, j in zip(bind, at_rest)])
        else:
            xforms = skel_query.ComputeSkinningTransforms(code)
        out = Vt.Vec3fArray.FromNumpy(p.astype(np.float32))
        if not skin.ComputeSkinnedPoints(xforms, out, code):
            raise MeshError(f"{name}: USD could not skin {prim.GetPath()}")
        p = np.asarray(out, dtype=np.float64)
    world = _world(prim, skinned, code)
    return p @ world[:3, :3] + world[3, :3]  # row vectors: p @ M


def _topology(prim: Any, skinned: tuple[Any, Any, Any] | None, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) triangles of a mesh (each polygon fan-triangulated; reversed when the mesh is left-handed or placed by
    a mirroring transform) and, per triangle corner, its index in the flat face-vertex list."""
    from pxr import Usd, UsdGeom

    mesh = UsdGeom.Mesh(prim)
    counts, indices = mesh.GetFaceVertexCountsAttr().Get(), mesh.GetFaceVertexIndicesAttr().Get()
    if counts is None or indices is None or len(counts) == 0:
        raise MeshError(f"{name}: {prim.GetPath()} has no faces (faceVertexCounts / faceVertexIndices)")
    counts, indices = np.asarray(counts, dtype=np.int64), np.asarray(indices, dtype=np.int64)
    if counts.min() < 3 or counts.sum() != len(indices):
        raise MeshError(
            f"{name}: {prim.GetPath()}'s faceVertexCounts and faceVertexIndices do not fit (a polygon under 3 corners?)"
        )
    corners = fan_corners(counts)
    left = mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded
    mirrored = np.linalg.det(_world(prim, skinned, Usd.TimeCode.EarliestTime())[:3, :3]) < 0
    if left != mirrored:
        corners = corners[:, ::-1]
    return indices[corners], corners


def _uvs(prim: Any, corners: np.ndarray, num_points: int) -> MeshAttributes:
    """The mesh's ``st`` texture coordinates (vertex, varying or faceVarying; indexed or not), as per-corner
    attributes; none when it has none."""
    from pxr import UsdGeom

    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    if not primvar or not primvar.HasValue():
        return MeshAttributes()
    values = np.asarray(primvar.Get(), dtype=np.float64).reshape(-1, 2)
    index = np.asarray(primvar.GetIndices() or np.arange(len(values)), dtype=np.int64)
    interpolation = primvar.GetInterpolation()
    if interpolation == UsdGeom.Tokens.faceVarying and len(index) > int(corners.max()):
        return MeshAttributes(uvs=values, uv_faces=index[corners])
    if interpolation in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying) and len(index) == num_points:
        return MeshAttributes(uvs=values, uv_faces=None)  # per vertex: the caller indexes them by the faces
    return MeshAttributes()


def _times(stage: Any, prim: Any, skinned: tuple[Any, Any, Any] | None) -> list[float]:
    """Every authored time sample that moves the mesh: its points', its skeleton animation's, and the transforms'
    of the prim (or skeleton) that places it and of their ancestors."""
    from pxr import UsdGeom

    times = set(UsdGeom.Mesh(prim).GetPointsAttr().GetTimeSamples())
    if skinned is not None:
        anim = skinned[1].GetAnimQuery()
        if anim:
            times.update(anim.GetJointTransformTimeSamples())
    node = prim if skinned is None else skinned[2]
    while node and node.IsValid() and node != stage.GetPseudoRoot():
        if node.IsA(UsdGeom.Xformable):
            times.update(UsdGeom.Xformable(node).GetTimeSamples())
        node = node.GetParent()
    return sorted(float(t) for t in times)


def mesh_frames(stage: Any, prim: Any, name: str, fps: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(T, V, 3) points of a mesh in the stage's frame over its animated time span at ``fps`` frames per second
    (default: one frame per time code), one frame at the earliest time when nothing moves it; (F, 3) triangles."""
    from pxr import Usd

    skinned = _skinning(prim)
    times = _times(stage, prim, skinned)
    if times:
        per_frame = float(stage.GetTimeCodesPerSecond()) / (fps or float(stage.GetTimeCodesPerSecond()))
        n = int(np.floor((times[-1] - times[0]) / per_frame + 1e-3)) + 1
        codes = [Usd.TimeCode(times[0] + k * per_frame) for k in range(n)]
    else:
        codes = [Usd.TimeCode.EarliestTime()]
    faces, _ = _topology(prim, skinned, name)
    return np.stack([_points(prim, skinned, code, name) for code in codes]), faces


def read_usd_mesh(
    path: str | Path, z_up_metres: bool = False, mesh: str | None = None, body: bool = False, rest: bool = False
) -> tuple[np.ndarray, np.ndarray, MeshAttributes]:
    """The stage's shown meshes at its earliest time (skins applied), concatenated in traversal order, or with
    ``body`` only its body prim (:func:`body_prim` with ``mesh``) -> (vertices, faces, UVs per corner where every mesh
    has ``st``), in the stage's own axis and unit, or in garsim's Z-up metres with ``z_up_metres``. ``rest``: skinned
    meshes in their skeleton's rest pose (an avatar's canonical pose, not its animation's first frame)."""
    from pxr import Usd

    p = Path(path)
    stage, prims = open_stage(p)
    if body:
        prims = [body_prim(p, prims, mesh)]
    vertices, faces, uvs, uv_faces, offset, uv_offset = [], [], [], [], 0, 0
    for prim in prims:
        skinned = _skinning(prim)
        v = _points(prim, skinned, Usd.TimeCode.EarliestTime(), p.name, rest)
        f, corners = _topology(prim, skinned, p.name)
        if f.size and f.max() >= len(v):
            raise MeshError(f"{p}: {prim.GetPath()}'s faces index point {int(f.max())} of {len(v)}")
        a = _uvs(prim, corners, len(v))
        if a.uvs is not None:
            uvs.append(a.uvs)
            uv_faces.append((f if a.uv_faces is None else a.uv_faces) + uv_offset)
            uv_offset += len(a.uvs)
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    v = np.concatenate(vertices)
    attrs = MeshAttributes()
    if len(uvs) == len(prims):
        attrs = MeshAttributes(uvs=np.concatenate(uvs), uv_faces=np.concatenate(uv_faces))
    return (to_z_up_metres(stage, v) if z_up_metres else v), np.concatenate(faces), attrs


def load_usd_animation(
    path: str | Path, mesh: str | None = None, fps: float | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """A USD stage's animated body (the prim named ``mesh``; default ``Body`` if there is one, else the only mesh)
    sampled at ``fps`` (default: the stage's time codes per second) -> (frames (T, V, 3) in Z-up metres, faces, the
    frame rate)."""
    p = Path(path)
    stage, prims = open_stage(p)
    prim = body_prim(p, prims, mesh)
    frames, faces = mesh_frames(stage, prim, p.name, fps)
    if not np.isfinite(frames).all():
        raise MeshError(f"{p}: the mesh {prim.GetName()!r} has non-finite points")
    rate = float(fps or stage.GetTimeCodesPerSecond())
    return to_z_up_metres(stage, frames).astype(np.float32), faces, rate
