"""Mesh I/O: vertex order survives round trips; every bad input gives a clear MeshError."""

from __future__ import annotations

import re

import numpy as np
import pytest
import trimesh
from mesh_fixtures import obj_lists, seamed_obj_text

from garsim.geometry.io import (
    MeshAttributes,
    MeshError,
    as_mesh,
    load_mesh,
    load_mesh_with_attributes,
    save_mesh,
    triangulate_polygons,
    validate_mesh,
    y_up_to_z_up,
    z_up_to_y_up,
)


@pytest.fixture
def permuted(icosphere):
    """The icosphere with randomly permuted vertex order (faces re-indexed to match)."""
    v, f = icosphere
    perm = np.random.default_rng(0).permutation(len(v))
    inv = np.argsort(perm)
    return v[perm], inv[f]


@pytest.mark.parametrize("ext", [".obj", ".ply", ".glb", ".off"])
def test_round_trip_keeps_vertex_order(tmp_path, permuted, ext):
    v, f = permuted
    path = save_mesh(tmp_path / f"m{ext}", v, f)
    v2, f2 = load_mesh(path)
    assert v2.dtype == np.float32 and f2.dtype == np.int64
    np.testing.assert_allclose(v2, v, atol=1e-6)
    np.testing.assert_array_equal(f2, f)


def test_stl_is_merged_to_a_connected_mesh(tmp_path, icosphere):
    v, f = icosphere
    v2, f2 = load_mesh(save_mesh(tmp_path / "m.stl", v, f))
    assert len(v2) == len(v) and len(f2) == len(f)
    np.testing.assert_allclose(v2[f2], v[f], atol=1e-6)  # same triangles, same corner order


def test_save_is_atomic_and_leaves_no_temp_files(tmp_path, icosphere):
    v, f = icosphere
    save_mesh(tmp_path / "a.obj", v, f)
    save_mesh(tmp_path / "a.obj", v * 2, f)  # overwrite
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.obj"]
    np.testing.assert_allclose(load_mesh(tmp_path / "a.obj")[0], v * 2, atol=1e-6)
    with pytest.raises(MeshError, match="NaN"):
        save_mesh(tmp_path / "a.obj", np.full_like(v, np.nan), f)
    np.testing.assert_allclose(load_mesh(tmp_path / "a.obj")[0], v * 2, atol=1e-6)  # old file intact


def test_vertex_colors_are_written(tmp_path, icosphere):
    v, f = icosphere
    colors = np.zeros((len(v), 3))
    colors[:, 0] = 1.0
    path = save_mesh(tmp_path / "c.ply", v, f, vertex_colors=colors)
    loaded = trimesh.load(path, process=False)
    np.testing.assert_array_equal(loaded.visual.vertex_colors[:, :3], np.tile([255, 0, 0], (len(v), 1)))
    with pytest.raises(MeshError, match="vertex_colors"):
        save_mesh(tmp_path / "c.ply", v, f, vertex_colors=np.zeros((3, 3)))


def test_y_up_round_trip(tmp_path, permuted):
    v, f = permuted
    path = save_mesh(tmp_path / "y.glb", v, f, y_up=True)
    raw = trimesh.load(path, process=False, force="mesh")
    np.testing.assert_allclose(raw.vertices, np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1), atol=1e-6)  # stored Y-up
    v2, f2 = load_mesh(path, y_up=True)
    np.testing.assert_allclose(v2, v, atol=1e-6)
    np.testing.assert_array_equal(f2, f)
    # up (+Z) becomes +Y and the body's front (-Y) becomes +Z (glTF's front)
    np.testing.assert_allclose(z_up_to_y_up(np.array([[0, 0, 1.0], [0, -1.0, 0]])), [[0, 1, 0], [0, 0, 1]])
    np.testing.assert_allclose(y_up_to_z_up(z_up_to_y_up(v)), v, atol=1e-7)


