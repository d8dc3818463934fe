import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from garsim.cli import INCOMPLETE, build_parser, main
from garsim.data.store import DatasetStore


def test_data_info_and_verify(tmp_path, capsys):
    from store_fixtures import make_record

    store = DatasetStore(tmp_path)
    store.append_manifest(store.write_sequence(make_record("s0")))
    assert main(["data", "info", str(tmp_path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["sequences"] == 1 and info["samples"] == 3
    assert main(["data", "info", str(tmp_path)]) == 0
    assert "3 samples" in capsys.readouterr().out
    assert main(["data", "info", str(tmp_path / "nothing")]) != 0
    assert "not a garsim dataset" in capsys.readouterr().err
    assert main(["data", "verify", str(tmp_path)]) == 0
    path = tmp_path / "sequences/s0.npz"
    path.write_bytes(path.read_bytes()[:100])
    assert main(["data", "verify", str(tmp_path)]) == 1
    assert "truncated" in capsys.readouterr().out


def test_drape_prior_only_writes_mesh_and_png(tmp_path):
    body = trimesh.creation.icosphere(subdivisions=3)
    moved = body.copy()
    moved.apply_translation([0.0, 0.0, 0.2])
    garment = trimesh.creation.icosphere(subdivisions=2)
    garment.apply_scale(1.1)
    for name, m in (("c.obj", body), ("t.obj", moved), ("g.obj", garment)):
        m.export(tmp_path / name)
    out = tmp_path / "out.obj"
    rc = main(
        [
            "drape",
            "--canonical",
            str(tmp_path / "c.obj"),
            "--target",
            str(tmp_path / "t.obj"),
            "--garment",
            str(tmp_path / "g.obj"),
            "--fabric",
            "silk",
            "--out",
            str(out),
            "--prior-only",
            "--png",
            str(tmp_path / "out.png"),
        ]
    )
    assert rc == 0 and (tmp_path / "out.png").stat().st_size > 1000
    draped = trimesh.load(out, process=False)
    np.testing.assert_allclose(draped.vertices, np.asarray(garment.vertices) + [0, 0, 0.2], atol=1e-5)


def test_fabric_argument_takes_a_preset_or_physical_values(scene, tmp_path):
    """``--fabric``: a preset name (any case) or key=value physical values, which the model drapes with."""
    from garsim.cli import fabric_arg

    assert fabric_arg(" Denim") == "denim"
    assert fabric_arg("bending=2e-5, density=0.2,stretch=3000") == {"bending": 2e-5, "density": 0.2, "stretch": 3000.0}
    folder, _ = scene
    outs = {}
    for fabric in ("silk", "bending=1e-3,density=0.9,stretch=20000"):
        out = tmp_path / f"{len(outs)}.obj"
        argv = ["drape", "--canonical", str(folder / "c.obj"), "--target", str(folder / "t.obj")]
        assert main([*argv, "--garment", str(folder / "g.obj"), "--fabric", fabric, "--out", str(out)]) == 0
        outs[fabric] = np.asarray(trimesh.load(out, process=False).vertices)
    assert np.abs(outs["silk"] - outs["bending=1e-3,density=0.9,stretch=20000"]).max() > 1e-4  # the values count


def test_errors_are_reported_not_raised(tmp_path, capsys):
    rc = main(
        [
            "drape",
            "--canonical",
            str(tmp_path / "missing.obj"),
            "--target",
            "x.obj",
            "--garment",
            "y.obj",
            "--out",
            str(tmp_path / "o.obj"),
            "--prior-only",
        ]
    )
    assert rc == 2 and "no such file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        build_parser().parse_args(["data", "generate", "--out", "x", "--shard", "3/2"])


def test_data_generate_passes_its_settings(tmp_path, monkeypatch, capsys):
    """``garsim data generate`` hands the counts, the shard and ``--no-graphs`` to the generator's config."""
    import garsim.physics.generate as gen

    seen = []
    monkeypatch.setattr(gen, "generate", lambda cfg, progress: seen.append(cfg) or {"seconds": []})
    out = str(tmp_path / "d")
    assert main(["data", "generate", "--out", out, "--train", "3", "--shard", "1/2", "--no-graphs", "--quiet"]) == 0
    assert main(["data", "generate", "--out", out, "--quiet", "--strap-pins", "crest", "--reuse", "v4"]) == 0
    (a, b) = seen
    assert (a.num_train, a.shard, a.sim) == (3, (1, 2), {"graphs": False}) and b.sim == {}
    assert (a.strap_pins, a.reuse, b.strap_pins, b.reuse) == ("band", None, "crest", Path("v4"))
    assert b.num_train == gen.GenerateConfig.num_train and a.settings() == replace(b, strap_pins="band").settings()
    assert '"seconds"' not in capsys.readouterr().out
    # jobs that failed transiently are not recorded: the run says so and exits INCOMPLETE, for a script to rerun it
    monkeypatch.setattr(gen, "generate", lambda cfg, progress: {"seconds": [], "errors": 2})
    assert main(["data", "generate", "--out", out, "--quiet"]) == INCOMPLETE == 3
    assert "2 jobs failed and were not recorded; rerun the same command" in capsys.readouterr().err


def test_demo(tmp_path, capsys):
    """The demo end to end on tiny settings (~15 s): every family on both bodies, the grid, the walk animation."""
    import struct

    from garsim.demo import DEMO_BODIES, DEMO_GARMENTS

    assert main(["demo", "--out", str(tmp_path), "--vertices", "300", "--frames", "3"]) == 0
    out = capsys.readouterr().out
    for body in DEMO_BODIES:
        assert (tmp_path / f"{body}_body.obj").exists()
        for kind in DEMO_GARMENTS:
            assert trimesh.load(tmp_path / f"{body}_{kind}.obj", process=False).vertices.shape[0] > 100
            assert f"{body} {kind}" in " ".join(out.split())  # a timing line per drape
    png = (tmp_path / "demo.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000
    for ext in (".glb", ".usdc", ".gif", ".npz"):
        assert (tmp_path / f"walk_dress{ext}").stat().st_size > 0
        assert str(tmp_path / f"walk_dress{ext}") in out
    data = (tmp_path / "walk_dress.glb").read_bytes()
    (json_len,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + json_len])
    assert doc["extras"]["frames"] == 3
    assert all(len(m["primitives"][0]["targets"]) == 3 for m in doc["meshes"])
    with np.load(tmp_path / "walk_dress.npz") as z:
        assert z["frames"].shape[0] == z["prior_frames"].shape[0] == z["body_frames"].shape[0] == 3


def test_animate_writes_an_animation_matching_single_drapes(tmp_path, anny_body):
    """`garsim animate --motion` writes a GLB whose frames are the per-frame drapes; bad extensions fail first."""
    from garsim import GarSim
    from garsim.bodies.poses import batched_matrices, motion, stack_poses
    from garsim.garments.templates import make_garment
    from garsim.geometry.io import save_mesh

    g = make_garment("skirt", anny_body, target_vertices=300)
    path = tmp_path / "skirt.obj"
    save_mesh(path, g.vertices, g.faces)
    assert (
        main(
            [
                "animate",
                "--garment",
                str(path),
                "--motion",
                "raise_arms",
                "--frames",
                "4",
                "--prior-only",
                "--quiet",
                "--out",
                str(tmp_path / "a.pc2"),
            ]
        )
        == 0
    )
    from garsim.export import read_pc2

    frames, _, _ = read_pc2(tmp_path / "a.pc2")
    bodies = anny_body.pose_batch(batched_matrices(stack_poses(motion("raise_arms", 4))))[0]
    can = anny_body.canonical().vertices
    last = GarSim.prior_only().drape((can, anny_body.faces), (bodies[-1], anny_body.faces), (g.vertices, g.faces))
    assert frames.shape == (4, len(g.vertices), 3)
    np.testing.assert_allclose(frames[-1], last, atol=1e-5)
    assert main(["animate", "--garment", str(path), "--motion", "walk", "--out", str(tmp_path / "a.fbx")]) != 0
    assert not (tmp_path / "a.fbx").exists()


# --- every command's --help: defaults and an example ---------------------------------------------------------------


def _commands(parser=None, prefix=()) -> list[tuple[str, ...]]:
    """Every command path of the parser: (), ("drape",), ("data", "generate"), ..."""
    import argparse

    parser = parser or build_parser()
    paths = [prefix]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                paths += _commands(sub, (*prefix, name))
    return paths


def test_every_command_is_listed():
    assert {" ".join(c) for c in _commands()} >= {"", "drape", "animate", "view", "demo", "data generate", "train"}


@pytest.mark.parametrize("command", _commands(), ids=lambda c: " ".join(c) or "garsim")
def test_help_shows_defaults_and_an_example(command):
    """`garsim ... --help` through the installed entry point's module: exit 0, an example of this very command."""
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-m", "garsim.cli", *command, "--help"], capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, r.stderr
    assert "Example:" in r.stdout
    example = r.stdout.split("Example:", 1)[1]
    assert "garsim " + " ".join(command) in example
    if command in {("drape",), ("animate",), ("demo",), ("bench",), ("train",), ("data", "generate")}:
        assert "(default: " in r.stdout


def test_version_is_the_package_version(capsys):
    from garsim import __version__

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"garsim {__version__}"


def test_help_defaults_are_the_library_defaults(capsys):
    """Options that leave their default to a config class show that class's value (read without importing it)."""
    import dataclasses

    from garsim.cli import dataclass_default
    from garsim.train.losses import LossWeights
    from garsim.train.trainer import TrainConfig

    for cls in (TrainConfig, LossWeights):
        module = cls.__module__
        for f in dataclasses.fields(cls):
            if f.default is not dataclasses.MISSING:
                assert dataclass_default(module, cls.__name__, f.name) == repr(f.default), f.name
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = capsys.readouterr().out
    assert f"(default: {TrainConfig().epochs})" in text and f"(default: {LossWeights().eps})" in text


def test_cli_import_is_light():
    """`garsim --help` and argument errors load neither numpy nor torch (and the drape path pins threads first)."""
    import subprocess
    import sys

    code = "import sys, garsim.cli; sys.exit(any(m in sys.modules for m in ('numpy', 'torch', 'trimesh')))"
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0


def test_cli_choices_match_the_library():
    from garsim.bodies.poses import MOTIONS
    from garsim.cli import (
        ANIMATION_OUTPUTS,
        FABRIC_CHOICES,
        FAMILY_CHOICES,
        GROUP_CHOICES,
        MESH_INPUTS,
        MESH_OUTPUTS,
        MODEL_CHOICES,
        MOTION_CHOICES,
        STRAP_CHOICES,
    )
    from garsim.data.sample import FABRICS, GARMENT_TYPES
    from garsim.eval.experiments import GROUPS
    from garsim.export import SUPPORTED_EXTENSIONS
    from garsim.geometry.io import SUPPORTED_EXTENSIONS as MESH_EXTENSIONS
    from garsim.model.baselines import MODELS
    from garsim.physics.generate import STRAP_PINS

    assert FABRIC_CHOICES == FABRICS and MOTION_CHOICES == MOTIONS and set(MODEL_CHOICES) == set(MODELS)
    assert FAMILY_CHOICES == GARMENT_TYPES and GROUP_CHOICES == tuple(sorted(GROUPS)) and STRAP_CHOICES == STRAP_PINS
    assert set(ANIMATION_OUTPUTS) == set(SUPPORTED_EXTENSIONS) | {".npz"}  # .npz: the viewer's sequence
    assert set(MESH_OUTPUTS) == set(MESH_EXTENSIONS) - {".gltf", ".usdz"} and set(MESH_INPUTS) == set(MESH_EXTENSIONS)


# --- bad input: one line that says what to fix, exit status 2, no traceback, no output -----------------------------


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A standing ellipsoid 'body' (1.7 m, Z up, metres), the same body moved, and a garment around its waist (an
    open band of a wider ellipsoid: its caps would be inside the body)."""
    folder = tmp_path_factory.mktemp("scene")
    body = trimesh.creation.icosphere(subdivisions=3)
    body.apply_scale([0.2, 0.15, 0.85])
    body.apply_translation([0.0, 0.0, 0.85])
    shell = trimesh.creation.icosphere(subdivisions=3)
    shell.apply_scale([0.24, 0.19, 0.3])
    shell.apply_translation([0.0, 0.0, 0.9])
    garment = shell.submesh([np.flatnonzero((np.abs(shell.vertices[shell.faces][:, :, 2] - 0.9) < 0.12).all(1))])[0]
    moved = body.copy()
    moved.apply_translation([0.0, 0.0, 0.1])
    meshes = {"c": body, "t": moved, "g": garment}
    for name, m in meshes.items():
        m.export(folder / f"{name}.obj")
    return folder, meshes


def _write_obj(path, vertices, faces):
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def _bad_inputs(folder, meshes):
    """name -> (files to write {name: writer}, argument changes, expected text in the message)."""
    g = meshes["g"]
    gv, gf = np.asarray(g.vertices), np.asarray(g.faces)
    c, cf = np.asarray(meshes["c"].vertices), np.asarray(meshes["c"].faces)
    nan = gv.copy()
    nan[3] = np.nan
    oob = gf.copy()
    oob[5, 1] = len(gv) + 7
    text = (folder / "g.obj").read_text()
    other = trimesh.creation.icosphere(subdivisions=2)
    other.apply_scale([0.2, 0.15, 0.85])
    other.apply_translation([0.0, 0.0, 0.95])
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # Z up -> Y up
    return {
        "missing mesh": ({}, {"--garment": "nothing.obj"}, "no such file"),
        "empty mesh": ({"empty.obj": lambda p: p.write_text("")}, {"--garment": "empty.obj"}, "empty"),
        "truncated mesh": (
            {"cut.obj": lambda p: p.write_text(text[: text.rindex("\nf ") + 6])},
            {"--garment": "cut.obj"},
            "truncated",
        ),
        "unreadable mesh (a folder)": ({"dir.obj": lambda p: p.mkdir()}, {"--garment": "dir.obj"}, "directory"),
        "unparseable mesh": (
            {"junk.ply": lambda p: p.write_bytes(b"ply\nformat binary_little_endian 1.0\n\x00\x01garbage")},
            {"--garment": "junk.ply"},
            "junk.ply",
        ),
        "unknown mesh format": ({"g.fbx": lambda p: p.write_text("x")}, {"--garment": "g.fbx"}, "'.fbx'"),
        "NaN vertex": ({"nan.obj": lambda p: _write_obj(p, nan, gf)}, {"--garment": "nan.obj"}, "NaN"),
        "face out of range": (
            {"oob.obj": lambda p: p.write_text(text + "f 1 2 999\n")},
            {"--garment": "oob.obj"},
            "vertices that do not exist",
        ),
        "bodies of different topologies": (
            {"other.obj": lambda p: other.export(p)},
            {"--target": "other.obj"},
            "topology",
        ),
        "wrong axis": (
            {f"{n}_y.obj": (lambda p, n=n: _write_obj(p, meshes[n].vertices @ rot.T, meshes[n].faces)) for n in "ctg"},
            {"--canonical": "c_y.obj", "--target": "t_y.obj", "--garment": "g_y.obj"},
            "--up y",
        ),
        "wrong unit": (
            {f"{n}_cm.obj": (lambda p, n=n: _write_obj(p, meshes[n].vertices * 100, meshes[n].faces)) for n in "ctg"},
            {"--canonical": "c_cm.obj", "--target": "t_cm.obj", "--garment": "g_cm.obj"},
            "--units cm",
        ),
        "--up y on a Z-up file": ({}, {"--up": "y"}, "--up z"),
        "--units cm on a metre file": ({}, {"--units": "cm"}, "--units m"),
        "output checked before the inputs": ({}, {"--garment": "nothing.obj", "--out": "draped.fbx"}, "'.fbx'"),
        "garment far from the body": (
            {"far.obj": lambda p: _write_obj(p, gv + [2.0, 0.0, 0.0], gf)},
            {"--garment": "far.obj"},
            "from the canonical body",
        ),
        "garment alone in another axis": (
            {"g_y.obj": lambda p: _write_obj(p, gv @ rot.T, gf)},
            {"--garment": "g_y.obj"},
            "another axis or unit",
        ),
        "garment alone in another unit": (
            {"g_cm.obj": lambda p: _write_obj(p, gv * 100, gf)},
            {"--garment": "g_cm.obj"},
            "another axis or unit",
        ),
        "garment partly inside the body": (
            {"in.obj": lambda p: _write_obj(p, gv * [0.8, 0.8, 1.0], gf)},
            {"--garment": "in.obj"},
            "inside the canonical body",
        ),
        "target in another unit": (
            {"t_mm.obj": lambda p: _write_obj(p, np.asarray(meshes["t"].vertices) * 1000, cf)},
            {"--target": "t_mm.obj"},
            "the size of the canonical body",
        ),
        "target in another axis": (
            {"t_y.obj": lambda p: _write_obj(p, np.asarray(meshes["t"].vertices) @ rot.T, cf)},
            {"--target": "t_y.obj"},
            "away from the canonical body's vertical",
        ),
        "unknown fabric": ({}, {"--fabric": "wool"}, "unknown fabric 'wool'"),
        "fabric value not a number": ({}, {"--fabric": "bending=soft"}, "'bending=soft' is not key=number"),
        "fabric values incomplete": ({}, {"--fabric": "bending=2e-5,density=0.2"}, "missing stretch"),
        "pinned index out of range": (
            {"pins.txt": lambda p: p.write_text("0 1 100000\n")},
            {"--pinned": "pins.txt"},
            "pinned indices",
        ),
        "pinned file empty": ({"pins.txt": lambda p: p.write_text("\n")}, {"--pinned": "pins.txt"}, "is empty"),
        "pinned file not numbers": (
            {"pins.txt": lambda p: p.write_text("waist\n")},
            {"--pinned": "pins.txt"},
            "--pinned",
        ),
        "unsupported output extension": ({}, {"--out": "out/draped.fbx"}, "'.fbx'"),
        "output folder under a file": (
            {"afile": lambda p: p.write_text("x")},
            {"--out": "afile/draped.obj"},
            "is a file",
        ),
        "output is a folder": ({"outdir.obj": lambda p: p.mkdir()}, {"--out": "outdir.obj"}, "is a folder"),
        "png extension": ({}, {"--png": "out/draped.jpg"}, "--png"),
        "--pinned auto on a closed garment": (
            {"closed.obj": lambda p: _write_obj(p, (c - [0.0, 0.0, 0.85]) * 1.15 + [0.0, 0.0, 0.85], cf)},
            {"--pinned": "auto", "--garment": "closed.obj"},
            "no border loop",
        ),
        "--format disagrees with --out": ({}, {"--format": "glb"}, "--format glb disagrees"),
        "output over an input": (
            {"g2.obj": lambda p: p.write_text(text)},
            {"--garment": "g2.obj", "--out": "g2.obj"},
            "would overwrite the input",
        ),
    }


def _rc(argv) -> int:
    """main's exit status, also for argparse's usage errors (which exit)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code)


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize(
    "case",
    [
        "missing mesh",
        "empty mesh",
        "truncated mesh",
        "unreadable mesh (a folder)",
        "unparseable mesh",
        "unknown mesh format",
        "NaN vertex",
        "face out of range",
        "bodies of different topologies",
        "wrong axis",
        "wrong unit",
        "--up y on a Z-up file",
        "--units cm on a metre file",
        "output checked before the inputs",
        "garment far from the body",
        "garment alone in another axis",
        "garment alone in another unit",
        "garment partly inside the body",
        "target in another unit",
        "target in another axis",
        "unknown fabric",
        "fabric value not a number",
        "fabric values incomplete",
        "pinned index out of range",
        "pinned file empty",
        "pinned file not numbers",
        "unsupported output extension",
        "output folder under a file",
        "output is a folder",
        "png extension",
        "--pinned auto on a closed garment",
        "--format disagrees with --out",
        "output over an input",
    ],
)
def test_drape_bad_input_is_one_line(case, scene, tmp_path, capsys, monkeypatch):
    folder, meshes = scene
    files, changes, expected = _bad_inputs(folder, meshes)[case]
    monkeypatch.chdir(tmp_path)
    for name, write in files.items():
        write(tmp_path / name)
    args = {
        "--canonical": str(folder / "c.obj"),
        "--target": str(folder / "t.obj"),
        "--garment": str(folder / "g.obj"),
        "--out": "out/draped.obj",
        **changes,
    }
    before = set(tmp_path.rglob("*"))
    assert _rc(["drape", "--prior-only", *[x for kv in args.items() for x in kv]]) == 2
    assert expected in _one_error_line(capsys)
    assert set(tmp_path.rglob("*")) == before  # no output, not even a folder


def test_drape_keeps_uv_seams_and_vertex_order(scene, tmp_path):
    """A garment OBJ with UV seams (more vt than v, f v/vt/vn) draped with --prior-only: the output has the draped
    positions in the input's vertex order, the same vt list and the same face corner indices."""
    from mesh_fixtures import obj_lists, seamed_obj_text

    from garsim import GarSim

    folder, meshes = scene
    g = meshes["g"]
    text, vt, _ = seamed_obj_text(np.asarray(g.vertices), np.asarray(g.faces))
    (tmp_path / "g.obj").write_text(text)
    out = tmp_path / "draped.obj"
    argv = [
        "--canonical",
        str(folder / "c.obj"),
        "--target",
        str(folder / "t.obj"),
        "--garment",
        str(tmp_path / "g.obj"),
    ]
    assert main(["drape", *argv, "--prior-only", "--out", str(out)]) == 0
    v, out_vt, out_f = obj_lists(out)
    c, t = meshes["c"], meshes["t"]
    expected = GarSim.prior_only().drape(c, t, (g.vertices, g.faces))
    np.testing.assert_allclose(v, expected, atol=1e-6)
    assert len(vt) > len(v)
    np.testing.assert_array_equal(out_vt, vt)
    in_f = [line.split()[1:] for line in text.splitlines() if line.startswith("f ")]
    assert [[c.split("/")[:2] for c in face] for face in out_f] == [[c.split("/")[:2] for c in face] for face in in_f]
    assert [[c.split("/")[2] for c in face] for face in out_f] == [[c.split("/")[2] for c in face] for face in in_f]


def _bodies(folder, c, faces, names_shifts):
    folder.mkdir(exist_ok=True)
    for name, dz in names_shifts:
        _write_obj(folder / name, c + [0.0, 0.0, dz], faces)
    return folder


def test_drape_batch_writes_one_output_per_target(scene, tmp_path, capsys):
    """--target FOLDER (sorted by name) or several files, --out a folder: <target name>.<ext> per target, each the
    single drape on that target; the garment's UVs go to every output; --format picks the type."""
    from mesh_fixtures import obj_lists, seamed_obj_text

    from garsim import GarSim
    from garsim.geometry.io import load_mesh

    folder, meshes = scene
    c, faces, g = np.asarray(meshes["c"].vertices), np.asarray(meshes["c"].faces), meshes["g"]
    bodies = _bodies(tmp_path / "bodies", c, faces, [("b.obj", 0.05), ("a.obj", 0.1), ("c.obj", -0.05)])
    (bodies / "notes.txt").write_text("not a mesh")
    text, vt, _ = seamed_obj_text(np.asarray(g.vertices), np.asarray(g.faces), normals=False)
    (tmp_path / "g.obj").write_text(text)
    argv = ["drape", "--canonical", str(folder / "c.obj"), "--garment", str(tmp_path / "g.obj"), "--prior-only"]
    out = tmp_path / "draped"
    assert main([*argv, "--target", str(bodies), "--out", str(out), "--png", str(tmp_path / "png")]) == 0
    printed = capsys.readouterr().out.split()
    names = ["a", "b", "c"]
    assert printed[0::2] == [str(out / f"{n}.obj") for n in names]
    assert printed[1::2] == [str(tmp_path / "png" / f"{n}.png") for n in names]
    sim = GarSim.prior_only()
    for name, dz in zip(names, (0.1, 0.05, -0.05)):
        v, out_vt, _ = obj_lists(out / f"{name}.obj")
        np.testing.assert_allclose(v, sim.drape((c, faces), (c + [0, 0, dz], faces), (g.vertices, g.faces)), atol=1e-6)
        np.testing.assert_array_equal(out_vt, vt)
    out2 = tmp_path / "glb"
    files = [str(bodies / "c.obj"), str(bodies / "a.obj")]
    assert main([*argv, "--target", *files, "--format", "glb", "--out", str(out2)]) == 0
    assert capsys.readouterr().out.split() == [str(out2 / "c.glb"), str(out2 / "a.glb")]  # in the order given
    glb = load_mesh(out2 / "c.glb", y_up=True)[0]  # glTF is Y up
    np.testing.assert_allclose(glb, np.asarray(g.vertices) - [0, 0, 0.05], atol=1e-5)


@pytest.mark.parametrize(
    "case, argv, expected",
    [
        ("a target of another topology", ["--target", "bodies/", "--out", "draped/"], "topology"),
        ("a missing target", ["--target", "bodies/a.obj", "none.obj", "--out", "draped/"], "no such file"),
        ("--out a file name", ["--target", "good/", "--out", "draped.obj"], "give a folder"),
        ("--out under a file", ["--target", "good/", "--out", "afile/draped"], "is a file"),
        ("--png a file name", ["--target", "good/", "--out", "o/", "--png", "x.png"], "give a folder"),
        ("two targets, one name", ["--target", "good/a.obj", "bodies/a.obj", "--out", "o/"], "rename one"),
        ("no meshes in the folder", ["--target", "empty/", "--out", "o/"], "no mesh files"),
        ("no meshes, --out a file", ["--target", "empty/", "--out", "o.obj"], "no mesh files"),
        ("a missing folder", ["--target", "nothing/", "--out", "o/"], "nothing: no such file or folder"),
        ("output over the targets", ["--target", "good/", "--out", "good/"], "would overwrite the input"),
    ],
)
def test_drape_batch_bad_input_is_one_line(case, argv, expected, scene, tmp_path, capsys, monkeypatch):
    """Every target is read and checked before the first drape: a bad one leaves nothing written."""
    folder, meshes = scene
    monkeypatch.chdir(tmp_path)
    c, faces = np.asarray(meshes["c"].vertices), np.asarray(meshes["c"].faces)
    _bodies(tmp_path / "good", c, faces, [("a.obj", 0.1), ("b.obj", 0.05)])
    _bodies(tmp_path / "bodies", c, faces, [("a.obj", 0.1), ("b.obj", 0.05)])
    trimesh.creation.icosphere(subdivisions=1).export(tmp_path / "bodies" / "z.obj")  # the last, another topology
    (tmp_path / "empty").mkdir()
    (tmp_path / "afile").write_text("x")
    before = set(tmp_path.rglob("*"))
    base = ["drape", "--prior-only", "--canonical", str(folder / "c.obj"), "--garment", str(folder / "g.obj")]
    assert _rc([*base, *argv]) == 2
    assert expected in _one_error_line(capsys)
    assert set(tmp_path.rglob("*")) == before


def test_drape_pinned_auto_keeps_the_top_loop_on_the_prior(scene, tmp_path):
    """--pinned auto on a tube open at both ends (around the scene's body), draped by the shipped model: the top
    ring follows the prior; the bottom ring and the rest are the model's."""
    from mesh_fixtures import loop_rows, open_cylinder

    from garsim import GarSim
    from garsim.geometry.io import load_mesh

    folder, meshes = scene
    gv, gf = open_cylinder(radius=0.26, z0=0.6, z1=1.1, rings=12, sections=40)
    _write_obj(tmp_path / "tube.obj", gv, gf)
    out = tmp_path / "draped.obj"
    argv = ["--canonical", str(folder / "c.obj"), "--target", str(folder / "t.obj"), "--garment"]
    assert main(["drape", *argv, str(tmp_path / "tube.obj"), "--pinned", "auto", "--out", str(out)]) == 0
    draped = load_mesh(out)[0]
    prior = GarSim.prior_only().drape(meshes["c"], meshes["t"], (gv, gf))
    top, bottom = loop_rows(40, 11), loop_rows(40, 0)
    np.testing.assert_allclose(draped[top], prior[top], atol=1e-7)
    assert np.abs(draped[bottom] - prior[bottom]).max() > 1e-4
    assert "auto" in build_parser()._subparsers._group_actions[0].choices["drape"].format_help()


@pytest.mark.parametrize(
    "case, argv, expected",
    [
        ("unsupported output", ["--motion", "walk", "--out", "walk.fbx"], "'.fbx'"),
        ("output under a file", ["--motion", "walk", "--out", "afile/walk.glb"], "is a file"),
        ("unknown motion", ["--motion", "dance", "--out", "walk.glb"], "invalid choice: 'dance'"),
        ("unknown fabric", ["--motion", "walk", "--fabric", "wool", "--out", "walk.glb"], "unknown fabric 'wool'"),
        ("no bodies", ["--out", "walk.glb"], "--motion NAME"),
        ("motion and bodies", ["--motion", "walk", "--canonical", "c.obj", "--out", "w.glb"], "not both"),
        ("one frame", ["--motion", "walk", "--frames", "1", "--out", "walk.glb"], "--frames"),
        (
            "frames without a motion",
            ["--canonical", "{c}", "--targets", "none/", "--frames", "10", "--out", "w.glb"],
            "--frames sets the length of a --motion",
        ),
        ("no fps", ["--motion", "walk", "--fps", "0", "--out", "walk.glb"], "--fps must be > 0, got 0"),
        ("missing targets", ["--canonical", "{c}", "--targets", "none/", "--out", "w.glb"], "no such file"),
        ("empty targets folder", ["--canonical", "{c}", "--targets", "empty/", "--out", "w.glb"], "no .obj"),
        ("targets of another topology", ["--canonical", "{c}", "--targets", "other/", "--out", "w.glb"], "topology"),
        ("npz without vertices", ["--canonical", "{c}", "--targets", "bad.npz", "--out", "w.glb"], "'vertices'"),
        ("truncated npz", ["--canonical", "{c}", "--targets", "cut.npz", "--out", "w.glb"], "not a readable .npz"),
        ("targets of wrong shape", ["--canonical", "{c}", "--targets", "flat.npz", "--out", "w.glb"], "(T, V, 3)"),
        (
            "pc2 whose OBJ is the garment",
            ["--motion", "walk", "--out", "{g}.pc2"],
            "would overwrite the input --garment",
        ),
        (
            "output over the targets",
            ["--canonical", "{c}", "--targets", "flat.npz", "--out", "flat.npz"],
            "would overwrite the input --targets",
        ),
        (
            "pc2 into the targets folder",
            ["--canonical", "{c}", "--targets", "other/", "--out", "other/0.pc2"],
            "would write 0.obj into the --targets folder",
        ),
    ],
)
def test_animate_bad_input_is_one_line(case, argv, expected, scene, tmp_path, capsys, monkeypatch):
    folder, meshes = scene
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "empty").mkdir()
    (tmp_path / "other").mkdir()
    trimesh.creation.icosphere(subdivisions=1).export(tmp_path / "other" / "0.obj")
    np.savez(tmp_path / "bad.npz", frames=np.zeros((2, 3, 3)))
    np.savez(tmp_path / "flat.npz", vertices=np.zeros((5, 3)))
    (tmp_path / "cut.npz").write_bytes((tmp_path / "bad.npz").read_bytes()[:60])
    before = set(tmp_path.rglob("*"))
    argv = [a.format(c=folder / "c.obj", g=folder / "g") for a in argv]
    assert _rc(["animate", "--garment", str(folder / "g.obj"), "--prior-only", "--quiet", *argv]) == 2
    assert expected in _one_error_line(capsys)
    assert set(tmp_path.rglob("*")) == before


def test_animate_mesh_sequence_from_a_folder(scene, tmp_path, capsys):
    """--canonical + --targets folder: the frames are the single drapes, in file-name order."""
    from garsim import GarSim

    folder, meshes = scene
    bodies = tmp_path / "bodies"
    bodies.mkdir()
    c = np.asarray(meshes["c"].vertices)
    faces = np.asarray(meshes["c"].faces)
    for k in range(3):
        _write_obj(bodies / f"{k:02d}.obj", c + [0.0, 0.05 * k, 0.0], faces)
    out = tmp_path / "a.pc2"
    argv = ["--canonical", str(folder / "c.obj"), "--targets", str(bodies), "--garment", str(folder / "g.obj")]
    assert main(["animate", *argv, "--prior-only", "--quiet", "--out", str(out)]) == 0
    from garsim.export import read_pc2

    frames = read_pc2(out)[0]
    g = meshes["g"]
    last = GarSim.prior_only().drape((c, faces), (c + [0.0, 0.1, 0.0], faces), (g.vertices, g.faces))
    assert frames.shape == (3, len(g.vertices), 3)
    np.testing.assert_allclose(frames[-1], last, atol=1e-5)


def test_animate_carries_the_garments_uvs(scene, tmp_path, caplog):
    """Per-vertex UVs of the garment go to the animation (here the OBJ beside the PC2); seams are dropped there
    with a warning (the formats store one UV per vertex)."""
    from mesh_fixtures import obj_lists, seamed_obj_text

    folder, meshes = scene
    c, faces, g = np.asarray(meshes["c"].vertices), np.asarray(meshes["c"].faces), meshes["g"]
    bodies = _bodies(tmp_path / "bodies", c, faces, [("0.obj", 0.0), ("1.obj", 0.05)])
    uv = np.random.default_rng(0).random((len(g.vertices), 2)).round(6)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(g.vertices).tolist()]
    lines += [f"vt {a!r} {b!r}" for a, b in uv.tolist()] + [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in g.faces + 1]
    (tmp_path / "g.obj").write_text("\n".join(lines) + "\n")
    argv = ["animate", "--canonical", str(folder / "c.obj"), "--targets", str(bodies), "--prior-only", "--quiet"]
    assert main([*argv, "--garment", str(tmp_path / "g.obj"), "--out", str(tmp_path / "a.pc2")]) == 0
    np.testing.assert_allclose(obj_lists(tmp_path / "a.obj")[1], uv, atol=1e-7)
    text = seamed_obj_text(np.asarray(g.vertices), np.asarray(g.faces), normals=False)[0]
    (tmp_path / "seams.obj").write_text(text)
    with caplog.at_level("WARNING"):
        assert main([*argv, "--garment", str(tmp_path / "seams.obj"), "--out", str(tmp_path / "s.pc2")]) == 0
    assert "seams" in caplog.text and len(obj_lists(tmp_path / "s.obj")[1]) == 0


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["demo", "--out", "afile"], "is a file"),
        (["train", "--data", "d", "--out", "afile"], "is a file"),
        (["data", "generate", "--out", "afile/v2"], "is a file"),
        (["eval", "--data", "d", "--out", "results.txt"], "'.txt'"),
        (["bench", "--out", "afile/bench.json"], "is a file"),
        (["view"], "required: path"),
        (["drape", "--canonical", "a.obj"], "required"),
        (["nonsense"], "invalid choice"),
    ],
)
def test_output_and_usage_errors_come_first(argv, expected, tmp_path, capsys, monkeypatch):
    """Unwritable outputs and usage errors are refused before any work: one line, exit status 2, nothing written."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x")
    before = set(tmp_path.rglob("*"))
    assert _rc(argv) == 2
    assert expected in _one_error_line(capsys)
    assert set(tmp_path.rglob("*")) == before


def test_train_and_eval_the_deepsd_baseline_from_the_cli(tmp_path, capsys):
    """`garsim train --model deepsd` writes a model that `garsim eval` loads by its kind and scores beside the prior."""
    from pathlib import Path

    fixture = str(Path(__file__).parent / "fixtures" / "dataset_v2")
    run = tmp_path / "run"
    args = ["train", "--data", fixture, "--out", str(run), "--model", "deepsd", "--epochs", "1", "--val-every", "2"]
    assert main([*args, "--device", "cpu", "--quiet"]) == 0
    assert json.loads((run / "best" / "config.json").read_text())["model"] == "deepsd"
    assert main(["eval", "--data", fixture, "--model", str(run / "best"), "--splits", "test"]) == 0
    out = capsys.readouterr().out
    assert "deepsd" in out and "prior" in out and "nearest" in out


def test_train_on_some_families_only(tmp_path):
    """`garsim train --families` trains and validates on those families (the fixture's one skirt job: no validation)."""
    from pathlib import Path

    fixture = str(Path(__file__).parent / "fixtures" / "dataset_v2")
    run = tmp_path / "run"
    args = ["train", "--data", fixture, "--out", str(run), "--families", "skirt", "top", "--epochs", "1"]
    assert main([*args, "--val-every", "2", "--quiet"]) == 0
    assert json.loads((run / "sequences.json").read_text()) == {"train": ["train-00000"], "val": []}
    assert (run / "best" / "model.safetensors").exists()


def test_fine_tune_with_new_layers_and_the_fold_term(tmp_path, capsys):
    """`garsim train --init M --fabric-decoder-film --global-context --num-steps 6 --trainable ... --fold-weight`: the
    new layers and step are added to M's weights, only the named parameters are trained (the rest keep M's values),
    and the run records its options."""
    from pathlib import Path

    from garsim.model.garsim import GarSimModel
    from garsim.model.weights import WEIGHTS_FILE

    fixture = str(Path(__file__).parent / "fixtures" / "dataset_v2")
    base = tmp_path / "base"
    args = ["train", "--data", fixture, "--epochs", "1", "--val-every", "2", "--quiet"]
    assert main([*args, "--out", str(base), "--head", "displacement"]) == 0
    run = tmp_path / "tuned"
    tune = [
        "--init",
        str(base / "best"),
        "--fabric-decoder-film",
        "--global-context",
        "--target-surface",
        "--local-rotation",
        "--num-steps",
        "6",
        "--trainable",
        "processor.film",
        "processor.glob",
        "decoder.fabric_film",
        "surface_encoder",
    ]
    losses = ["--pair-weight", "5", "--fold-weight", "0.3", "--relative-l2", "0.03"]
    assert main([*args, "--out", str(run), *tune, *losses, "--lr", "1e-2"]) == 0
    before, after = GarSimModel.load(base / "best"), GarSimModel.load(run / "checkpoint")
    assert after.config.fabric_decoder_film and not before.config.fabric_decoder_film
    assert after.config.global_context and not before.config.global_context
    assert (before.config.num_steps, after.config.num_steps) == (5, 6)
    old, new = before.state_dict(), after.state_dict()
    assert all(torch.equal(v, new[k]) for k, v in old.items() if not k.startswith("processor.film"))
    assert any(not torch.equal(v, new[k]) for k, v in old.items() if k.startswith("processor.film"))
    assert new["decoder.fabric_film.weight"].abs().sum() > 0  # started at zero, trained
    assert new["processor.glob.0.mlp.2.weight"].abs().sum() > 0
    assert after.config.target_surface and new["surface_encoder.mlp.2.weight"].abs().sum() > 0
    assert after.config.local_rotation and not before.config.local_rotation
    cfg = json.loads((run / "train_config.json").read_text())
    assert cfg["trainable"] == ["processor.film", "processor.glob", "decoder.fabric_film", "surface_encoder"]
    assert cfg["losses"]["fold"] == 0.3 and cfg["losses"]["relative"] == 0.03
    deepsd = ["--out", str(tmp_path / "d"), "--model", "deepsd", "--global-context"]
    capsys.readouterr()
    assert main([*args, *deepsd]) == 2
    assert "option of GarSim" in _one_error_line(capsys)
    assert (run / "best" / WEIGHTS_FILE).exists()


def test_animate_records_model_and_smoothing_in_the_file(tmp_path, anny_body):
    """The animation says what made it: model, refinement and the temporal smoothing applied (USD layer data)."""
    import json

    from pxr import Sdf

    from garsim.garments.templates import make_garment
    from garsim.geometry.io import save_mesh

    g = make_garment("skirt", anny_body, target_vertices=300)
    save_mesh(tmp_path / "skirt.obj", g.vertices, g.faces)
    base = ["animate", "--garment", str(tmp_path / "skirt.obj"), "--motion", "walk", "--frames", "3", "--quiet"]
    assert main([*base, "--smoothing", "1.5", "--out", str(tmp_path / "a.usda")]) == 0
    meta = json.loads(Sdf.Layer.FindOrOpen(str(tmp_path / "a.usda")).customLayerData["garsim"])
    assert meta["model"] == "GarSim model + refine" and meta["temporal_smoothing_frames"] == 1.5
    assert main([*base, "--prior-only", "--out", str(tmp_path / "p.usda")]) == 0
    meta = json.loads(Sdf.Layer.FindOrOpen(str(tmp_path / "p.usda")).customLayerData["garsim"])
    assert meta["model"] == "skinning prior" and meta["temporal_smoothing_frames"] == 0.0
    assert main([*base, "--smoothing", "-1", "--out", str(tmp_path / "b.usda")]) == 2
    assert not (tmp_path / "b.usda").exists()


def test_eval_by_takes_keys_and_crossed_keys_and_refuses_others(capsys):
    args = build_parser().parse_args(["eval", "--data", "d", "--by", "family/construction", "canonical_pose"])
    assert args.by == ["family/construction", "canonical_pose"]
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["eval", "--data", "d", "--by", "family/colour"])
    assert exc.value.code == 2 and "cannot group by ['colour']" in capsys.readouterr().err


