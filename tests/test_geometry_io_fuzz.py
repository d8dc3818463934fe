"""Property-based fuzzing of mesh input: every malformed file or array ends in a one-line MeshError
(never another exception type), or loads as a valid mesh."""

from __future__ import annotations

import math
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from garsim.geometry.io import MeshError, as_mesh, load_mesh, load_mesh_with_attributes, save_mesh, validate_mesh

FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
EXTENSIONS = (".obj", ".ply", ".glb", ".gltf", ".off", ".stl")
_DIR = Path(tempfile.mkdtemp(prefix="garsim-io-fuzz-"))  # hypothesis re-runs a test body: no function fixtures


@pytest.fixture(scope="module", autouse=True)
def _cleanup():
    yield
    shutil.rmtree(_DIR, ignore_errors=True)


def _valid_obj_text() -> str:
    m = trimesh.creation.icosphere(subdivisions=1)
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in m.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in m.faces]
    return "\n".join(lines) + "\n"


VALID_OBJ = _valid_obj_text()


def _write(data: bytes | str, ext: str) -> Path:
    path = _DIR / f"fuzz{ext}"
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def _is_valid(v: np.ndarray, f: np.ndarray) -> None:
    assert v.dtype == np.float32 and v.ndim == 2 and v.shape[1] == 3 and len(v) > 0
    assert np.isfinite(v).all()
    assert f.dtype == np.int64 and f.ndim == 2 and f.shape[1] == 3 and len(f) > 0
    assert f.min() >= 0 and f.max() < len(v)
    assert ((f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])).all()


def _load_or_mesh_error(path: Path) -> tuple[np.ndarray, np.ndarray] | MeshError:
    """load_mesh's result, checked valid, or its MeshError (one line, naming the file); anything else fails."""
    try:
        v, f = load_mesh(path)
    except MeshError as exc:
        msg = str(exc)
        assert msg and "\n" not in msg and path.name in msg, msg
        return exc
    _is_valid(v, f)
    return v, f


def _call_or_mesh_error(fn, *args) -> tuple[np.ndarray, np.ndarray] | MeshError:
    try:
        v, f = fn(*args)
    except MeshError as exc:
        assert str(exc) and "\n" not in str(exc), str(exc)
        return exc
    _is_valid(v, f)
    return v, f


@FUZZ
@given(data=st.binary(max_size=2048), ext=st.sampled_from(EXTENSIONS))
def test_random_bytes(data, ext):
    _load_or_mesh_error(_write(data, ext))


@FUZZ
@given(
    head=st.sampled_from([b"ply\n", b"glTF", b"solid x\n", b"OFF\n", b"v 0 0 0\n", b"\x00" * 80]),
    data=st.binary(max_size=1024),
    ext=st.sampled_from(EXTENSIONS),
)
def test_random_bytes_after_a_plausible_header(head, data, ext):
    _load_or_mesh_error(_write(head + data, ext))


@pytest.fixture(scope="module")
def valid_files(icosphere) -> dict[str, bytes]:
    v, f = icosphere
    return {ext: save_mesh(_DIR / f"valid{ext}", v, f).read_bytes() for ext in (".obj", ".ply", ".glb", ".off", ".stl")}


@FUZZ
@given(cut=st.floats(0.0, 1.0), ext=st.sampled_from((".obj", ".ply", ".glb", ".off", ".stl")))
def test_valid_files_truncated_anywhere(valid_files, cut, ext):
    data = valid_files[ext]
    _load_or_mesh_error(_write(data[: int(cut * len(data))], ext))


@FUZZ
@given(cut=st.integers(1, len(VALID_OBJ) - 1))
def test_obj_cut_mid_line_is_reported_as_truncated(cut):
    text = VALID_OBJ[:cut]
    out = _load_or_mesh_error(_write(text, ".obj"))
    last = text.rsplit("\n", 1)[-1].split()
    incomplete = bool(last) and ((last[0] == "v" and len(last) < 4) or (last[0] == "f" and len(last) < 4))
    if incomplete:
        assert isinstance(out, MeshError) and "truncated" in str(out), (text[-40:], out)


@FUZZ
@given(
    flips=st.lists(st.tuples(st.integers(0, 10**9), st.integers(1, 255)), min_size=1, max_size=8),
    ext=st.sampled_from((".obj", ".ply", ".glb", ".off", ".stl")),
)
def test_valid_files_with_flipped_bytes(valid_files, flips, ext):
    data = bytearray(valid_files[ext])
    for pos, mask in flips:
        data[pos % len(data)] ^= mask
    _load_or_mesh_error(_write(bytes(data), ext))


