"""garsim view: the readers (NPZ, GLB, OBJ folder) and the viser server, started non-blocking on a free port."""

from __future__ import annotations

import socket
import subprocess
import sys
import urllib.request

import numpy as np
import pytest

from garsim.view import VIEWER_NEEDS, ViewerUnavailable, load_view_data

T = 3


@pytest.fixture(scope="module")
def scene():
    """A tiny garment sequence (icosphere, moving), its prior, and a body (box) moving along."""
    import trimesh

    g = trimesh.creation.icosphere(subdivisions=1, radius=0.2)
    b = trimesh.creation.box(extents=(0.3, 0.2, 0.6))
    gv, bv = np.asarray(g.vertices, np.float32), np.asarray(b.vertices, np.float32)
    frames = np.stack([gv + np.float32([0.0, 0.0, 1.0 + 0.05 * t]) for t in range(T)])
    body = np.stack([bv + np.float32([0.0, 0.0, 0.9 + 0.05 * t]) for t in range(T)])
    prior = frames.copy()
    prior[:, :, 0] += np.linspace(0.0, 0.02, len(gv), dtype=np.float32)  # a correction of 0..20 mm
    return {
        "frames": frames,
        "faces": np.asarray(g.faces, np.int64),
        "body_frames": body,
        "body_faces": np.asarray(b.faces, np.int64),
        "prior_frames": prior,
    }


@pytest.fixture
def npz(tmp_path, scene):
    path = tmp_path / "drape.npz"
    np.savez(path, **scene, fps=np.float32(12))
    return path


@pytest.fixture
def glb(tmp_path, scene):
    from garsim.export import export_animation

    return export_animation(
        tmp_path / "drape.glb",
        scene["frames"],
        scene["faces"],
        body_frames=scene["body_frames"],
        body_faces=scene["body_faces"],
        fps=12,
    )[0]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_readers_give_the_same_sequence(tmp_path, scene, npz, glb):
    from garsim.export import write_obj_sequence
    from garsim.geometry.io import save_mesh

    a, b = load_view_data(npz), load_view_data(glb)
    folder = tmp_path / "seq"
    write_obj_sequence(folder, scene["frames"], scene["faces"], stem="shirt")
    save_mesh(folder / "body.obj", scene["body_frames"][0], scene["body_faces"])  # one body: held still
    c = load_view_data(folder)
    assert a.fps == b.fps == 12 and a.num_frames == b.num_frames == c.num_frames == T
    for d in (a, b, c):
        np.testing.assert_allclose(d.frames, scene["frames"], atol=1e-5)
        np.testing.assert_array_equal(d.faces, scene["faces"])
    np.testing.assert_allclose(b.body_frames, scene["body_frames"], atol=1e-5)  # GLB: Y up back to Z up
    np.testing.assert_allclose(c.body_frames, np.repeat(scene["body_frames"][:1], T, axis=0), atol=1e-5)
    np.testing.assert_allclose(a.correction().max(), 0.02, atol=1e-6)
    assert b.prior_frames is None and b.correction() is None
    save_mesh(folder / "other.obj", scene["frames"][0], scene["faces"])
    with pytest.raises(ValueError, match="several garment meshes"):
        load_view_data(folder)
    np.savez(tmp_path / "bad.npz", vertices=scene["frames"])
    with pytest.raises(ValueError, match="'frames'"):
        load_view_data(tmp_path / "bad.npz")


def test_usd_in_its_declared_axis_and_unit_reads_as_z_up_metres(tmp_path, scene):
    """A USD written Y up in centimetres (as `garsim animate --up y --units cm` does) views like the Z-up one."""
    from garsim.export import export_animation
    from garsim.geometry.io import from_internal

    kw = {"body_faces": scene["body_faces"], "fps": 12}
    z = export_animation(tmp_path / "z.usda", scene["frames"], scene["faces"], body_frames=scene["body_frames"], **kw)
    y = export_animation(
        tmp_path / "y.usdc",
        from_internal(scene["frames"], "y", "cm"),
        scene["faces"],
        body_frames=from_internal(scene["body_frames"], "y", "cm"),
        up="y",
        units="cm",
        **kw,
    )
    for path in (*z, *y):
        d = load_view_data(path)
        assert d.fps == 12 and d.num_frames == T
        np.testing.assert_allclose(d.frames, scene["frames"], atol=1e-5)
        np.testing.assert_allclose(d.body_frames, scene["body_frames"], atol=1e-5)
        np.testing.assert_array_equal(d.faces, scene["faces"])