def test_eval_compare_scores_a_second_model_on_the_same_samples(tmp_path, capsys):
    """The shipped model against itself: no difference on any group, and the table is in the JSON; a --compare that
    is not a model folder is refused before anything runs."""
    from pathlib import Path

    from garsim.api import WEIGHTS_DIR

    fixture = str(Path(__file__).parent / "fixtures" / "dataset_v2")
    out = tmp_path / "r.json"
    argv = ["eval", "--data", fixture, "--splits", "ood", "--compare", str(WEIGHTS_DIR), "--out", str(out)]
    assert main(argv) == 0
    table = json.loads(out.read_text())["compare"]["ood"]
    assert table["all"]["frames"] == 4  # the runtime and torch forwards agree to well under a micrometre
    assert table["all"]["diff_mm"] == pytest.approx(0.0, abs=1e-3) and abs(table["trousers"]["diff_high_mm"]) < 1e-3
    assert "raw error against" in capsys.readouterr().out
    assert main(["eval", "--data", fixture, "--compare", str(tmp_path)]) == 2
    line = _one_error_line(capsys)
    assert "--compare" in line and "not a model folder" in line


def test_a_reader_that_goes_away_ends_the_command_quietly(monkeypatch, capsys):
    """`garsim data info DIR | head`: the closed pipe ends the command with status 1 and no error message."""
    import garsim.cli as cli

    def closed(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(cli, "cmd_data_info", closed)
    assert main(["data", "info", "anything"]) == 1
    assert capsys.readouterr().err == ""


def test_drape_writes_glb_in_metres_and_obj_in_the_input_units(scene, tmp_path):
    """The scene in centimetres (--units cm): the OBJ output is in centimetres like the input, the GLB in metres and
    Y up, as glTF requires (and `garsim animate` writes it)."""
    from garsim import GarSim
    from garsim.geometry.io import load_mesh
    from garsim.view import load_view_data

    folder, meshes = scene
    for name in "ctg":
        _write_obj(tmp_path / f"{name}.obj", np.asarray(meshes[name].vertices) * 100.0, meshes[name].faces)
    argv = ["drape", "--prior-only", "--units", "cm", "--garment", str(tmp_path / "g.obj")]
    argv += ["--canonical", str(tmp_path / "c.obj"), "--target", str(tmp_path / "t.obj")]
    metres = GarSim.prior_only().drape(meshes["c"], meshes["t"], meshes["g"])
    for ext, scale in ((".obj", 100.0), (".glb", 1.0)):
        assert main([*argv, "--out", str(tmp_path / f"out{ext}")]) == 0
        got = load_mesh(tmp_path / f"out{ext}", y_up=ext == ".glb")[0]
        np.testing.assert_allclose(got, metres * scale, atol=1e-4 * scale)
        # garsim view places either in metres, Z up: the OBJ says its unit in garsim's metadata line
        np.testing.assert_allclose(load_view_data(tmp_path / f"out{ext}").frames[0], metres, atol=1e-5)


def test_drape_reads_and_writes_usd_in_its_declared_axis_and_unit(scene, tmp_path):
    """Canonical, target and garment as USD stages in Y up and centimetres (declared), draped with the CLI's default
    Z-up metres: the same drape as from the OBJs; a USD output declares the run's axis and unit."""
    from pxr import Usd, UsdGeom

    from garsim import GarSim
    from garsim.export import export_animation
    from garsim.geometry.io import load_mesh, z_up_to_y_up
    from garsim.view import load_view_data

    folder, meshes = scene
    for name in "ctg":
        m = meshes[name]
        export_animation(
            tmp_path / f"{name}.usda", 100 * z_up_to_y_up(np.asarray(m.vertices))[None], m.faces, up="y", units="cm"
        )
    usd = ["--canonical", str(tmp_path / "c.usda"), "--target", str(tmp_path / "t.usda")]
    argv = ["drape", "--prior-only", "--garment", str(tmp_path / "g.usda"), *usd]
    expected = GarSim.prior_only().drape(meshes["c"], meshes["t"], meshes["g"])
    assert main([*argv, "--out", str(tmp_path / "d.obj")]) == 0
    np.testing.assert_allclose(load_mesh(tmp_path / "d.obj")[0], expected, atol=1e-5)
    assert main([*argv, "--units", "cm", "--out", str(tmp_path / "d.usdc")]) == 0  # the inputs restated in cm
    stage = Usd.Stage.Open(str(tmp_path / "d.usdc"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z and UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    np.testing.assert_allclose(load_mesh(tmp_path / "d.usdc")[0], 100 * expected, atol=1e-3)
    np.testing.assert_allclose(load_view_data(tmp_path / "d.usdc").frames[0], expected, atol=1e-5)


def test_drape_picks_the_body_of_a_multi_mesh_glb(scene, tmp_path, capsys):
    """A target GLB holding the body and its eyes: the mesh named Body is the target (as with --body-mesh Body);
    --body-mesh Eyes is refused with the meshes named."""
    from garsim.geometry.io import load_mesh

    folder, meshes = scene
    avatar = trimesh.Scene()
    avatar.add_geometry(meshes["t"], geom_name="Body", node_name="Body")
    avatar.add_geometry(trimesh.creation.icosphere(subdivisions=1, radius=0.01), geom_name="Eyes", node_name="Eyes")
    (tmp_path / "avatar.glb").write_bytes(avatar.export(file_type="glb"))
    argv = ["drape", "--prior-only", "--garment", str(folder / "g.obj"), "--canonical", str(folder / "c.obj")]
    assert main([*argv, "--target", str(folder / "t.obj"), "--out", str(tmp_path / "obj.obj")]) == 0
    for extra, name in (([], "a"), (["--body-mesh", "Body"], "b")):
        assert (
            main([*argv, "--target", str(tmp_path / "avatar.glb"), *extra, "--out", str(tmp_path / f"{name}.obj")]) == 0
        )
        np.testing.assert_allclose(
            load_mesh(tmp_path / f"{name}.obj")[0], load_mesh(tmp_path / "obj.obj")[0], atol=1e-6
        )
    capsys.readouterr()
    bad = [*argv, "--target", str(tmp_path / "avatar.glb"), "--body-mesh", "Eyes", "--out", str(tmp_path / "e.obj")]
    assert main(bad) == 2
    assert "it holds 2 meshes (Body, Eyes): pick the body with --body-mesh" in capsys.readouterr().err


def test_drape_picks_the_garment_of_a_glb_that_holds_the_avatar_too(scene, tmp_path, caplog):
    """A garment exported with its avatar (one GLB, two meshes): --garment-mesh Skirt drapes the skirt alone, like its
    own file; without the flag the file is draped as one garment, with a warning that names its meshes."""
    from garsim.geometry.io import load_mesh

    folder, meshes = scene
    outfit = trimesh.Scene()
    outfit.add_geometry(meshes["g"], geom_name="Skirt", node_name="Skirt")
    outfit.add_geometry(meshes["c"], geom_name="Avatar", node_name="Avatar")
    (tmp_path / "outfit.glb").write_bytes(outfit.export(file_type="glb"))
    argv = ["drape", "--prior-only", "--canonical", str(folder / "c.obj"), "--target", str(folder / "t.obj")]
    assert main([*argv, "--garment", str(folder / "g.obj"), "--out", str(tmp_path / "own.obj")]) == 0
    picked = [*argv, "--garment", str(tmp_path / "outfit.glb"), "--garment-mesh", "Skirt"]
    assert main([*picked, "--out", str(tmp_path / "picked.obj")]) == 0
    np.testing.assert_allclose(load_mesh(tmp_path / "picked.obj")[0], load_mesh(tmp_path / "own.obj")[0], atol=1e-6)
    with caplog.at_level("WARNING", logger="garsim"):
        main([*argv, "--garment", str(tmp_path / "outfit.glb"), "--out", str(tmp_path / "all.obj")])
    assert "it holds 2 meshes (Skirt, Avatar): pick the garment with --garment-mesh" in caplog.text
    assert (
        main([*argv, "--garment", str(folder / "g.obj"), "--garment-mesh", "Skirt", "--out", str(tmp_path / "x.obj")])
        == 2
    )
