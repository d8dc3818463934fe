"""glTF scenes as they show (garsim.geometry.gltf_scene): skins, morph targets, node motion and samplers against
hand-computed cases, against USD's own skinning (UsdSkel, also read back by garsim.geometry.usd_stage) and
trimesh's static reading, and read through load_mesh / load_mesh_animation."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh
from gltf_builder import Doc

from garsim.geometry.gltf_scene import GltfError, GltfScene
from garsim.geometry.io import MeshError, load_mesh, load_mesh_animation, load_mesh_with_attributes
from garsim.geometry.usd_stage import load_usd_animation, read_usd_mesh


def _z_quat(deg: float) -> list[float]:
    h = np.radians(deg) / 2
    return [0.0, 0.0, float(np.sin(h)), float(np.cos(h))]


def _two_bones(tmp_path: Path, interpolation: str = "LINEAR") -> Path:
    """Joint 1 one metre above joint 0 turns 90 degrees about Z from t = 0 to t = 1. Vertex 0 (0, 2, 0) follows
    joint 1; vertex 1 (0, 1.5, 0) is half joint 0, half joint 1; vertex 2 (1, 0, 0) follows joint 0."""
    d = Doc()
    positions = [[0.0, 2.0, 0.0], [0.0, 1.5, 0.0], [1.0, 0.0, 0.0]]
    joints = d.add(np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0]]), 5123)
    weights = d.add(np.array([[255, 0, 0, 0], [128, 128, 0, 0], [255, 0, 0, 0]]), 5121, normalized=True)
    m = d.mesh(positions, [[0, 1, 2]], JOINTS_0=joints, WEIGHTS_0=weights)
    j1 = d.node(name="j1", translation=[0.0, 1.0, 0.0])
    j0 = d.node(name="j0", children=[j1])
    ibm = np.stack([np.eye(4), np.linalg.inv(np.array([[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1.0]]))])
    d.doc["skins"] = [{"joints": [j0, j1], "inverseBindMatrices": d.add(ibm.transpose(0, 2, 1).reshape(2, 16))}]
    skinned = d.node(mesh=m, skin=0, translation=[5.0, 5.0, 5.0])  # a skinned node's own transform is ignored
    d.animate([(j1, "rotation", [0.0, 1.0], [_z_quat(0), _z_quat(90)], interpolation)])
    return d.write(tmp_path / "bones.glb", [j0, skinned])


def test_a_two_bone_skin_moves_vertices_as_computed_by_hand(tmp_path):
    scene = GltfScene.read(_two_bones(tmp_path))
    np.testing.assert_allclose(scene.vertices(), [[0, 2, 0], [0, 1.5, 0], [1, 0, 0]], atol=1e-6)  # the bind pose
    frames = scene.vertices(np.array([0.0, 0.5, 1.0, 3.0]))
    s = np.sqrt(0.5)
    np.testing.assert_allclose(frames[0], scene.vertices(), atol=1e-6)
    np.testing.assert_allclose(frames[1, 0], [-s, 1 + s, 0], atol=1e-6)  # slerp: 45 degrees halfway
    np.testing.assert_allclose(frames[2], [[-1, 1, 0], [-0.25, 1.25, 0], [1, 0, 0]], atol=3e-3)  # weights 128/255
    np.testing.assert_allclose(frames[3], frames[2], atol=1e-9)  # held at the last key
    assert scene.animations == ["move"] and scene.duration() == (0.0, 1.0)
    assert len(scene.sample_times(30)) == 31


def test_step_and_cubic_samplers_and_morph_weights(tmp_path):
    """Morph weights from the mesh at rest, animated: STEP holds a key; CUBICSPLINE follows the Hermite curve."""
    d = Doc()
    base = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    up = np.array([[0.0, 0, 1]] * 3)
    m = d.mesh(base, [[0, 1, 2]], targets=[up, 2 * up])
    d.doc["meshes"][m]["weights"] = [0.5, 0.0]
    n = d.node(mesh=m, translation=[0.0, 0.0, 10.0])
    # weights: STEP keys (0, 1) at t=0, (1, 0) at t=1; translation: CUBICSPLINE, x from 0 to 1 with zero tangents
    d.animate([(n, "weights", [0.0, 1.0], [[0.0, 1.0], [1.0, 0.0]], "STEP")])
    cubic = [[[0, 0, 0], [0, 0, 10], [0, 0, 0]], [[0, 0, 0], [1, 0, 10], [0, 0, 0]]]
    d.doc["animations"][0]["samplers"].append(
        {
            "input": d.add(np.array([0.0, 1.0])),
            "output": d.add(np.asarray(cubic, float).reshape(-1, 3)),
            "interpolation": "CUBICSPLINE",
        }
    )
    d.doc["animations"][0]["channels"].append({"sampler": 1, "target": {"node": n, "path": "translation"}})
    scene = GltfScene.read(d.write(tmp_path / "keys.gltf", [n]))
    np.testing.assert_allclose(scene.vertices(), base + [0, 0, 10.5], atol=1e-6)  # 0.5 of the first target
    f = scene.vertices(np.array([0.25, 0.999, 1.0]))
    x = 3 * 0.25**2 - 2 * 0.25**3  # Hermite with zero tangents
    np.testing.assert_allclose(f[0], base + [x, 0, 12], atol=1e-6)  # weights (0, 1): 2 * up
    np.testing.assert_allclose(f[1, :, 2], 12, atol=1e-6)  # STEP holds until the key
    np.testing.assert_allclose(f[2], base + [1, 0, 11], atol=1e-6)


def test_static_scenes_read_like_trimesh(tmp_path):
    """Without skins or animation the reader gives trimesh's vertices, order and faces (two nodes, one nested,
    with translation / rotation / scale and a matrix)."""
    box = trimesh.creation.box()
    ico = trimesh.creation.icosphere(subdivisions=1)
    scene = trimesh.Scene()
    t1 = trimesh.transformations.compose_matrix(translate=[1, 2, 3], angles=[0.3, 0.2, 0.1], scale=[2, 2, 2])
    scene.add_geometry(box, node_name="box", transform=t1)
    scene.add_geometry(
        ico, node_name="ico", parent_node_name="box", transform=trimesh.transformations.translation_matrix([0, 1, 0])
    )
    path = tmp_path / "static.glb"
    path.write_bytes(scene.export(file_type="glb"))
    expected = trimesh.load(str(path), force="mesh", process=False)
    v, f = load_mesh(path)
    np.testing.assert_allclose(v, expected.vertices, atol=1e-5)
    np.testing.assert_array_equal(f, expected.faces)


def _usd_skinned_points(rest_local, anim, positions, joint_idx, joint_w, times):
    """UsdSkel's skinning of a joint chain: rest_local (J, 4, 4) column matrices, anim per time (J, T, R, S)."""
    from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)  # centimetres: the reader converts
    root = UsdSkel.Root.Define(stage, "/Root")
    skel = UsdSkel.Skeleton.Define(stage, "/Root/Skel")
    names = ["j0", "j0/j1", "j0/j1/j2"]
    skel.CreateJointsAttr(names)
    world, worlds = np.eye(4), []
    for m in rest_local:
        world = world @ m
        worlds.append(world)
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(w.T.tolist()) for w in worlds]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(m.T.tolist()) for m in rest_local]))
    a = UsdSkel.Animation.Define(stage, "/Root/Skel/Anim")
    a.CreateJointsAttr(names)
    tr, rot, sc = a.CreateTranslationsAttr(), a.CreateRotationsAttr(), a.CreateScalesAttr()
    for t, (ts, qs, ss) in zip(times, anim):
        tr.Set(Vt.Vec3fArray([Gf.Vec3f(*x) for x in ts]), float(t))
        rot.Set(Vt.QuatfArray([Gf.Quatf(float(q[3]), Gf.Vec3f(*q[:3])) for q in qs]), float(t))
        sc.Set(Vt.Vec3hArray([Gf.Vec3h(*x) for x in ss]), float(t))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([a.GetPath()])
    mesh = UsdGeom.Mesh.Define(stage, "/Root/Mesh")
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in positions]))
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    k = joint_idx.shape[1]
    binding.CreateJointIndicesPrimvar(False, k).Set(Vt.IntArray(joint_idx.ravel().tolist()))
    binding.CreateJointWeightsPrimvar(False, k).Set(Vt.FloatArray(joint_w.ravel().tolist()))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1))
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.TraverseInstanceProxies())
    skel_query, skin_query = cache.GetSkelQuery(skel), cache.GetSkinningQuery(mesh.GetPrim())
    out = []
    for t in times:
        xforms = skel_query.ComputeSkinningTransforms(float(t))
        points = Vt.Vec3fArray([Gf.Vec3f(*p) for p in positions])
        assert skin_query.ComputeSkinnedPoints(xforms, points, float(t))
        out.append(np.array(points))
    return np.stack(out), stage


