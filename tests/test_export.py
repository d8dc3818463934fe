"""Animation exporters (garsim.export): every file is read back with an independent reader.

glTF: trimesh for the base mesh + a small JSON/BIN parser (below) for morph targets and the animation;
USD: pxr.Usd; PC2: read_pc2 and a raw struct parse; OBJ: trimesh; video: imageio.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from export_readers import accessor, gltf_frames, read_gltf, z_up

from garsim.export import (
    SUPPORTED_EXTENSIONS,
    ExportError,
    export_animation,
    read_pc2,
    write_gltf_animation,
    write_obj_sequence,
    write_pc2,
    write_preview,
    write_usd_animation,
)

T = 4
RTOL = 1e-6


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def garment() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 3x3 grid (9 vertices, 8 triangles) waving over T frames: (frames (T, 9, 3), faces, uvs (9, 2))."""
    u, w = np.meshgrid(np.linspace(0.0, 1.0, 3), np.linspace(0.0, 1.0, 3), indexing="ij")
    uvs = np.stack([u.ravel(), w.ravel()], axis=1)
    faces = []
    for i in range(2):
        for j in range(2):
            a = i * 3 + j
            faces += [[a, a + 3, a + 1], [a + 1, a + 3, a + 4]]
    frames = np.stack(
        [
            np.stack([0.4 * uvs[:, 0] - 0.2, -0.15 + 0.05 * np.sin(3.0 * uvs[:, 0] + t), 1.0 + 0.5 * uvs[:, 1]], axis=1)
            for t in range(T)
        ]
    ).astype(np.float32)
    return frames, np.array(faces, dtype=np.int64), uvs.astype(np.float32)