_NUMBER = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["nan", "inf", "-inf", "1e400", "-0", "1e-400", "0x1p3", "", "1.2.3", "--1", "NaN"]),
)
_INDEX = st.one_of(
    st.integers(-(10**30), 10**30),
    st.sampled_from(["0", "-1", "-4", "99999999999999999999", "1/", "1//2", "/1", "a", "1.5", "", "-0"]),
)


@FUZZ
@given(
    verts=st.lists(st.lists(_NUMBER, min_size=0, max_size=5), min_size=0, max_size=6),
    faces=st.lists(st.lists(_INDEX, min_size=0, max_size=5), min_size=0, max_size=5),
    newline=st.booleans(),
)
def test_obj_with_odd_coordinates_and_indices(verts, faces, newline):
    lines = ["v " + " ".join(str(x) for x in row) for row in verts]
    lines += ["f " + " ".join(str(i) for i in row) for row in faces]
    _load_or_mesh_error(_write("\n".join(lines) + ("\n" if newline else ""), ".obj"))


@FUZZ
@given(
    bad=st.sampled_from([math.nan, math.inf, -math.inf]),
    row=st.integers(0, 2),
    col=st.integers(0, 2),
    index=st.sampled_from([-(10**12), -4, -1, 3, 4, 2**31, 2**63 - 1, 10**12]),
)
def test_nan_coordinates_and_huge_or_negative_indices(bad, row, col, index):
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    f = np.array([[0, 1, 2]])
    vb = v.copy()
    vb[row, col] = bad
    assert isinstance(_call_or_mesh_error(validate_mesh, vb, f), MeshError)
    fb = f.copy()
    fb[0, col] = index
    assert isinstance(_call_or_mesh_error(validate_mesh, v, fb), MeshError)
    assert isinstance(_call_or_mesh_error(as_mesh, (v, fb)), MeshError)
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf " + " ".join(str(int(i) + 1) for i in fb[0]) + "\n"
    _load_or_mesh_error(_write(text, ".obj"))


def test_empty_files_and_obj_with_only_vertices():
    for ext in EXTENSIONS:
        assert isinstance(_load_or_mesh_error(_write(b"", ext)), MeshError)
    out = _load_or_mesh_error(_write("v 0 0 0\nv 1 0 0\nv 0 1 0\n", ".obj"))
    assert isinstance(out, MeshError) and "no triangle faces" in str(out)


_DTYPES = st.sampled_from(
    [
        np.float64,
        np.float32,
        np.float16,
        np.int64,
        np.int32,
        np.uint8,
        np.bool_,
        np.complex64,
        np.dtype("U3"),
        np.dtype("datetime64[s]"),
        object,
    ]
)


@st.composite
def _arrays(draw):
    dtype = draw(_DTYPES)
    shape = draw(hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5))
    if dtype is object:
        return np.array(
            [
                draw(st.one_of(st.none(), st.integers(), st.floats(), st.text(max_size=2)))
                for _ in range(int(np.prod(shape)))
            ],
            dtype=object,
        ).reshape(shape)
    return draw(hnp.arrays(np.dtype(dtype), shape))


_ODD = st.one_of(
    _arrays(),
    st.none(),
    st.integers(),
    st.floats(),
    st.text(max_size=4),
    st.lists(st.lists(st.one_of(st.integers(-5, 5), st.floats()), max_size=4), max_size=4),
)


V3 = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
F3 = np.array([[0, 1, 2], [0, 2, 3]])


@st.composite
def _rows_of_three(draw):
    """(n, 3) arrays of any dtype: they get past the shape checks, so the dtype handling is what is tested."""
    dtype = draw(_DTYPES)
    n = draw(st.integers(1, 4))
    if dtype is object:
        values = st.one_of(st.none(), st.integers(-(10**20), 10**20), st.floats(), st.text(max_size=2))
        return np.array([draw(values) for _ in range(3 * n)], dtype=object).reshape(n, 3)
    return draw(hnp.arrays(np.dtype(dtype), (n, 3)))


@FUZZ
@given(vertices=st.one_of(_ODD, _rows_of_three()), faces=st.one_of(_ODD, _rows_of_three()))
def test_arrays_of_wrong_shapes_and_dtypes(vertices, faces):
    for v, f in ((vertices, faces), (V3, faces), (vertices, F3)):
        _call_or_mesh_error(validate_mesh, v, f)
        _call_or_mesh_error(as_mesh, (v, f))