def test_skinning_matches_usdskel_on_a_random_rig(tmp_path):
    """A three-joint chain with random rest transforms, random animated translation / rotation / scale keys and
    four random weights per vertex: the glTF reader and USD's UsdSkel skin the mesh alike at every key, and
    garsim's USD reader (usd_stage) gives UsdSkel's points from the saved stage, in metres."""
    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 3))
    joint_idx = np.stack([rng.permutation(3)[:2] for _ in range(40)])
    joint_idx = np.concatenate([joint_idx, joint_idx[:, :1], joint_idx[:, 1:]], axis=1)
    joint_w = rng.random((40, 4))
    joint_w /= joint_w.sum(1, keepdims=True)
    rest = []
    for j in range(3):
        q = rng.normal(size=4)
        m = np.eye(4)
        m[:3, :3] = trimesh.transformations.quaternion_matrix(np.roll(q / np.linalg.norm(q), 1))[:3, :3]
        m[:3, 3] = rng.normal(size=3) * (j > 0)
        rest.append(m)
    times = [0.0, 1.0, 2.0]
    anim = [
        (
            rng.normal(size=(3, 3)),
            (lambda q: q / np.linalg.norm(q, axis=1, keepdims=True))(rng.normal(size=(3, 4))),
            1 + 0.2 * rng.random((3, 3)),
        )
        for _ in times
    ]
    expected, stage = _usd_skinned_points(np.array(rest), anim, v, joint_idx, joint_w, times)
    stage.GetRootLayer().Export(str(tmp_path / "rig.usda"))
    frames, _, _ = load_usd_animation(tmp_path / "rig.usda")  # its only mesh, skinned by UsdSkel, in metres
    np.testing.assert_allclose(frames, 0.01 * expected, atol=1e-6)
    at_rest = read_usd_mesh(tmp_path / "rig.usda", z_up_metres=True, rest=True)[0]  # the skeleton's rest pose
    np.testing.assert_allclose(at_rest, 0.01 * v, atol=1e-6)  # bound at rest: the mesh as stored
    np.testing.assert_allclose(read_usd_mesh(tmp_path / "rig.usda", z_up_metres=True)[0], frames[0], atol=1e-6)

    d = Doc()
    m = d.mesh(v, [[0, 1, 2]], JOINTS_0=d.add(joint_idx, 5123), WEIGHTS_0=d.add(joint_w))
    j2 = d.node(matrix=rest[2].T.ravel().tolist())
    j1 = d.node(matrix=rest[1].T.ravel().tolist(), children=[j2])
    j0 = d.node(matrix=rest[0].T.ravel().tolist(), children=[j1])
    for n in (j0, j1, j2):  # an animated node has TRS, not a matrix (its rest only enters the bind matrices)
        del d.doc["nodes"][n]["matrix"]
    bind = [rest[0], rest[0] @ rest[1], rest[0] @ rest[1] @ rest[2]]
    ibm = np.stack([np.linalg.inv(b).T.ravel() for b in bind])
    d.doc["skins"] = [{"joints": [j0, j1, j2], "inverseBindMatrices": d.add(ibm)}]
    mesh_node = d.node(mesh=m, skin=0)
    channels = []
    for j, node in enumerate((j0, j1, j2)):
        channels.append((node, "translation", times, [a[0][j] for a in anim], "LINEAR"))
        channels.append((node, "rotation", times, [a[1][j] for a in anim], "LINEAR"))
        channels.append((node, "scale", times, [a[2][j] for a in anim], "LINEAR"))
    d.animate(channels)
    got = GltfScene.read(d.write(tmp_path / "rig.glb", [j0, mesh_node])).vertices(np.array(times))
    assert np.abs(expected[1] - expected[0]).max() > 0.5  # the rig moves: a real comparison
    np.testing.assert_allclose(got, expected, atol=2e-3)  # USD stores scales as halves (3 digits)


