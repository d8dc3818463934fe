"""USD stages as usdview shows them (garsim.geometry.usd_stage): winding under leftHanded orientation and mirroring
transforms, mixed polygon sizes, hidden / guide / instanced meshes, UVs, and an animation's timing at the stage's
time codes per second; each case built here with usd-core."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from garsim.geometry.io import MeshError, load_mesh, load_mesh_with_attributes
from garsim.geometry.usd_stage import load_usd_animation, read_usd_mesh


def _stage(path, tcps: float = 24.0):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(tcps)
    return stage


def _box(stage, where: str, faces=None, **attrs):
    from pxr import UsdGeom

    box = trimesh.creation.box()
    mesh = UsdGeom.Mesh.Define(stage, where)
    mesh.CreatePointsAttr(box.vertices.tolist())
    f = box.faces if faces is None else faces
    counts = [len(x) for x in f]
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr([int(i) for x in f for i in x])
    for key, value in attrs.items():
        mesh.GetPrim().GetAttribute(key).Set(value) if mesh.GetPrim().HasAttribute(key) else None
    return mesh, box


def _volume(v, f) -> float:
    return float(trimesh.Trimesh(v, f, process=False).volume)


def test_winding_follows_orientation_and_mirroring(tmp_path):
    from pxr import UsdGeom

    stage = _stage(tmp_path / "w.usda")
    mesh, box = _box(stage, "/Left", faces=box_faces_reversed())
    mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)  # stored clockwise, declared so: outward
    mirrored, _ = _box(stage, "/Mirror/Box")
    UsdGeom.Xformable(stage.GetPrimAtPath("/Mirror")).AddScaleOp().Set((-1.0, 1.0, 1.0))
    stage.GetRootLayer().Save()
    v, f = load_mesh(tmp_path / "w.usda")
    assert len(v) == 16
    assert _volume(v[:8], f[:12]) == pytest.approx(1.0)
    assert _volume(v[8:], f[12:] - 8) == pytest.approx(1.0)  # the mirrored box still faces out


def box_faces_reversed():
    return trimesh.creation.box().faces[:, ::-1]


def test_mixed_polygons_hidden_guide_and_instanced_meshes(tmp_path):
    from pxr import Sdf, Usd, UsdGeom

    stage = _stage(tmp_path / "m.usda")
    quad_tri = [[0, 1, 2, 3], [1, 4, 2]]
    mesh = UsdGeom.Mesh.Define(stage, "/Body")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0)])
    mesh.CreateFaceVertexCountsAttr([4, 3])
    mesh.CreateFaceVertexIndicesAttr([i for x in quad_tri for i in x])
    hidden, _ = _box(stage, "/Hidden")
    UsdGeom.Imageable(hidden).MakeInvisible()
    guide, _ = _box(stage, "/Guide")
    UsdGeom.Imageable(guide).CreatePurposeAttr(UsdGeom.Tokens.guide)
    stage.GetRootLayer().Save()
    v, f = load_mesh(tmp_path / "m.usda")
    assert len(v) == 5 and f.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2]]  # the body alone, fan-triangulated

    inst = _stage(tmp_path / "i.usda")
    UsdGeom.Xform.Define(inst, "/Proto")
    _box(inst, "/Proto/Body")
    avatar = inst.DefinePrim("/World/Avatar", "Xform")
    avatar.GetReferences().AddInternalReference(Sdf.Path("/Proto"))
    avatar.SetInstanceable(True)
    inst.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)  # the prototype itself is not shown
    inst.GetRootLayer().Save()
    assert len(load_mesh(tmp_path / "i.usda")[0]) == 8
    assert Usd.Stage.Open(str(tmp_path / "i.usda")).GetPrimAtPath("/World/Avatar").IsInstance()


def test_uvs_come_with_a_usd_garment(tmp_path):
    from pxr import Sdf, UsdGeom

    stage = _stage(tmp_path / "uv.usda")
    mesh = UsdGeom.Mesh.Define(stage, "/Garment")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set([(0.0, 0.0), (0.5, 0.0), (0.5, 0.5), (0.0, 0.5)])
    stage.GetRootLayer().Save()
    v, f, attrs = load_mesh_with_attributes(tmp_path / "uv.usda")
    np.testing.assert_allclose(attrs.vertex_uvs(f, len(v)), [[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5]], atol=1e-6)


def test_an_animation_keeps_its_timing_at_24_time_codes_per_second(tmp_path):
    """Keys at time codes 0, 12 and 24 of a 24 tcps stage (one second; the body rises 1 m), sampled at 30 fps: 31
    frames a thirtieth of a second apart, points interpolated between the keys; a moving parent transform counts."""
    from pxr import UsdGeom, Vt

    stage = _stage(tmp_path / "a.usda")
    UsdGeom.Xform.Define(stage, "/Root")
    mesh, box = _box(stage, "/Root/Body")
    for k in (0, 12, 24):
        mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy((box.vertices + [0, 0, k / 24]).astype("f4")), float(k))
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/Root")).AddTranslateOp()
    op.Set((0.0, 0.0, 0.0), 0.0)
    op.Set((0.0, 0.0, 0.0), 48.0)  # the parent's keys reach two seconds
    stage.GetRootLayer().Save()
    frames, faces, fps = load_usd_animation(tmp_path / "a.usda", fps=30)
    assert fps == 30 and len(frames) == 61  # two seconds at 30 fps
    z = frames[:, :, 2].min(axis=1)
    np.testing.assert_allclose(z[:31], box.vertices[:, 2].min() + np.arange(31) / 30, atol=1e-5)
    with pytest.raises(MeshError, match="no mesh 'Shirt'"):
        read_usd_mesh(tmp_path / "a.usda", mesh="Shirt", body=True)