@pytest.fixture(scope="module")
def body() -> tuple[np.ndarray, np.ndarray]:
    """A small icosphere (42 vertices) rising 1 cm per frame: (frames (T, 42, 3), faces)."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=1, radius=0.2)
    v = np.asarray(m.vertices, dtype=np.float32)
    frames = np.stack([v + np.array([0.0, 0.0, 1.2 + 0.01 * t], dtype=np.float32) for t in range(T)])
    return frames, np.asarray(m.faces, dtype=np.int64)


def _close(actual: np.ndarray, expected: np.ndarray) -> None:
    scale = float(np.abs(expected).max())
    np.testing.assert_allclose(actual, expected, rtol=RTOL, atol=RTOL * scale)


# ----------------------------------------------------------------------------- PC2 / OBJ


def test_pc2_roundtrip_and_raw_layout(tmp_path, garment):
    frames = garment[0]
    p = write_pc2(tmp_path / "g.pc2", frames, start=1.0, rate=1.0)
    got, start, rate = read_pc2(p)
    assert got.shape == (T, 9, 3) and (start, rate) == (1.0, 1.0)
    np.testing.assert_array_equal(got, frames)  # float32 in, float32 out: bit-exact
    # independent raw parse of the documented layout
    data = p.read_bytes()
    magic, version, npts, start_raw, rate_raw, nsamp = struct.unpack_from("<12siiffi", data, 0)
    assert magic == b"POINTCACHE2\0" and version == 1 and npts == 9 and nsamp == T
    assert (start_raw, rate_raw) == (1.0, 1.0)
    assert len(data) == 32 + T * 9 * 12
    raw = np.array(struct.unpack_from(f"<{T * 9 * 3}f", data, 32)).reshape(T, 9, 3)
    _close(raw, frames)


def test_read_pc2_rejects_truncated_file(tmp_path, garment):
    p = write_pc2(tmp_path / "g.pc2", garment[0])
    p.write_bytes(p.read_bytes()[:-4])
    with pytest.raises(ValueError, match="truncated"):
        read_pc2(p)


def test_obj_sequence_keeps_order_uvs_normals(tmp_path, garment):
    import trimesh

    frames, faces, uvs = garment
    normals = np.tile(np.array([0.0, -1.0, 0.0], dtype=np.float32), (T, 9, 1))
    paths = write_obj_sequence(tmp_path / "seq", frames, faces, uvs=uvs, normals=normals, stem="shirt")
    assert [p.name for p in paths] == [f"shirt_{k:04d}.obj" for k in range(T)]
    for k, p in enumerate(paths):
        m = trimesh.load(p, process=False, maintain_order=True)
        assert m.vertices.shape == (9, 3)
        _close(np.asarray(m.vertices), frames[k])
        np.testing.assert_array_equal(m.faces, faces)
        _close(np.asarray(m.visual.uv), uvs)
        text = p.read_text()
        assert text.count("\nvt ") == 9 and text.count("\nvn ") == 9 and "f 1/1/1 4/4/4 2/2/2" in text


def test_export_animation_pc2_writes_frame0_obj_and_body(tmp_path, garment, body):
    import trimesh

    frames, faces, uvs = garment
    out = export_animation(tmp_path / "drape.pc2", frames, faces, body_frames=body[0], body_faces=body[1], uvs=uvs)
    assert [p.name for p in out] == ["drape.pc2", "drape.obj", "drape_body.pc2", "drape_body.obj"]
    m = trimesh.load(tmp_path / "drape.obj", process=False, maintain_order=True)
    _close(np.asarray(m.vertices), frames[0])
    np.testing.assert_array_equal(m.faces, faces)
    _close(read_pc2(tmp_path / "drape_body.pc2")[0], body[0])
    mb = trimesh.load(tmp_path / "drape_body.obj", process=False, maintain_order=True)
    np.testing.assert_array_equal(mb.faces, body[1])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in out)  # no temp files left


# ----------------------------------------------------------------------------- glTF


@pytest.mark.parametrize("interpolation", ["LINEAR", "STEP"])
def test_glb_base_mesh_morph_targets_and_animation(tmp_path, garment, body, interpolation):
    import trimesh

    frames, faces, uvs = garment
    p = write_gltf_animation(
        tmp_path / "drape.glb",
        frames,
        faces,
        body_frames=body[0],
        body_faces=body[1],
        fps=24,
        uvs=uvs,
        interpolation=interpolation,
    )
    # trimesh: the base meshes are frame 0 in Y-up, vertex order and faces kept, UVs survive
    scene = trimesh.load(p, force="scene")
    g, b = scene.geometry["Garment"], scene.geometry["Body"]
    _close(z_up(np.asarray(g.vertices)), frames[0])
    np.testing.assert_array_equal(g.faces, faces)
    _close(np.asarray(g.visual.uv), uvs)
    _close(z_up(np.asarray(b.vertices)), body[0][0])
    np.testing.assert_array_equal(b.faces, body[1])
    # our reader: every frame from the morph targets
    doc, blob = read_gltf(p)
    gm = gltf_frames(doc, blob, "Garment")
    assert gm["frames"].shape == (T, 9, 3)
    _close(z_up(gm["frames"]), frames)
    np.testing.assert_array_equal(gm["faces"], faces)
    _close(gm["attrs"]["TEXCOORD_0"], np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], axis=1))  # glTF's v points down
    bm = gltf_frames(doc, blob, "Body")
    _close(z_up(bm["frames"]), body[0])
    # the animation: key k at k / fps with weight 1 on target k only, one channel per mesh node
    (anim,) = doc["animations"]
    assert len(anim["channels"]) == 2
    names = set()
    for ch in anim["channels"]:
        sampler = anim["samplers"][ch["sampler"]]
        assert ch["target"]["path"] == "weights" and sampler["interpolation"] == interpolation
        node = doc["nodes"][ch["target"]["node"]]
        names.add(node["name"])
        times = accessor(doc, blob, sampler["input"])
        weights = accessor(doc, blob, sampler["output"]).reshape(T, T)
        _close(times, np.arange(T) / 24.0)
        np.testing.assert_array_equal(weights, np.eye(T))
        assert len(doc["meshes"][node["mesh"]]["primitives"][0]["targets"]) == T
    assert names == {"Garment", "Body"}


def test_gltf_embedded_z_up_and_per_frame_normals(tmp_path, garment):
    frames, faces, _ = garment
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(T, 9, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    out = export_animation(tmp_path / "drape.gltf", frames, faces, y_up=False, normals=normals)
    doc, blob = read_gltf(out[0])
    gm = gltf_frames(doc, blob, "Garment")
    _close(gm["frames"], frames)  # y_up=False: garsim's coordinates as they are
    _close(gm["normals"], normals)
    assert [m["name"] for m in doc["meshes"]] == ["Garment"]


def test_gltf_single_frame(tmp_path, garment):
    frames, faces, _ = garment
    doc, blob = read_gltf(write_gltf_animation(tmp_path / "still.glb", frames[:1], faces))
    _close(z_up(gltf_frames(doc, blob, "Garment")["frames"]), frames[:1])


# ----------------------------------------------------------------------------- USD


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usd"])
def test_usd_time_samples_metadata_and_uvs(tmp_path, garment, body, ext):
    from pxr import Usd, UsdGeom

    frames, faces, uvs = garment
    p = write_usd_animation(
        tmp_path / f"drape{ext}", frames, faces, body_frames=body[0], body_faces=body[1], fps=24, uvs=uvs
    )
    stage = Usd.Stage.Open(str(p))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 24.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, T - 1.0)
    assert stage.GetDefaultPrim().GetPath() == "/Scene"
    for prim_path, (v, f) in {"/Scene/Garment": (frames, faces), "/Scene/Body": body}.items():
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(prim_path))
        assert mesh, prim_path
        points = mesh.GetPointsAttr()
        assert points.GetTimeSamples() == [float(k) for k in range(T)]
        for k in range(T):
            _close(np.asarray(points.Get(float(k))), v[k])
        assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(f)
        np.testing.assert_array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), f.ravel())
        assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    st = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/Scene/Garment")).GetPrimvar("st")
    assert st and st.GetInterpolation() == UsdGeom.Tokens.vertex
    _close(np.asarray(st.Get()), uvs)
    assert sorted(q.name for q in tmp_path.iterdir()) == [p.name]  # no temp files left


# ----------------------------------------------------------------------------- video


@pytest.mark.parametrize("ext", [".mp4", ".gif"])
def test_preview_frame_count(tmp_path, garment, body, ext):
    import imageio.v2 as iio

    frames, faces, _ = garment
    p = write_preview(tmp_path / f"preview{ext}", frames, faces, body_frames=body[0], body_faces=body[1], size=64)
    if ext == ".gif":
        video = iio.mimread(p)
        assert len(video) == T
        assert {im.shape[:2] for im in video} == {video[0].shape[:2]} and video[0].shape[0] == 64
        assert not np.array_equal(video[0], video[1])  # the garment moves
        from PIL import Image

        with Image.open(p) as gif:
            assert abs(gif.info["duration"] - 1000 / 15) <= 10  # GIF delays are whole centiseconds
    else:
        reader = iio.get_reader(p, format="FFMPEG")
        try:
            assert reader.count_frames() == T
            meta = reader.get_meta_data()
            h_w = meta["size"][::-1]
            assert meta["fps"] == pytest.approx(15.0)
        finally:
            reader.close()
        assert h_w[0] % 16 == 0 and h_w[1] % 16 == 0


def test_preview_caps_frames(tmp_path, garment):
    import imageio.v2 as iio

    frames, faces, _ = garment
    p = export_animation(tmp_path / "p.gif", frames, faces, size=32, max_frames=2)[0]
    assert len(iio.mimread(p)) == 2


# ----------------------------------------------------------------------------- validation


def _bad_cases(frames, faces, uvs, body):
    nan = frames.copy()
    nan[2, 5, 1] = np.nan
    return {
        "nan frames": dict(frames=nan),
        "one frame without T": dict(frames=frames[0]),
        "frames not xyz": dict(frames=frames[..., :2]),
        "empty frames": dict(frames=frames[:0]),
        "faces out of range": dict(faces=np.array([[0, 1, 9]])),
        "negative face index": dict(faces=np.array([[0, -1, 2]])),
        "faces not triangles": dict(faces=np.array([[0, 1, 2, 3]])),
        "fractional faces": dict(faces=np.array([[0.0, 1.5, 2.0]])),
        "body frame count": dict(body_frames=body[0][:2], body_faces=body[1]),
        "body without faces": dict(body_frames=body[0]),
        "body faces out of range": dict(body_frames=body[0], body_faces=body[1] + 100),
        "uv shape": dict(uvs=uvs[:5]),
        "fps": dict(fps=0),
    }


@pytest.mark.parametrize("ext", [".glb", ".usda", ".pc2", ".gif"])
def test_bad_inputs_raise_value_error_and_write_nothing(tmp_path, garment, body, ext):
    frames, faces, uvs = garment
    for label, change in _bad_cases(frames, faces, uvs, body).items():
        if ext == ".pc2" and label == "fps":
            continue  # PC2 has no time base
        if ext == ".gif" and label == "uv shape":
            continue  # previews ignore UVs
        kw = dict(frames=frames, faces=faces, uvs=uvs if ext != ".gif" else None) | change
        with pytest.raises(ValueError) as info:
            export_animation(tmp_path / f"out{ext}", **kw)
        msg = str(info.value)
        assert "\n" not in msg and msg, label
        assert isinstance(info.value, ExportError), label
    assert list(tmp_path.iterdir()) == []


def test_unsupported_extension_names_supported_ones(tmp_path, garment):
    frames, faces, _ = garment
    with pytest.raises(ValueError, match=r"\.glb.*\.usd.*\.pc2.*\.mp4") as info:
        export_animation(tmp_path / "out.fbx", frames, faces)
    assert "\n" not in str(info.value) and "'.fbx'" in str(info.value)
    for writer, name in [(write_gltf_animation, "x.usd"), (write_usd_animation, "x.glb"), (write_preview, "x.avi")]:
        with pytest.raises(ValueError, match="use one of"):
            writer(tmp_path / name, frames, faces)
    with pytest.raises(ValueError, match=r"\.pc2"):
        write_pc2(tmp_path / "x", frames)
    assert set(SUPPORTED_EXTENSIONS) == {".glb", ".gltf", ".usd", ".usda", ".usdc", ".pc2", ".mp4", ".gif"}


@pytest.mark.parametrize("name", ["a.glb", "a.usdc", "a.pc2", "a.mp4"])
def test_unwritable_folder_fails_before_work(tmp_path, garment, monkeypatch, name):
    frames, faces, _ = garment
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the output folder should be")
    # the check comes before validation and rendering: even invalid frames report the folder
    import garsim.geometry.render as render

    monkeypatch.setattr(render, "render_image", lambda *a, **k: pytest.fail("rendered before checking the folder"))
    with pytest.raises(ValueError, match="output folder"):
        export_animation(blocker / "sub" / name, frames[..., :2], faces)


def test_read_only_folder_fails(tmp_path, garment):
    import os

    frames, faces, _ = garment
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        probe = ro / "probe"
        try:
            probe.write_text("")
            probe.unlink()
            pytest.skip("running with privileges that ignore folder permissions")
        except PermissionError:
            pass
        with pytest.raises(ValueError, match="not writable"):
            write_usd_animation(ro / "a.usda", frames, faces)
        with pytest.raises(ValueError, match="not writable"):
            write_obj_sequence(ro, frames, faces)
    finally:
        ro.chmod(0o700)
        assert os.listdir(ro) == []


# ----------------------------------------------------------------------------- metadata

METADATA = {"model": "garsim v0.4", "temporal_smoothing_frames": 1.5, "refine": True}


def _obj_metadata(path: Path) -> dict | None:
    """The ``# garsim {json}`` comment line of an OBJ, parsed as plain text (None without one)."""
    found = [line[len("# garsim ") :] for line in path.read_text().splitlines() if line.startswith("# garsim {")]
    assert len(found) <= 1
    return json.loads(found[0]) if found else None