def test_quad_obj_is_triangulated(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nf 1 2 3 4\nf 1 2 5\n")
    v, f = load_mesh(path)
    assert v.shape == (5, 3) and f.shape == (3, 3)
    areas = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    np.testing.assert_allclose(areas, [0.5, 0.5, 0.5])  # the unit quad became two halves
    assert set(f[:2].ravel()) == {0, 1, 2, 3}


def test_validate_fan_triangulates_polygon_arrays():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    np.testing.assert_array_equal(triangulate_polygons(np.array([[0, 1, 2, 3]])), [[0, 1, 2], [0, 2, 3]])
    _, f = validate_mesh(v, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(f, [[0, 1, 2], [0, 2, 3]])


OBJ_CASES = {
    "empty": ("", "empty"),
    "no vertices": ("# only a comment\n", "no triangle faces"),
    "nan": ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "NaN/inf"),
    "inf": ("v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n", "NaN/inf"),
    "out of range": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "do not exist|outside"),
    "repeated index": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 2\n", "repeat a vertex"),
    "zero area": ("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n", "zero area"),
    "points only": ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangle faces"),
}


@pytest.mark.parametrize("case", sorted(OBJ_CASES))
def test_bad_obj_files_give_one_line_errors(tmp_path, case):
    text, pattern = OBJ_CASES[case]
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(MeshError, match=pattern) as err:
        load_mesh(path)
    msg = str(err.value)
    assert "\n" not in msg and "bad.obj" in msg


def test_missing_file_and_unsupported_extension(tmp_path, icosphere):
    with pytest.raises(MeshError, match="no such file"):
        load_mesh(tmp_path / "missing.obj")
    (tmp_path / "m.xyz").write_text("1 2 3\n")
    with pytest.raises(MeshError, match="use one of"):
        load_mesh(tmp_path / "m.xyz")
    with pytest.raises(MeshError, match="use one of"):
        save_mesh(tmp_path / "m.fbx", *icosphere)
    with pytest.raises(MeshError, match="directory"):
        load_mesh(tmp_path.joinpath("d.obj").mkdir() or tmp_path / "d.obj")


def test_validate_mesh_array_errors():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    with pytest.raises(MeshError, match="shape"):
        validate_mesh(v[:, :2], [[0, 1, 2]])
    with pytest.raises(MeshError, match="outside"):
        validate_mesh(v, [[0, 1, -1]])
    with pytest.raises(MeshError, match="no faces"):
        validate_mesh(v, np.zeros((0, 3), dtype=int))
    with pytest.raises(MeshError, match="integers"):
        validate_mesh(v, [[0, 1, 1.5]])
    with pytest.raises(MeshError, match="garment"):
        validate_mesh(v, [[0, 1, 1]], name="garment")
    assert issubclass(MeshError, ValueError)


def test_as_mesh_accepts_trimesh_pairs_paths_and_objects(tmp_path, icosphere):
    v, f = icosphere
    tm = trimesh.Trimesh(v, f, process=False)
    for obj in (
        tm,
        (v, f),
        [v.astype(np.float64), f.astype(np.int32)],
        save_mesh(tmp_path / "a.ply", v, f),
        str(tmp_path / "a.ply"),
        trimesh.Scene([tm]),
    ):
        v2, f2 = as_mesh(obj)
        np.testing.assert_allclose(v2, v, atol=1e-6)
        np.testing.assert_array_equal(f2, f)

    class Holder:
        vertices, faces = v, f

    np.testing.assert_array_equal(as_mesh(Holder())[1], f)
    with pytest.raises(MeshError, match="cannot read a mesh"):
        as_mesh(42)
    with pytest.raises(MeshError, match="pair"):
        as_mesh((v, f, f))


# --- UVs and normals ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("normals", [False, True], ids=["v/vt", "v/vt/vn"])
def test_obj_uv_seams_and_normals_round_trip(tmp_path, icosphere, normals):
    """An OBJ with more vt than v keeps its vertex order, vt list and per-corner indices through load + save."""
    v, f = icosphere
    text, vt, tf = seamed_obj_text(v.astype(np.float64), f, normals)
    src = tmp_path / "seams.obj"
    src.write_text(text)
    v1, f1 = load_mesh(src)
    v2, f2, attrs = load_mesh_with_attributes(src)
    assert len(v1) == len(v) and len(vt) > len(v)
    np.testing.assert_array_equal(v2, v1)
    np.testing.assert_array_equal(f2, f)
    np.testing.assert_array_equal(attrs.uvs, vt)
    np.testing.assert_array_equal(attrs.uv_faces, tf)
    assert attrs.vertex_uvs(f2, len(v2)) is None  # seams: no single UV per vertex
    assert (attrs.normals is not None) == normals
    out = save_mesh(tmp_path / "out.obj", v2 * 2, f2, attributes=attrs)
    ov, ovt, of = obj_lists(out)
    np.testing.assert_allclose(ov, v2 * 2, atol=1e-6)
    np.testing.assert_array_equal(ovt, vt)  # the same numbers, exactly
    assert of == [line.split()[1:] for line in text.splitlines() if line.startswith("f ")]


