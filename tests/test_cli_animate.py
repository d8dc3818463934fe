"""`garsim animate` as a user runs it: every export re-read by an independent reader against per-frame drapes,
pose files, Y-up / centimetre round trips, pins, and a clean stdout."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from export_readers import gltf_frames, read_gltf, z_up

from garsim.cli import main


@pytest.fixture(scope="module")
def case(tmp_path_factory, anny_body):
    """A 300-vertex skirt on the default Anny body, three target poses as an .npz of body vertices."""
    from garsim.bodies.poses import motion, pose_bodies
    from garsim.garments.templates import make_garment
    from garsim.geometry.io import save_mesh

    folder = tmp_path_factory.mktemp("animate")
    g = make_garment("skirt", anny_body, target_vertices=300)
    save_mesh(folder / "skirt.obj", g.vertices, g.faces)
    canonical = anny_body.canonical().vertices
    save_mesh(folder / "canonical.obj", canonical, anny_body.faces)
    bodies = pose_bodies(anny_body, motion("walk", 3))
    np.savez(folder / "bodies.npz", vertices=bodies)
    return folder, g, canonical, bodies, anny_body.faces


def test_every_export_matches_the_per_frame_drapes(case, tmp_path):
    """GLB, USD and PC2 written by `animate` (no temporal smoothing) hold, frame by frame and in vertex order, what
    `GarSim.pretrained().drape` gives for each target body alone; the body comes along in each file."""
    from pxr import Usd, UsdGeom

    from garsim import GarSim
    from garsim.export import read_pc2

    folder, g, canonical, bodies, faces = case
    sim = GarSim.pretrained()
    expected = np.stack([sim.drape((canonical, faces), (b, faces), (g.vertices, g.faces)) for b in bodies])
    assert np.abs(expected[-1] - expected[0]).max() > 0.01  # the frames differ: a real comparison
    base = ["animate", "--garment", str(folder / "skirt.obj"), "--canonical", str(folder / "canonical.obj")]
    base += ["--targets", str(folder / "bodies.npz"), "--smoothing", "0", "--quiet"]
    for name in ("a.glb", "a.usdc", "a.pc2"):
        assert main([*base, "--out", str(tmp_path / name)]) == 0

    doc, blob = read_gltf(tmp_path / "a.glb")
    garment, body = gltf_frames(doc, blob, "Garment"), gltf_frames(doc, blob, "Body")
    np.testing.assert_allclose(z_up(garment["frames"]), expected, atol=1e-5)
    np.testing.assert_array_equal(garment["faces"], g.faces)
    np.testing.assert_allclose(z_up(body["frames"]), bodies, atol=1e-5)

    stage = Usd.Stage.Open(str(tmp_path / "a.usdc"))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Scene/Garment")).GetPointsAttr()
    assert points.GetTimeSamples() == [0.0, 1.0, 2.0]
    got = np.stack([np.asarray(points.Get(float(k))) for k in range(3)])
    np.testing.assert_allclose(got, expected, atol=1e-5)
    np.testing.assert_allclose(np.asarray(points.Get()), expected[0], atol=1e-5)  # a static reader: frame 0
    body_points = UsdGeom.Mesh(stage.GetPrimAtPath("/Scene/Body")).GetPointsAttr()
    np.testing.assert_allclose(np.asarray(body_points.Get(2.0)), bodies[2], atol=1e-5)

    frames, _, _ = read_pc2(tmp_path / "a.pc2")
    np.testing.assert_allclose(frames, expected, atol=1e-5)
    np.testing.assert_allclose(read_pc2(tmp_path / "a_body.pc2")[0], bodies, atol=1e-5)


def test_y_up_centimetre_input_round_trips(case, tmp_path):
    """The same scene in Blender's Y up and centimetres with --up y --units cm: the PC2 holds the Z-up run's frames
    in Y-up centimetres, the USD declares its axis and unit, the GLB (metres, Y up by the standard) is the same."""
    from pxr import Usd, UsdGeom

    from garsim.export import read_pc2
    from garsim.geometry.io import from_internal, save_mesh

    folder, g, canonical, bodies, faces = case
    save_mesh(tmp_path / "skirt.obj", from_internal(g.vertices, "y", "cm"), g.faces)
    save_mesh(tmp_path / "canonical.obj", from_internal(canonical, "y", "cm"), faces)
    np.savez(tmp_path / "bodies.npz", vertices=from_internal(bodies, "y", "cm"))
    z_up_run = ["animate", "--garment", str(folder / "skirt.obj"), "--canonical", str(folder / "canonical.obj")]
    z_up_run += ["--targets", str(folder / "bodies.npz"), "--prior-only", "--quiet"]
    y_up_run = ["animate", "--garment", str(tmp_path / "skirt.obj"), "--canonical", str(tmp_path / "canonical.obj")]
    y_up_run += ["--targets", str(tmp_path / "bodies.npz"), "--prior-only", "--quiet", "--up", "y", "--units", "cm"]
    for name in ("z.pc2", "z.glb"):
        assert main([*z_up_run, "--out", str(tmp_path / name)]) == 0
    for name in ("y.pc2", "y.glb", "y.usda"):
        assert main([*y_up_run, "--out", str(tmp_path / name)]) == 0
    z_frames = read_pc2(tmp_path / "z.pc2")[0]
    np.testing.assert_allclose(read_pc2(tmp_path / "y.pc2")[0], from_internal(z_frames, "y", "cm"), atol=2e-3)
    gz = gltf_frames(*read_gltf(tmp_path / "z.glb"), "Garment")["frames"]
    gy = gltf_frames(*read_gltf(tmp_path / "y.glb"), "Garment")["frames"]
    np.testing.assert_allclose(gy, gz, atol=2e-5)
    stage = Usd.Stage.Open(str(tmp_path / "y.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Scene/Garment")).GetPointsAttr()
    np.testing.assert_allclose(np.asarray(points.Get(2.0)), from_internal(z_frames[2], "y", "cm"), atol=2e-3)
    # without the flags the Y-up centimetre garment is refused, and the message names them
    bad = [a for a in y_up_run if a not in ("--up", "y", "--units", "cm")]
    assert main([*bad, "--out", str(tmp_path / "bad.pc2")]) == 2
    assert not (tmp_path / "bad.pc2").exists()


def test_pose_files_drive_the_default_body(case, tmp_path, anny_body):
    """--poses: a JSON of joint angles, resampled with --interpolate, and an NPZ of Anny bone rotations give the
    drapes on the bodies those poses make; pins follow the prior exactly."""
    from garsim import GarSim
    from garsim.bodies.poses import angles_to_pose, pose_bodies, resample_poses, unbatch
    from garsim.export import read_pc2

    folder, g, canonical, _, faces = case
    keyframes = [
        {"shoulder_elevation_L": -60.0, "shoulder_elevation_R": -60.0},
        {"shoulder_elevation_L": -60.0, "shoulder_elevation_R": -60.0, "hip_flexion_L": 30.0, "knee_flexion_L": 20.0},
    ]
    (tmp_path / "keys.json").write_text(json.dumps(keyframes))
    poses = resample_poses([unbatch(angles_to_pose(k), 0) for k in keyframes], 4)
    bodies = pose_bodies(anny_body, poses)
    pins = np.flatnonzero(g.vertices[:, 2] > g.vertices[:, 2].max() - 0.01)
    np.savetxt(tmp_path / "pins.txt", pins, fmt="%d")
    base = ["animate", "--garment", str(folder / "skirt.obj"), "--prior-only", "--quiet"]
    argv = [*base, "--poses", str(tmp_path / "keys.json"), "--interpolate", "4", "--pinned", str(tmp_path / "pins.txt")]
    assert main([*argv, "--out", str(tmp_path / "j.pc2")]) == 0
    frames = read_pc2(tmp_path / "j.pc2")[0]
    prior = GarSim.prior_only()
    expected = [prior.drape((canonical, faces), (b, faces), (g.vertices, g.faces)) for b in bodies]
    assert frames.shape == (4, len(g.vertices), 3)
    np.testing.assert_allclose(frames, np.stack(expected), atol=1e-5)
    np.testing.assert_allclose(read_pc2(tmp_path / "j_body.pc2")[0], bodies, atol=1e-5)
    # the same poses as Anny bone rotations (T, 3) in an .npz: the same animation
    np.savez(tmp_path / "bones.npz", **{bone: np.stack([p[bone] for p in poses]) for bone in poses[0]})
    assert main([*base, "--poses", str(tmp_path / "bones.npz"), "--out", str(tmp_path / "n.pc2")]) == 0
    np.testing.assert_allclose(read_pc2(tmp_path / "n.pc2")[0], frames, atol=1e-5)


@pytest.mark.parametrize(
    "content, expected",
    [
        ("[]", "non-empty list of frames"),
        ('[{"hip_flexion_L": 10, "upperleg01.L": [0, 0, 0]}]', "mixes joint angles and bones"),
        ('[{"upperleg01.L": [0, 0]}]', "axis-angle"),
        ('[{"upperleg01.L": [[1, 0, 0], [0, 2, 0], [0, 0, 1]]}]', "not a rotation"),
        ('[{"hip_flexion_L": "a lot"}]', "finite number of degrees"),
        ('[{"no_such_bone": [0, 0, 0]}]', "unknown bone"),
        ("{oops", "not a readable pose file"),
    ],
)
def test_bad_pose_files_are_one_line_errors(case, tmp_path, capsys, content, expected):
    folder = case[0]
    (tmp_path / "p.json").write_text(content)
    argv = ["animate", "--garment", str(folder / "skirt.obj"), "--poses", str(tmp_path / "p.json"), "--prior-only"]
    assert main([*argv, "--quiet", "--out", str(tmp_path / "a.pc2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "a.pc2").exists()


def test_stdout_carries_only_the_written_paths(case, tmp_path):
    """With the shipped model (Warp's kernels, the refinement), stdout is exactly the files written; logs and the
    progress bar go to stderr."""
    folder = case[0]
    argv = ["animate", "--garment", str(folder / "skirt.obj"), "--motion", "walk", "--frames", "2"]
    out = subprocess.run(
        [sys.executable, "-m", "garsim.cli", *argv, "--out", str(tmp_path / "w.pc2")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.splitlines() == [str(tmp_path / n) for n in ("w.pc2", "w.obj", "w_body.pc2", "w_body.obj")]


def test_npz_output_is_the_viewers_sequence_with_the_prior(case, tmp_path):
    """`animate --out x.npz` writes what `garsim view` reads: the drape, the body and the skinning prior, so the
    viewer can compare them and colour the correction."""
    from garsim.export import read_pc2
    from garsim.view import load_view_data

    folder, g, _, bodies, _ = case
    base = ["animate", "--garment", str(folder / "skirt.obj"), "--canonical", str(folder / "canonical.obj")]
    base += ["--targets", str(folder / "bodies.npz"), "--smoothing", "0", "--quiet"]
    assert main([*base, "--out", str(tmp_path / "a.npz")]) == 0
    assert main([*base, "--out", str(tmp_path / "a.pc2")]) == 0
    assert main([*base, "--prior-only", "--out", str(tmp_path / "p.pc2")]) == 0
    view = load_view_data(tmp_path / "a.npz")
    np.testing.assert_allclose(view.frames, read_pc2(tmp_path / "a.pc2")[0], atol=1e-5)
    np.testing.assert_allclose(view.prior_frames, read_pc2(tmp_path / "p.pc2")[0], atol=1e-5)
    np.testing.assert_allclose(view.body_frames, bodies, atol=1e-5)
    assert view.correction().max() > 0.005
    # its bodies ('body_frames') are targets again: the same drape
    again = ["animate", "--garment", str(folder / "skirt.obj"), "--canonical", str(folder / "canonical.obj")]
    again += ["--targets", str(tmp_path / "a.npz"), "--smoothing", "0", "--quiet", "--out", str(tmp_path / "b.pc2")]
    assert main(again) == 0
    np.testing.assert_allclose(read_pc2(tmp_path / "b.pc2")[0], read_pc2(tmp_path / "a.pc2")[0], atol=1e-5)
    # in another axis and unit: the garment and canonical body given Y up in cm, the .npz's bodies are converted
    from garsim.geometry.io import from_internal, load_mesh, save_mesh

    for name in ("skirt", "canonical"):
        v, f = load_mesh(folder / f"{name}.obj")
        save_mesh(tmp_path / f"{name}_ycm.obj", from_internal(v, "y", "cm"), f)
    ycm = ["animate", "--garment", str(tmp_path / "skirt_ycm.obj"), "--canonical", str(tmp_path / "canonical_ycm.obj")]
    ycm += ["--targets", str(tmp_path / "a.npz"), "--up", "y", "--units", "cm", "--smoothing", "0", "--quiet"]
    assert main([*ycm, "--out", str(tmp_path / "c.pc2")]) == 0
    got = read_pc2(tmp_path / "c.pc2")[0]  # the PC2 is written in the input's axis and unit
    np.testing.assert_allclose(got, from_internal(read_pc2(tmp_path / "a.pc2")[0], "y", "cm"), atol=2e-3)


def test_a_folder_of_unpadded_frames_plays_in_number_order_and_normals_face_as_given(case, tmp_path):
    """Target OBJs named frame_1 .. frame_10 (no zero padding) are the frames in number order, not name order; a
    garment whose normals point against its winding gets per-frame normals that point the same way."""
    from pxr import Usd, UsdGeom

    from garsim.export import read_pc2
    from garsim.geometry.io import MeshAttributes, save_mesh
    from garsim.geometry.mesh import vertex_normals

    folder, g, _, bodies, faces = case
    targets = tmp_path / "targets"
    targets.mkdir()
    numbers = [1, 2, 10]
    for k, n in enumerate(numbers):
        save_mesh(targets / f"frame_{n}.obj", bodies[k], faces)
    inward = -vertex_normals(g.vertices, g.faces)
    garment = tmp_path / "inward.obj"
    save_mesh(garment, g.vertices, g.faces, attributes=MeshAttributes(normals=inward, normal_faces=g.faces))
    base = ["animate", "--garment", str(garment), "--canonical", str(folder / "canonical.obj"), "--prior-only"]
    base += ["--targets", str(targets), "--quiet"]
    assert main([*base, "--out", str(tmp_path / "a.pc2")]) == 0
    np.testing.assert_allclose(read_pc2(tmp_path / "a_body.pc2")[0], bodies, atol=1e-5)
    assert main([*base, "--out", str(tmp_path / "a.usda")]) == 0
    stage = Usd.Stage.Open(str(tmp_path / "a.usda"))  # held: its prims live as long as the stage
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Scene/Garment"))
    for t in range(len(numbers)):
        points = np.asarray(mesh.GetPointsAttr().Get(float(t)))
        normals = np.asarray(mesh.GetNormalsAttr().Get(float(t)))
        assert np.mean(np.sum(normals * vertex_normals(points, g.faces), axis=1) < 0) > 0.99


def test_a_skinned_gltf_body_drives_animate_like_its_frames(case, tmp_path, capsys, anny_body):
    """A glTF of the body skinned by Anny's own bones and weights (the T-pose stored, the walk animated), given as
    both --canonical and --targets, drapes like the same frames from an .npz; a wrong --animation is named."""
    from gltf_builder import skinned_body

    from garsim.bodies.poses import batched_matrices, motion, stack_poses
    from garsim.export import read_pc2

    folder, g, canonical, bodies, faces = case
    walk = anny_body.pose_batch(batched_matrices(stack_poses(motion("walk", 3))))[1]
    tpose = anny_body.pose_batch(batched_matrices(stack_poses([anny_body.t_pose()])))[1][0]
    rig = (anny_body.rest_vertices, faces, anny_body.skin_weights, anny_body.skin_indices, tpose, walk)
    glb = skinned_body(tmp_path / "walk.glb", *rig, fps=24)
    base = ["animate", "--garment", str(folder / "skirt.obj"), "--smoothing", "0", "--quiet", "--fps", "24"]
    assert main([*base, "--canonical", str(glb), "--targets", str(glb), "--out", str(tmp_path / "a.pc2")]) == 0
    npz = ["--canonical", str(folder / "canonical.obj"), "--targets", str(folder / "bodies.npz")]
    assert main([*base, *npz, "--out", str(tmp_path / "b.pc2")]) == 0
    np.testing.assert_allclose(read_pc2(tmp_path / "a_body.pc2")[0], bodies, atol=1e-5)
    a, b = read_pc2(tmp_path / "a.pc2")[0], read_pc2(tmp_path / "b.pc2")[0]
    assert a.shape == (3, len(g.vertices), 3)
    np.testing.assert_allclose(a, b, atol=1e-4)
    argv = [*base, "--canonical", str(glb), "--targets", str(glb), "--animation", "run", "--prior-only"]
    assert main([*argv, "--out", str(tmp_path / "c.pc2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no animation 'run'; it has 'move'" in err[0]


def test_animate_reads_its_own_usd_and_pc2_bodies_as_targets(case, tmp_path, capsys):
    """The body `animate` writes beside the garment (USD time samples, a PC2 cache) drives a second run like the
    .npz it came from; a USD stage in centimetres and Y up is brought to the run's --up/--units."""
    from pxr import Usd, UsdGeom, Vt

    from garsim.export import read_pc2
    from garsim.geometry.io import z_up_to_y_up

    folder, g, canonical, bodies, faces = case
    base = ["animate", "--garment", str(folder / "skirt.obj"), "--canonical", str(folder / "canonical.obj")]
    base += ["--smoothing", "0", "--quiet", "--prior-only"]
    assert main([*base, "--targets", str(folder / "bodies.npz"), "--out", str(tmp_path / "a.usdc")]) == 0
    assert main([*base, "--targets", str(folder / "bodies.npz"), "--out", str(tmp_path / "a.pc2")]) == 0
    expected = read_pc2(tmp_path / "a.pc2")[0]
    for src in ("a.usdc", "a_body.pc2"):
        assert main([*base, "--targets", str(tmp_path / src), "--out", str(tmp_path / f"from_{src}.pc2")]) == 0
        np.testing.assert_allclose(read_pc2(tmp_path / f"from_{src}.pc2")[0], expected, atol=1e-5)

    stage = Usd.Stage.Open(str(tmp_path / "a.usdc"))  # the same body, restated in Y-up centimetres
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Scene/Body")).GetPointsAttr()
    for k, b in enumerate(bodies):
        points.Set(Vt.Vec3fArray.FromNumpy((100 * z_up_to_y_up(b)).astype("f4")), k)
    stage.GetRootLayer().Export(str(tmp_path / "cm.usda"))
    assert main([*base, "--targets", str(tmp_path / "cm.usda"), "--out", str(tmp_path / "cm.pc2")]) == 0
    np.testing.assert_allclose(read_pc2(tmp_path / "cm.pc2")[0], expected, atol=1e-5)
    assert (
        main([*base, "--targets", str(tmp_path / "a.usdc"), "--body-mesh", "Shirt", "--out", str(tmp_path / "x.pc2")])
        == 2
    )
    assert "no mesh 'Shirt'; the stage has 'Garment', 'Body'" in capsys.readouterr().err


def test_a_motion_writes_the_body_skinned_to_annys_bones(case, tmp_path, anny_body):
    """With --motion the GLB's body is a mesh skinned to one joint per Anny bone: evaluated as a viewer does
    (garsim.geometry.gltf_scene, checked against UsdSkel) it is the posed body of every frame, in a file a fraction of
    the morph-target one's size; garsim view shows the same body."""
    from garsim.bodies.poses import motion, pose_bodies, pose_bodies_rigged
    from garsim.export import BodySkin, ExportError, write_gltf_animation
    from garsim.geometry.gltf_scene import GltfScene
    from garsim.geometry.io import y_up_to_z_up
    from garsim.view import load_view_data

    folder = case[0]
    argv = ["animate", "--garment", str(folder / "skirt.obj"), "--motion", "walk", "--frames", "4", "--quiet"]
    assert main([*argv, "--prior-only", "--smoothing", "0", "--out", str(tmp_path / "w.glb")]) == 0
    bodies = pose_bodies(anny_body, motion("walk", 4))
    scene = GltfScene.read(tmp_path / "w.glb")
    assert len(scene.doc["skins"][0]["joints"]) == len(anny_body.bone_labels)
    body = next(i for i in scene.instances if i.name == "Body")
    frames = y_up_to_z_up(scene.frames(30.0)[:, body.start : body.stop])
    assert frames.shape == bodies.shape
    np.testing.assert_allclose(frames, bodies, atol=2e-5)
    np.testing.assert_allclose(load_view_data(tmp_path / "w.glb").body_frames, bodies, atol=2e-5)
    long, transforms = pose_bodies_rigged(anny_body, motion("walk", 24))  # at 24 frames, the body alone
    rig = BodySkin(anny_body.rest_vertices, anny_body.skin_weights, anny_body.skin_indices, transforms)
    garment = np.repeat(case[1].vertices[None], 24, axis=0)
    write = [tmp_path / "g.glb", garment, case[1].faces, long, anny_body.faces]
    skinned = write_gltf_animation(*write, body_skin=rig).stat().st_size
    morph = write_gltf_animation(*write).stat().st_size
    assert skinned < 0.4 * morph  # 1.6 against 4.6 MB; the morph file grows by 165 kB a frame, the rig by 3 kB
    with pytest.raises(ExportError, match="lies up to"):  # a rig must pose the frames it stands for
        write_gltf_animation(*write[:3], long[::-1], anny_body.faces, body_skin=rig)


def test_a_usd_avatar_with_eyes_is_its_own_canonical_body(case, tmp_path):
    """A stage with an animated Body (its T-pose at time 0, the walk after it, 24 time codes per second) and an Eyes
    mesh, given as --canonical and --targets: the Body alone is read for both, one frame per time code (--fps
    defaults to the stage's 24), and the drape is the one of the same bodies from an .npz."""
    from pxr import Usd, UsdGeom, Vt

    from garsim.export import read_pc2

    folder, g, canonical, bodies, faces = case
    stage = Usd.Stage.CreateNew(str(tmp_path / "avatar.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)  # USD's fallback is centimetres
    stage.SetTimeCodesPerSecond(24.0)
    body = UsdGeom.Mesh.Define(stage, "/Avatar/Body")
    body.CreateFaceVertexCountsAttr([3] * len(faces))
    body.CreateFaceVertexIndicesAttr(faces.ravel().tolist())
    sequence = np.concatenate([canonical[None], bodies])
    for k, b in enumerate(sequence):
        body.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(b.astype("f4")), float(k))
    eyes = UsdGeom.Mesh.Define(stage, "/Avatar/Eyes")
    eyes.CreatePointsAttr([(0, -0.1, 1.6), (0.02, -0.1, 1.6), (0, -0.1, 1.62)])
    eyes.CreateFaceVertexCountsAttr([3])
    eyes.CreateFaceVertexIndicesAttr([0, 1, 2])
    stage.GetRootLayer().Save()
    np.savez(tmp_path / "seq.npz", vertices=sequence)
    base = ["animate", "--garment", str(folder / "skirt.obj"), "--smoothing", "0", "--quiet", "--prior-only"]
    usd = ["--canonical", str(tmp_path / "avatar.usda"), "--targets", str(tmp_path / "avatar.usda")]  # at 24 fps
    assert main([*base, *usd, "--out", str(tmp_path / "u.pc2")]) == 0
    npz = ["--canonical", str(folder / "canonical.obj"), "--targets", str(tmp_path / "seq.npz")]
    assert main([*base, *npz, "--out", str(tmp_path / "n.pc2")]) == 0
    got, expected = read_pc2(tmp_path / "u.pc2")[0], read_pc2(tmp_path / "n.pc2")[0]
    assert got.shape == expected.shape == (4, len(g.vertices), 3)
    np.testing.assert_allclose(got, expected, atol=1e-5)


def test_a_garsim_walk_glb_is_a_body_source_for_another_garment(case, tmp_path, capsys):
    """The GLB `animate --motion` writes holds the garment and the skinned body: with --body-mesh Body (the default
    picks it by name too) its body alone is the canonical (as stored: the walk's first frame) and the targets."""
    from garsim.geometry.gltf_scene import GltfScene
    from garsim.geometry.io import MeshError, load_mesh_animation, y_up_to_z_up

    folder = case[0]
    walk = tmp_path / "walk.glb"
    argv = ["animate", "--garment", str(folder / "skirt.obj"), "--motion", "walk", "--frames", "3", "--quiet"]
    assert main([*argv, "--prior-only", "--out", str(walk)]) == 0
    frames, faces = load_mesh_animation(walk, 30.0, mesh="Body")
    assert frames.shape == (3, len(case[2]), 3) and np.array_equal(faces, case[4])
    scene = GltfScene.read(walk)
    body = next(i for i in scene.instances if i.name == "Body")
    stored = load_mesh_animation(walk, None)[0][0]  # as the file stores its nodes: the T-pose the skirt was made on
    np.testing.assert_allclose(stored, scene.vertices()[body.start : body.stop], atol=1e-6)
    np.testing.assert_allclose(y_up_to_z_up(stored), case[2], atol=2e-5)
    np.testing.assert_allclose(y_up_to_z_up(frames), case[3], atol=2e-5)
    with pytest.raises(MeshError, match="no mesh 'Hair'"):
        load_mesh_animation(walk, 30.0, mesh="Hair")
    bad = ["--canonical", str(folder / "canonical.obj"), "--targets", str(folder / "bodies.npz"), "--body-mesh", "Body"]
    assert main(["animate", "--garment", str(folder / "skirt.obj"), *bad, "--out", str(tmp_path / "x.pc2")]) == 2
    assert "--body-mesh picks the body in a .glb/.gltf or USD --targets file" in capsys.readouterr().err


def test_a_still_gltf_body_gives_one_frame_with_a_warning(case, tmp_path, caplog):
    from garsim.export import read_pc2
    from garsim.geometry.io import save_mesh

    folder, g, canonical, bodies, faces = case
    save_mesh(tmp_path / "still.glb", bodies[1], faces)
    argv = ["animate", "--garment", str(folder / "skirt.obj"), "--canonical", str(folder / "canonical.obj")]
    argv += ["--targets", str(tmp_path / "still.glb"), "--prior-only", "--quiet", "--out", str(tmp_path / "s.pc2")]
    with caplog.at_level("WARNING", logger="garsim"):
        assert main(argv) == 0
    assert "nothing in it moves the body: one target frame" in caplog.text
    np.testing.assert_allclose(read_pc2(tmp_path / "s_body.pc2")[0], bodies[1:2], atol=1e-6)