def test_transforms_in_the_file_place_the_mesh(tmp_path, scene):
    """A glTF node's scale / turn / move and a USD prim's transform ops are applied, as every other reader does."""
    import trimesh
    from pxr import Usd, UsdGeom

    from garsim.geometry.io import load_mesh

    v, f = scene["frames"][0], scene["faces"]
    turn = trimesh.transformations.rotation_matrix(np.pi / 3, [0, 1, 0])
    node = trimesh.transformations.translation_matrix([0.1, 0.2, 0.3]) @ turn @ np.diag([0.01, 0.01, 0.01, 1.0])
    glb = tmp_path / "node.glb"
    scene_graph = trimesh.Scene()
    scene_graph.add_geometry(trimesh.Trimesh(v * 100.0, f, process=False), transform=node)
    glb.write_bytes(scene_graph.export(file_type="glb"))
    expected = load_mesh(glb, y_up=True)[0]  # trimesh's scene graph, read as a Y-up file
    assert np.ptp(expected, axis=0).max() < 0.5  # the node's 0.01 scale applied (40 m across without it)
    np.testing.assert_allclose(load_view_data(glb).frames[0], expected, atol=1e-5)

    path = tmp_path / "xf.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Garment")
    mesh.CreatePointsAttr([tuple(map(float, p)) for p in v * 100.0])
    mesh.CreateFaceVertexCountsAttr([3] * len(f))
    mesh.CreateFaceVertexIndicesAttr([int(i) for i in f.ravel()])
    xf = UsdGeom.Xformable(mesh)
    xf.AddTranslateOp().Set((1.0, 0.0, 0.0))
    xf.AddScaleOp().Set((0.01, 0.01, 0.01))
    stage.Save()
    np.testing.assert_allclose(load_view_data(path).frames[0], v + np.float32([1.0, 0.0, 0.0]), atol=1e-5)


def test_pc2_and_objs_in_their_axis_and_unit(tmp_path, scene):
    """A PC2 from `garsim animate --up y --units cm` reads in the axis and unit its OBJ's metadata names; plain OBJs
    take --up / --units; a folder's frames go in number order (frame_2 before frame_10)."""
    from garsim.export import export_animation, write_obj
    from garsim.geometry.io import from_internal

    kw = {"body_frames": from_internal(scene["body_frames"], "y", "cm"), "body_faces": scene["body_faces"]}
    meta = {"input_up": "y", "input_units": "cm"}
    pc2 = export_animation(
        tmp_path / "a.pc2", from_internal(scene["frames"], "y", "cm"), scene["faces"], metadata=meta, **kw
    )[0]
    d = load_view_data(pc2)
    np.testing.assert_allclose(d.frames, scene["frames"], atol=1e-5)
    np.testing.assert_allclose(d.body_frames, scene["body_frames"], atol=1e-5)
    plain = tmp_path / "plain.obj"
    write_obj(plain, from_internal(scene["frames"][0], "y", "mm"), scene["faces"])
    np.testing.assert_allclose(load_view_data(plain, up="y", units="mm").frames[0], scene["frames"][0], atol=1e-5)
    folder = tmp_path / "unpadded"
    folder.mkdir()
    order = [1, 2, 10]  # name order would play 1, 10, 2
    for k, t in enumerate(order):
        write_obj(folder / f"frame_{t}.obj", scene["frames"][k], scene["faces"])
    np.testing.assert_allclose(load_view_data(folder).frames, scene["frames"], atol=1e-6)


def test_serve_npz_with_prior(npz, scene):
    pytest.importorskip("viser")
    from garsim.view import serve

    viewer = serve(npz, host="127.0.0.1", port=_free_port(), block=False)
    try:
        with urllib.request.urlopen(viewer.url, timeout=10) as r:
            assert r.status == 200 and "text/html" in r.headers.get("content-type", "")
            assert "<html" in r.read().decode("utf-8", "replace").lower()
        nodes = set(viewer.server.scene._handle_from_node_name)
        assert {"/garment", "/body"} <= nodes
        assert viewer.slider.min == 0 and viewer.slider.max == T - 1
        viewer.slider.value = 2  # the slider drives the scene
        assert viewer.frame == 2
        np.testing.assert_allclose(viewer.body.vertices, scene["body_frames"][2], atol=1e-6)
        np.testing.assert_allclose(viewer.garment_vertices(2), scene["frames"][2])
        colors = viewer.garment_colors(2)  # |prediction - prior| as colour: varies over the garment
        assert colors.shape == (len(scene["frames"][0]), 3) and np.ptp(colors, axis=0).max() > 0.3
        viewer.show_prior.value = True
        np.testing.assert_allclose(viewer.garment_vertices(2), scene["prior_frames"][2])
        viewer.color_by_correction.value = False
        assert np.ptp(viewer.garment_colors(2), axis=0).max() == 0
        viewer.show_body.value = False
        assert viewer.body.visible is False
        viewer.show_garment.value = False
        assert viewer.garment.visible is False
    finally:
        viewer.stop()