def test_load_mesh_reads_a_skinned_body_as_shown_and_samples_its_animation(tmp_path):
    path = _two_bones(tmp_path)
    v, f = load_mesh(path)
    np.testing.assert_allclose(v, [[0, 2, 0], [0, 1.5, 0], [1, 0, 0]], atol=1e-6)
    frames, faces = load_mesh_animation(path, fps=4)
    assert frames.shape == (5, 3, 3) and frames.dtype == np.float32
    np.testing.assert_array_equal(faces, f)
    np.testing.assert_allclose(frames[-1, 0], [-1, 1, 0], atol=1e-6)
    y_up, _ = load_mesh_animation(path, fps=4, y_up=True)
    np.testing.assert_allclose(y_up[-1, 0], [-1, 0, 1], atol=1e-6)  # (x, y, z) -> (x, -z, y)
    with pytest.raises(MeshError, match="no animation 'run'; it has 'move'"):
        load_mesh_animation(path, fps=4, animation="run")


def test_uvs_come_back_in_obj_convention_and_bad_files_are_named(tmp_path):
    d = Doc()
    uv = np.array([[0.0, 0.0], [1.0, 0.25], [0.0, 1.0]])
    m = d.mesh([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], TEXCOORD_0=d.add(uv))
    path = d.write(tmp_path / "uv.glb", [d.node(mesh=m)])
    _, _, attrs = load_mesh_with_attributes(path)
    np.testing.assert_allclose(attrs.uvs, [[0, 1], [1, 0.75], [0, 0]], atol=1e-6)  # glTF's v runs down
    doc = json.loads(d.write(tmp_path / "uv.gltf", [0]).read_text())  # its buffer embedded as a data URI
    for name, change, message in (
        ("draco.gltf", {"extensionsRequired": ["KHR_draco_mesh_compression"]}, "export it without compression"),
        ("web.gltf", {"buffers": [{"byteLength": 4, "uri": "https://example.com/a.bin"}]}, "reads no network"),
        ("gone.gltf", {"buffers": [{"byteLength": 4, "uri": "missing.bin"}]}, "missing.bin cannot be read"),
    ):
        p = tmp_path / name
        p.write_text(json.dumps(dict(doc, **change)))
        with pytest.raises(MeshError, match=message):
            load_mesh(p)
    p = tmp_path / "short.glb"
    p.write_bytes(path.read_bytes()[:-8])
    with pytest.raises(GltfError, match="truncated GLB"):
        GltfScene.read(p)
    doc["accessors"][0]["count"] = 1000  # more vertices than the buffer holds
    p = tmp_path / "long.gltf"
    p.write_text(json.dumps(doc))
    with pytest.raises(GltfError, match="past the end of its buffer"):
        GltfScene.read(p)