@pytest.mark.parametrize("ext", [".glb", ".gltf"])
def test_gltf_metadata_in_asset_extras(tmp_path, garment, body, ext):
    import trimesh

    frames, faces, uvs = garment
    nested = METADATA | {"nested": {"frames": [0, 1, 2], "note": 'quotes " and \\ and é'}, "none": None}
    (p,) = export_animation(
        tmp_path / f"drape{ext}", frames, faces, body_frames=body[0], body_faces=body[1], uvs=uvs, metadata=nested
    )
    doc, _ = read_gltf(p)
    assert doc["asset"]["extras"]["garsim"] == nested
    assert doc["asset"]["version"] == "2.0"
    assert doc["extras"]["frames"] == T  # the existing extras stay
    scene = trimesh.load(p, force="scene")
    assert scene.metadata["garsim"] == nested  # trimesh surfaces scene extras
    assert len(scene.geometry) == 2
    # without metadata nothing is added
    (q,) = export_animation(tmp_path / f"plain{ext}", frames, faces)
    doc, _ = read_gltf(q)
    assert "extras" not in doc["asset"] and "extras" not in doc["scenes"][0]


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usd"])
def test_usd_metadata_in_custom_layer_data(tmp_path, garment, ext):
    from pxr import Sdf, Usd

    frames, faces, uvs = garment
    nested = METADATA | {"nested": {"frames": [0, 1, 2], "note": 'quotes " and \\ and é'}, "none": None}
    (p,) = export_animation(tmp_path / f"drape{ext}", frames, faces, uvs=uvs, metadata=nested)
    layer = Sdf.Layer.FindOrOpen(str(p))
    assert json.loads(layer.customLayerData["garsim"]) == nested
    assert layer.documentation == "garsim garment animation"
    stage = Usd.Stage.Open(str(p))
    assert json.loads(stage.GetRootLayer().customLayerData["garsim"]) == nested
    assert stage.GetPrimAtPath("/Scene/Garment")
    (q,) = export_animation(tmp_path / f"plain{ext}", frames, faces)
    assert "garsim" not in Sdf.Layer.FindOrOpen(str(q)).customLayerData