def test_serve_glb_without_prior(glb):
    pytest.importorskip("viser")
    from garsim.view import serve

    viewer = serve(glb, host="127.0.0.1", port=_free_port(), block=False)
    try:
        with urllib.request.urlopen(viewer.url, timeout=10) as r:
            assert r.status == 200
        assert viewer.show_prior is None and viewer.color_by_correction is None and viewer.slider.max == T - 1
        viewer.slider.value = 1
        assert viewer.frame == 1
    finally:
        viewer.stop()


def test_missing_viser_is_one_line(npz, monkeypatch, capsys):
    from garsim.cli import main

    monkeypatch.setitem(sys.modules, "viser", None)  # import viser -> ImportError
    from garsim.view import serve

    with pytest.raises(ViewerUnavailable, match="pip install"):
        serve(npz, block=False)
    assert main(["view", str(npz)]) == 2
    assert capsys.readouterr().err.strip() == VIEWER_NEEDS
    assert main(["view", str(npz.with_name("missing.npz"))]) == 2
    assert "no such file" in capsys.readouterr().err


def test_import_garsim_does_not_import_viser():
    code = "import sys, garsim, garsim.view, garsim.cli; sys.exit('viser' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], timeout=120).returncode == 0


def test_screenshot_shows_the_garment(npz, tmp_path):
    """Headless Chromium (software WebGL) renders the served page: the garment's correction colours are on it."""
    pytest.importorskip("viser")
    from garsim.view import find_browser, screenshot, serve

    if find_browser() is None:
        pytest.skip("no Chromium installed (apt-get install chromium)")
    viewer = serve(npz, host="127.0.0.1", port=_free_port(), block=False)
    try:
        png = screenshot(viewer.url, tmp_path / "view.png", width=960, height=640)
    finally:
        viewer.stop()
    import matplotlib.image

    rgb = matplotlib.image.imread(png)[..., :3]
    assert rgb.shape == (640, 960, 3)
    scene = rgb[:, : int(0.7 * 960)]  # left of viser's panel; the grid and the body are grey, the garment is not
    scene = scene[: int(0.85 * 640)]  # above the axes gizmo in the bottom-left corner
    coloured = (scene.max(axis=-1) - scene.min(axis=-1)) > 0.1
    assert coloured.sum() > 2000, f"only {coloured.sum()} coloured pixels"


def test_save_npz_round_trips_through_the_reader(tmp_path):
    """ViewData.save_npz (the demo's and the screenshot's writer) is read back by load_view_data value for value;
    optional arrays left out stay absent."""
    from garsim.view import ViewData

    rng = np.random.default_rng(0)
    frames, prior = rng.normal(size=(3, 4, 3)), rng.normal(size=(3, 4, 3))
    body = rng.normal(size=(3, 5, 3))
    faces, body_faces = np.array([[0, 1, 2], [1, 3, 2]]), np.array([[0, 1, 2], [2, 3, 4]])
    full = ViewData(frames, faces, body, body_faces, prior, fps=24.0).save_npz(tmp_path / "full.npz")
    back = load_view_data(full)
    np.testing.assert_allclose(back.frames, frames.astype(np.float32))
    np.testing.assert_allclose(back.body_frames, body.astype(np.float32))
    np.testing.assert_allclose(back.prior_frames, prior.astype(np.float32))
    np.testing.assert_array_equal(back.faces, faces)
    np.testing.assert_array_equal(back.body_faces, body_faces)
    assert back.fps == 24.0
    bare = load_view_data(ViewData(frames, faces).save_npz(tmp_path / "bare.npz"))
    assert bare.body_frames is None and bare.prior_frames is None