def test_quads_with_uvs_match_the_triangulated_faces(tmp_path):
    """trimesh triangulates quads in its own order: the corner indices follow its triangles."""
    path = tmp_path / "quads.obj"
    path.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\n"
        "vt 0 0\nvt 0.1 0\nvt 0.1 0.1\nvt 0 0.1\nvt 0.3 0\nvt 0.3 0.1\nvt 0.7 0.7\nvn 0 0 1\nvn 0 0 1\n"
        "f 1/1/1 2/2/1 3/3/1 4/4/1\nf 2/7/2 5/5/2 6/6/2 3/3/2\n"
    )
    v, f, a = load_mesh_with_attributes(path)
    uv_of = {(0, 0): 0, (0, 1): 1, (0, 2): 2, (0, 3): 3, (1, 1): 6, (1, 4): 4, (1, 5): 5, (1, 2): 2}
    quad = [0 if set(tri) <= {0, 1, 2, 3} else 1 for tri in f.tolist()]
    expected = [[uv_of[(q, int(i))] for i in tri] for q, tri in zip(quad, f)]
    np.testing.assert_array_equal(a.uv_faces, expected)
    np.testing.assert_array_equal(a.normal_faces, np.repeat(np.array(quad)[:, None], 3, axis=1))


def test_normals_are_recomputed_for_moved_vertices_and_turned_with_y_up(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    attrs = MeshAttributes(normals=np.array([[0.0, 0.0, 1.0]]), normal_faces=np.zeros((2, 3), dtype=np.int64))
    bent = v.copy()
    bent[:, 2] = bent[:, 0]  # the square tilted 45 degrees about Y
    moved = attrs.recompute_normals(bent, f)
    np.testing.assert_allclose(moved.normals, [[-(0.5**0.5), 0.0, 0.5**0.5]], atol=1e-12)
    flipped = MeshAttributes(normals=-attrs.normals, normal_faces=attrs.normal_faces).recompute_normals(bent, f)
    np.testing.assert_allclose(flipped.normals, -moved.normals)  # oriented like the given normals
    path = save_mesh(tmp_path / "y.obj", bent, f, attributes=moved, y_up=True)
    np.testing.assert_allclose(load_mesh_with_attributes(path)[2].normals, z_up_to_y_up(moved.normals), atol=1e-12)


def test_glb_and_ply_carry_per_vertex_uvs_and_obj_keeps_seams(tmp_path, icosphere, caplog):
    v, f = icosphere
    uv = np.random.default_rng(0).random((len(v), 2))
    attrs = MeshAttributes(uvs=uv, uv_faces=f.copy())
    for ext in (".glb", ".ply"):
        v2, f2, a2 = load_mesh_with_attributes(save_mesh(tmp_path / f"m{ext}", v, f, attributes=attrs))
        np.testing.assert_array_equal(f2, f)
        np.testing.assert_allclose(a2.vertex_uvs(f2, len(v2)), uv, atol=1e-6)
    seams = MeshAttributes(uvs=np.concatenate([uv, [[0.5, 0.5]]]), uv_faces=np.where(f == 0, len(uv), f))
    seams.uv_faces[0, 0] = 0  # vertex 0 now has two UVs
    with caplog.at_level("WARNING"):
        path = save_mesh(tmp_path / "s.glb", v, f, attributes=seams)
    assert "seams" in caplog.text and load_mesh_with_attributes(path)[2].uvs is None
    assert save_mesh(tmp_path / "s.off", v, f, attributes=seams).exists()  # OFF has no UVs: nothing to keep


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n", "'vt'"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 x\nf 1/1 2/1 3/1\n", "could not parse|line 4"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 nan\nf 1/1 2/1 3/1\n", "finite"),
    ],
    ids=["vt index out of range", "vt not a number", "vt NaN"],
)
def test_bad_uvs_give_one_line_errors(tmp_path, text, pattern):
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(MeshError, match=pattern) as err:
        load_mesh_with_attributes(path)
    assert "\n" not in str(err.value) and "bad.obj" in str(err.value)
    v, f = np.eye(3), np.array([[0, 1, 2]])
    with pytest.raises(MeshError, match="UVs face indices outside"):
        save_mesh(tmp_path / "o.obj", v, f, attributes=MeshAttributes(np.zeros((1, 2)), np.ones((1, 3), dtype=int)))


TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


@pytest.mark.parametrize(
    "text, message",
    [
        (TRIANGLE + "# c\r\n\r\nvn 0 0 x\r\nvt x\r\nf 1/1/1 2/1/1 3/1/1\r\n", "line 6 'vn 0 0 x' is malformed: a 'vn'"),
        (TRIANGLE + "vt 0 0\rvt 0 nan # c\nf 1/1 2/1 3/1\n", "line 5 'vt 0 nan' is malformed: a 'vt' line needs 1"),
        (TRIANGLE + "  vt\t\nf 1/1 2/1 3/1\n", "line 4 'vt ' is malformed"),
        (TRIANGLE + "vt 0 0\nf 1/1 2/1 3/0\n", "face 0 references 'vt' 2 but the file has 1 'vt' lines"),
    ],
    ids=["the first bad line of either kind, CRLF", "a lone CR ends a line", "no numbers", "index 0"],
)
def test_bad_attribute_lines_are_named_by_number(tmp_path, text, message):
    path = tmp_path / "bad.obj"
    path.write_bytes(text.encode())
    with pytest.raises(MeshError, match=re.escape(message)):
        load_mesh_with_attributes(path)


def test_obj_attribute_spellings(tmp_path, caplog):
    """vt with 1 to 3 numbers (u alone: v = 0; w ignored), relative indices counted at their line, corner fields
    past v/vt/vn ignored; a corner that is not integers (even one past int64) drops the attributes with a warning."""
    path = tmp_path / "a.obj"
    path.write_text(TRIANGLE + "vt 0.5\n  vt 0.1 0.2 0.3 # w\nvn 0 0 1\nf 1/-2/-1 2/-1/1/9 3/2/1\nvt 0.7 0.8\n")
    _, f, a = load_mesh_with_attributes(path)
    np.testing.assert_array_equal(a.uvs, [[0.5, 0.0], [0.1, 0.2], [0.7, 0.8]])
    np.testing.assert_array_equal(a.uv_faces, [[0, 1, 1]])
    np.testing.assert_array_equal(a.normal_faces, [[0, 0, 0]])
    for corner in ("3/x/1", "3/99999999999999999999/1"):
        path.write_text(TRIANGLE + f"v 1 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1\nf 2/1/1 4/1/1 {corner}\n")
        with caplog.at_level("WARNING"):
            _, f, a = load_mesh_with_attributes(path)
        assert a.empty and f.tolist() == [[0, 1, 2], [1, 3, 2]] and "could not be matched" in caplog.text