def test_interleaved_sparse_and_strip_primitives(tmp_path):
    """Positions interleaved with normals (byteStride 24), a sparse morph target (two of four vertices moved) and a
    triangle strip: read as the specification lays them out."""
    d = Doc()
    pos = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    interleaved = np.concatenate([pos, np.tile([0.0, 0, 1], (4, 1))], axis=1).astype("<f4").tobytes()
    d.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(d.blob), "byteLength": 96, "byteStride": 24})
    d.blob += interleaved
    view = len(d.doc["bufferViews"]) - 1
    d.doc["accessors"].append({"bufferView": view, "componentType": 5126, "count": 4, "type": "VEC3"})
    position = len(d.doc["accessors"]) - 1
    rows, values = d.add(np.array([1, 3]), 5125), d.add(np.array([[0.0, 0, 2], [0, 0, 4]]))
    sparse = {"count": 2, "indices": {"bufferView": d.doc["accessors"][rows]["bufferView"], "componentType": 5125}}
    sparse["values"] = {"bufferView": d.doc["accessors"][values]["bufferView"]}
    d.doc["accessors"].append({"componentType": 5126, "count": 4, "type": "VEC3", "sparse": sparse})
    target = len(d.doc["accessors"]) - 1
    prim = {"attributes": {"POSITION": position}, "mode": 5, "targets": [{"POSITION": target}]}
    d.doc["meshes"].append({"primitives": [prim], "weights": [0.5]})
    scene = GltfScene.read(d.write(tmp_path / "strip.glb", [d.node(mesh=0)]))
    np.testing.assert_array_equal(scene.faces, [[0, 1, 2], [1, 3, 2]])  # the second triangle flipped back
    np.testing.assert_allclose(scene.vertices(), pos + [[0, 0, 0], [0, 0, 1], [0, 0, 0], [0, 0, 2]], atol=1e-6)