def test_pc2_metadata_in_obj_comment(tmp_path, garment, body):
    import trimesh

    from garsim.geometry.io import load_mesh

    frames, faces, uvs = garment
    files = export_animation(
        tmp_path / "drape.pc2", frames, faces, body_frames=body[0], body_faces=body[1], uvs=uvs, metadata=METADATA
    )
    obj = tmp_path / "drape.obj"
    assert obj in files
    lines = obj.read_text().splitlines()
    assert lines[0] == "# garsim export" and lines[1].startswith("# garsim {")
    assert _obj_metadata(obj) == METADATA
    assert _obj_metadata(tmp_path / "drape_body.obj") is None  # the metadata goes with the garment
    # the OBJ still reads, in vertex order, with garsim's loader and trimesh
    v, f = load_mesh(obj)
    _close(v, frames[0])
    np.testing.assert_array_equal(f, faces)
    m = trimesh.load(obj, process=False, maintain_order=True)
    _close(np.asarray(m.vertices), frames[0])
    np.testing.assert_array_equal(np.asarray(m.faces), faces)
    cache, _, _ = read_pc2(tmp_path / "drape.pc2")
    _close(cache, frames)


def test_obj_sequence_metadata_on_every_frame(tmp_path, garment):
    frames, faces, uvs = garment
    odd = {"text": "line\nbreak é"}
    paths = write_obj_sequence(tmp_path, frames, faces, uvs=uvs, metadata=odd)
    assert [_obj_metadata(p) for p in paths] == [odd] * T
    assert all(len(p.read_text().splitlines()[1]) == len(p.read_text().splitlines()[1].encode()) for p in paths)