@pytest.mark.parametrize(
    ("vertices", "faces", "pattern"),
    [
        (V3, np.array([["0", "1", "2"]]), "integers"),  # leaked TypeError from np.isfinite
        (V3, np.array([[0, 1, 2]], dtype="datetime64[s]"), "integers"),  # leaked TypeError from np.round
        (V3, np.array([[True, False, True]]), "integers"),
        (V3, np.array([[0, 1, 2]], dtype=complex), "integers"),  # the imaginary part was dropped silently
        (V3 + 1j, F3, "real numbers"),
        (np.zeros((3, 3), dtype="datetime64[s]"), [[0, 1, 2]], "real numbers"),
        (V3 * 1e300, F3, "float32 range"),  # became inf after the float32 cast
        (V3, np.array([[0, 1, 1e300]]), "outside"),  # was wrapped to -2**63 by the int64 cast
        (V3, np.array([[0, 1, 2**64 - 1]], dtype=np.uint64), r"outside .* 18446744073709551615"),
        (V3, np.array([[0, 1, None]], dtype=object), "integers"),
        (V3, [[0, 1, 2], [0, 1]], "not an integer"),
    ],
)
def test_array_regressions_found_by_fuzzing(vertices, faces, pattern):
    with pytest.raises(MeshError, match=pattern):
        validate_mesh(vertices, faces)


def test_unreadable_paths_are_mesh_errors():
    for path in ("bad\x00name.obj", str(_DIR / ("x" * 300 + ".obj"))):  # a NUL byte, a name too long for the OS
        with pytest.raises(MeshError, match="name.obj|xxx"):
            load_mesh(path)
        with pytest.raises(MeshError):
            as_mesh(path)


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv 1 1", "truncated"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4", "truncated"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 -", "truncated"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv", "truncated"),
        ("v 0 0 0\nv 1 0\nv 0 1 0\nv 1 1 1\nf 1 2 3\n", "line 2 .* malformed"),  # trimesh read (V, 2) vertices
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 2 4\nf 1 2 3\n", "line 5 .* malformed"),  # trimesh dropped it
    ],
)
def test_incomplete_obj_lines(text, pattern):
    out = _load_or_mesh_error(_write(text, ".obj"))
    assert isinstance(out, MeshError) and re.search(pattern, str(out)), out


@FUZZ
@given(
    faces=hnp.arrays(
        st.sampled_from([np.int64, np.int32, np.float64]),
        hnp.array_shapes(min_dims=2, max_dims=2, max_side=6),
        elements=st.integers(-3, 5),
    )
)
def test_small_valid_vertices_random_faces(faces):
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    _call_or_mesh_error(validate_mesh, v, faces)


# --- UVs and normals (vt / vn) ---------------------------------------------------------------------------------------

GRID_V = np.array([[x, y, 0.1 * x * y] for y in range(3) for x in range(3)], dtype=np.float64)
GRID_F = np.array([[a, a + 1, a + 4] for a in (0, 1, 3, 4)] + [[a, a + 4, a + 3] for a in (0, 1, 3, 4)])


def _corner_table(f: np.ndarray, *attribute_faces: np.ndarray | None) -> list[tuple]:
    """Every corner as (its triangle's sorted vertices, vertex, each attribute index): comparable across readers
    that order or turn the triangles differently."""
    columns = [np.asarray(f)] + [np.full(np.shape(f), -1) if a is None else np.asarray(a) for a in attribute_faces]
    return sorted(
        (tuple(sorted(f[i].tolist())),) + tuple(int(c[i, j]) for c in columns) for i in range(len(f)) for j in range(3)
    )