def test_indented_obj_lines_are_read(tmp_path):
    """Leading blanks before 'v' / 'f' (allowed by the format) keep every vertex, so faces point where they should."""
    from garsim.geometry.io import load_mesh

    path = tmp_path / "indented.obj"
    path.write_text("v 0 0 0\n  v 1 0 0\n\tv 0 1 0\nv 0 0 1\n  f 1 2 3\nf 1 3 4\n")
    v, f = load_mesh(path)
    np.testing.assert_array_equal(v, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    np.testing.assert_array_equal(f, [[0, 1, 2], [0, 2, 3]])


def test_indented_malformed_obj_line_is_refused(tmp_path):
    """An indented 'v' line with too few numbers is refused like an unindented one (not skipped, which would shift
    every later vertex index)."""
    from garsim.geometry.io import load_mesh

    path = tmp_path / "short.obj"
    path.write_text("v 0 0 0\n  v 1 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    with pytest.raises(MeshError, match="line 2"):
        load_mesh(path)


def test_obj_spellings_from_other_tools_read_as_the_plain_file(tmp_path, icosphere):
    """A UTF-8 byte-order mark, old Mac line ends and relative (negative) indices with UVs and normals give the
    same mesh and attributes as the plain file (the mark used to hide the first vertex, shifting every index)."""
    v, f = icosphere
    text, _, _ = seamed_obj_text(v, f, normals=True)
    plain = tmp_path / "plain.obj"
    plain.write_text(text)
    ref_v, ref_f, ref_a = load_mesh_with_attributes(plain)
    lines = text.splitlines()
    seen = {"v": 0, "vt": 0, "vn": 0}
    relative = []
    for line in lines:  # every index counted back from the lines above its face
        kind = line.split()[0] if line.split() else ""
        if kind in seen:
            seen[kind] += 1
        if kind == "f":
            corners = [c.split("/") for c in line.split()[1:]]
            back = [
                "/".join("" if x == "" else str(int(x) - seen[k] - 1) for x, k in zip(c, ("v", "vt", "vn")))
                for c in corners
            ]
            line = "f " + " ".join(back)
        relative.append(line)
    variants = {
        "bom.obj": b"\xef\xbb\xbf" + text.encode(),
        "mac.obj": text.replace("\n", "\r").encode(),
        "relative.obj": "\n".join(relative).encode(),
    }
    for name, data in variants.items():
        (tmp_path / name).write_bytes(data)
        got_v, got_f, got_a = load_mesh_with_attributes(tmp_path / name)
        np.testing.assert_array_equal(got_v, ref_v, err_msg=name)
        np.testing.assert_array_equal(got_f, ref_f, err_msg=name)
        np.testing.assert_array_equal(got_a.uvs[got_a.uv_faces], ref_a.uvs[ref_a.uv_faces], err_msg=name)
        np.testing.assert_array_equal(got_a.normals[got_a.normal_faces], ref_a.normals[ref_a.normal_faces])
    comma = tmp_path / "comma.obj"
    comma.write_text("# exported\nv 0 0 0\nv 1,5 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(MeshError, match=r"line 3 'v 1,5 0 0' is malformed: .*decimal points"):
        load_mesh(comma)


def _glb_with(tmp_path, name: str, **extra) -> object:
    """A one-triangle GLB whose JSON document has ``extra`` keys merged in (``meshes`` entries updated)."""
    import json
    import struct

    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    data = tri.export(file_type="glb")
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + n])
    for key, value in extra.items():
        if key == "mesh":
            doc["meshes"][0].update(value)
        else:
            doc[key] = value
    chunk = json.dumps(doc).encode()
    chunk += b" " * (-len(chunk) % 4)
    rest = data[20 + n :]
    out = struct.pack("<III", 0x46546C67, 2, 20 + len(chunk) + len(rest)) + struct.pack("<II", len(chunk), 0x4E4F534A)
    path = tmp_path / name
    path.write_bytes(out + chunk + rest)
    return path


def test_gltf_compressed_geometry_is_refused_and_skins_and_shape_keys_are_applied(tmp_path):
    """Compressed geometry would read as nothing: refused with what to do; a skin (joint 0 moved 1 m up) and
    weighted morph targets are applied as a viewer shows them (tests/test_geometry_gltf_scene.py has the rest)."""
    plain = _glb_with(tmp_path, "plain.glb")
    assert load_mesh(plain)[1].tolist() == [[0, 1, 2]]
    with pytest.raises(MeshError, match="without compression"):
        load_mesh(_glb_with(tmp_path, "draco.glb", extensionsRequired=["KHR_draco_mesh_compression"]))
    with pytest.raises(MeshError, match="JOINTS_n"):  # a skin whose vertices name no joints
        load_mesh(_glb_with(tmp_path, "skinned.glb", skins=[{"joints": [0]}], nodes=[{"mesh": 0, "skin": 0}]))


def test_natural_order_puts_frame_2_before_frame_10(tmp_path):
    from pathlib import Path

    from garsim.geometry.io import natural_order

    names = ["frame_10.obj", "frame_2.obj", "Frame_1.obj", "frame_0002.obj", "body.obj"]
    got = [p.name for p in natural_order(Path(n) for n in names)]
    assert got == ["body.obj", "Frame_1.obj", "frame_0002.obj", "frame_2.obj", "frame_10.obj"]  # ties: plain name
