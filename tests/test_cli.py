import json

import numpy as np
import pytest
import trimesh

from garsim.cli import build_parser, main
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


@pytest.mark.slow
def test_demo(tmp_path, capsys):
    """The demo end to end on tiny settings: every family on both bodies, the grid, the walk animation."""
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