@FUZZ
@given(data=st.data())
def test_obj_attributes_read_back_however_the_file_spells_them(data):
    """vt/vn lists and corner indices come back exactly whatever the spelling: absolute or relative (negative)
    indices, lines interleaved, vt with 1 to 3 numbers, corners without vt or vn, comments, blank lines, indentation,
    tabs, LF or CRLF line ends."""
    has_uv, has_normal = data.draw(st.sampled_from([(True, True), (True, False), (False, True)]))
    finite = st.floats(-10, 10, allow_nan=False)
    k, m = (data.draw(st.integers(1, 6)) if has else 0 for has in (has_uv, has_normal))
    uvs = np.array(data.draw(st.lists(st.tuples(finite, finite), min_size=k, max_size=k))).reshape(k, 2)
    normals = np.array(data.draw(st.lists(st.tuples(finite, finite, finite), min_size=m, max_size=m))).reshape(m, 3)
    uv_faces = np.array(data.draw(st.lists(st.integers(0, max(k - 1, 0)), min_size=24, max_size=24))).reshape(8, 3)
    n_faces = np.array(data.draw(st.lists(st.integers(0, max(m - 1, 0)), min_size=24, max_size=24))).reshape(8, 3)
    vt_numbers = data.draw(st.lists(st.sampled_from([1, 2, 3]), min_size=k, max_size=k))
    uvs[np.array(vt_numbers) == 1, 1] = 0.0  # 'vt u' reads as (u, 0)

    def line(text: str) -> str:  # v and f lines stay plain for the mesh reader (the fast one takes no indentation)
        indent = data.draw(st.sampled_from(["", " ", "\t "])) if text[:2] in ("vt", "vn") else ""
        return indent + text + data.draw(st.sampled_from(["", " ", " # note", "#c 1 2"]))

    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in GRID_V.tolist()]
    seen = {"vt": 0, "vn": 0, "f": 0}  # the lines of each kind so far: the next one's index
    for kind in data.draw(st.permutations(["vt"] * k + ["vn"] * m + ["f"] * 8)):
        i = seen[kind]
        if data.draw(st.booleans()):
            lines.append(data.draw(st.sampled_from(["", "# a comment", "   ", "vp 0.5"])))
        if kind == "vt":
            lines.append(line("vt " + " ".join(map(repr, (*uvs[i].tolist(), 0.25)[: vt_numbers[i]]))))
        elif kind == "vn":
            lines.append(line("vn " + " ".join(map(repr, normals[i].tolist()))))
        else:

            def index(j: int, count: int, relative: bool) -> str:
                return str(j - count) if relative and j < count else str(j + 1)

            corners = []
            for c in range(3):
                v = str(GRID_F[i, c] + 1)
                t = index(uv_faces[i, c], seen["vt"], data.draw(st.booleans())) if has_uv else ""
                n = index(n_faces[i, c], seen["vn"], data.draw(st.booleans())) if has_normal else None
                corners.append(v + ("/" + t if has_uv or n is not None else "") + ("" if n is None else "/" + n))
            lines.append(line("f " + " ".join(corners)))
        seen[kind] += 1
    end = data.draw(st.sampled_from(["\n", "\r\n"]))
    path = _write(end.join(lines) + end, ".obj")
    v, f, attrs = load_mesh_with_attributes(path)
    np.testing.assert_allclose(v, GRID_V, atol=1e-6)
    np.testing.assert_array_equal(attrs.uvs if has_uv else np.zeros((0, 2)), uvs)
    np.testing.assert_array_equal(attrs.normals if has_normal else np.zeros((0, 3)), normals)
    expected = _corner_table(GRID_F, uv_faces if has_uv else None, n_faces if has_normal else None)
    assert _corner_table(f, attrs.uv_faces, attrs.normal_faces) == expected


_ATTRIBUTE_FIELD = st.sampled_from(
    ["0", "1", "2", "9", "-1", "-3", "0.5", "1e999", "nan", "x", "", "1/1", "1/2/1", "1//1", "2/-1/-1", "/1", "1/x"]
    + ["99999999999999999999/1", "1/99999999999999999999", "1/1/1/1", "1_0/1"]
)


@FUZZ
@given(lines=st.lists(st.tuples(st.sampled_from(["vt", "vn", "f", "v", "#"]), st.lists(_ATTRIBUTE_FIELD, max_size=5))))
def test_random_attribute_lines_load_or_give_one_line_errors(lines):
    """A valid mesh followed by random vt / vn / f lines: attributes that fit the mesh, or a one-line MeshError."""
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in GRID_V.tolist()) + "vt 0 0\nvn 0 0 1\n"
    text += "".join(f"f {a + 1}/1/1 {b + 1}/1/1 {c + 1}/1/1\n" for a, b, c in GRID_F.tolist())
    path = _write(text + "".join(" ".join([kind, *fields]) + "\n" for kind, fields in lines), ".obj")
    try:
        v, f, attrs = load_mesh_with_attributes(path)
    except MeshError as exc:
        assert str(exc) and "\n" not in str(exc) and path.name in str(exc), str(exc)
        return
    _is_valid(v, f)
    attrs.check(len(f), name="fuzz")