@pytest.mark.parametrize("ext", [".mp4", ".gif"])
def test_preview_accepts_and_ignores_metadata(tmp_path, garment, ext):
    frames, faces, _ = garment
    (p,) = export_animation(tmp_path / f"p{ext}", frames[:2], faces, size=32, metadata=METADATA)
    assert p.stat().st_size > 0


def _bad_metadata():
    return {
        "a list": [("model", "x")],
        "a string": '{"model": "x"}',
        "a set value": {"frames": {1, 2}},
        "an array value": {"weights": np.zeros(3)},
        "nan": {"smoothing": float("nan")},
        "inf deep": {"a": [1, {"b": float("inf")}]},
        "int key": {1: "x"},
        "object value": {"path": Path("x")},
    }


@pytest.mark.parametrize("ext", [".glb", ".gltf", ".usda", ".usdc", ".pc2", ".gif", ".mp4"])
def test_bad_metadata_raises_and_writes_nothing(tmp_path, garment, body, ext):
    frames, faces, _ = garment
    for label, bad in _bad_metadata().items():
        with pytest.raises(ExportError, match="metadata") as info:
            export_animation(
                tmp_path / f"out{ext}", frames, faces, body_frames=body[0], body_faces=body[1], metadata=bad
            )
        assert "\n" not in str(info.value), label
    assert list(tmp_path.iterdir()) == []