def test_quantised_positions_and_uvs(tmp_path):
    """KHR_mesh_quantization: int16 positions scaled by their node, normalised uint16 UVs, read as numbers."""
    d = Doc()
    pos = np.array([[0, 0, 0], [1000, 0, 0], [0, 1000, 0]])
    m = d.mesh(np.zeros((3, 3)), [[0, 1, 2]], TEXCOORD_0=d.add(np.array([[0, 0], [65535, 0], [0, 65535]]), 5123, True))
    d.doc["accessors"][d.doc["meshes"][m]["primitives"][0]["attributes"]["POSITION"]] = d.doc["accessors"][
        d.add(pos, 5122)
    ]
    d.doc["extensionsRequired"] = d.doc["extensionsUsed"] = ["KHR_mesh_quantization"]
    scene = GltfScene.read(d.write(tmp_path / "q.glb", [d.node(mesh=m, scale=[0.001] * 3)]))
    np.testing.assert_allclose(scene.vertices(), [[0, 0, 0], [1, 0, 0], [0, 1, 0]], atol=1e-9)
    np.testing.assert_allclose(scene.uvs, [[0, 0], [1, 0], [0, 1]], atol=1e-9)


def test_mirrored_nodes_stitched_strips_partial_uvs_and_float32_key_times(tmp_path):
    """A node scaled by -1 shows the other side (winding reversed); a strip's stitching triangles are dropped; a
    primitive without UVs gets (0, 0); keys at k / 24 s stored in float32 keep their last frame."""
    d = Doc()
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    m = d.mesh(tri, [[0, 1, 2]], TEXCOORD_0=d.add(np.array([[0.0, 0], [1, 0], [0, 1]])))
    strip = {"attributes": {"POSITION": d.add(np.arange(24.0).reshape(8, 3))}, "mode": 5}
    strip["indices"] = d.add(np.array([0, 1, 2, 3, 3, 4, 4, 5, 6, 7]), 5125)
    d.doc["meshes"][m]["primitives"].append(strip)
    n = d.node(mesh=m, scale=[-1.0, 1.0, 1.0])
    times = (np.arange(51) / 24).astype(np.float32)
    d.animate([(n, "translation", times.tolist(), [[0.0, 0.01 * k, 0] for k in range(51)], "LINEAR")])
    scene = GltfScene.read(d.write(tmp_path / "m.glb", [n]))
    assert scene.faces[0].tolist() == [2, 1, 0]  # mirrored: the winding reversed
    assert len(scene.faces) == 1 + 4  # two quads from the strip, its two stitching triangles dropped
    np.testing.assert_allclose(scene.uvs[3:], 0.0)
    assert scene.uvs.shape == (11, 2)
    frames = scene.frames(24.0)
    assert len(frames) == 51
    np.testing.assert_allclose(frames[-1, 0], [0, 0.5, 0], atol=1e-6)


def test_keys_of_another_scenes_nodes_do_not_stretch_the_clip(tmp_path):
    d = Doc()
    m = d.mesh([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    shown, other = d.node(mesh=m), d.node(mesh=m)
    d.animate([(shown, "translation", [0.0, 1.0], [[0, 0, 0], [1, 0, 0]], "LINEAR")])
    d.animate([(other, "translation", [0.0, 5.0], [[0, 0, 0], [1, 0, 0]], "LINEAR")])
    second = d.doc["animations"].pop()  # one clip moving a node of this scene and one of another (0 .. 5 s)
    d.doc["animations"][0]["samplers"].append(second["samplers"][0])
    d.doc["animations"][0]["channels"].append({"sampler": 1, "target": {"node": other, "path": "translation"}})
    path = d.write(tmp_path / "two.glb", [shown])
    assert GltfScene.read(path).duration() == (0.0, 1.0)
    doc = json.loads(path.read_bytes()[20 : 20 + struct.unpack_from("<I", path.read_bytes(), 12)[0]])
    assert doc["animations"][0]["channels"][1]["target"]["node"] == other  # the other node's keys are in the file