def test_bad_metadata_in_each_writer(tmp_path, garment):
    from garsim.export import write_obj

    frames, faces, _ = garment
    bad = {"when": object()}
    for call in [
        lambda: write_gltf_animation(tmp_path / "a.glb", frames, faces, metadata=bad),
        lambda: write_usd_animation(tmp_path / "a.usda", frames, faces, metadata=bad),
        lambda: write_preview(tmp_path / "a.gif", frames, faces, metadata=bad),
        lambda: write_obj(tmp_path / "a.obj", frames[0], faces, metadata=bad),
        lambda: write_obj_sequence(tmp_path, frames, faces, metadata=bad),
    ]:
        with pytest.raises(ExportError, match=r"metadata\['when'\]: type object is not JSON-serialisable"):
            call()
    loop: dict = {}
    loop["self"] = loop
    with pytest.raises(ExportError, match="contains itself"):
        write_gltf_animation(tmp_path / "a.glb", frames, faces, metadata=loop)
    assert list(tmp_path.iterdir()) == []


def test_metadata_normalised_to_json(tmp_path, garment):
    from collections import OrderedDict

    frames, faces, _ = garment
    given = OrderedDict(frames=(1, 2), scale=np.float32(0.5), count=np.int64(3), flag=np.bool_(True))
    (p,) = export_animation(tmp_path / "a.glb", frames, faces, metadata=given)
    doc, _ = read_gltf(p)
    assert doc["asset"]["extras"]["garsim"] == {"frames": [1, 2], "scale": 0.5, "count": 3, "flag": True}


@pytest.mark.parametrize("ext", [".glb", ".usda", ".pc2", ".gif"])
def test_each_input_is_checked_once_per_export(tmp_path, garment, body, monkeypatch, ext):
    """export_animation checks the metadata and the arrays once, however many files the format writes."""
    from garsim.export import _common

    frames, faces, uvs = garment
    calls = {"check_metadata": 0, "check_frames": 0}

    def counting(name):
        check = getattr(_common, name)

        def counted(*args, **kw):
            calls[name] += 1
            return check(*args, **kw)

        return counted

    for name in calls:
        monkeypatch.setattr(_common, name, counting(name))
    kw = dict(body_frames=body[0][:2], body_faces=body[1], metadata=METADATA) | ({"size": 32} if ext == ".gif" else {})
    export_animation(tmp_path / f"a{ext}", frames[:2], faces, **kw)
    assert calls == {"check_metadata": 1, "check_frames": 2}  # the garment's frames and the body's


def test_pc2_bad_timing_writes_nothing(tmp_path, garment, body):
    frames, faces, uvs = garment
    with pytest.raises(ExportError, match="rate a positive one"):
        export_animation(tmp_path / "a.pc2", frames, faces, body_frames=body[0], body_faces=body[1], rate=0)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("start, rate", [("soon", 1.0), (0.0, None), (0.0, -1.0), (float("nan"), 1.0)])
def test_pc2_timing_errors_are_one_line_export_errors(start, rate):
    from garsim.export.pc2 import _check_timing

    with pytest.raises(ExportError, match="PC2 cache: start must be"):
        _check_timing(start, rate)
