import json

import numpy as np
import pytest
import trimesh

from garsim.cli import build_parser, main
from garsim.data.store import DatasetStore


def test_data_info_and_verify(tmp_path, capsys):
    from test_data_store import make_record

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
    rc = main(["drape", "--canonical", str(tmp_path / "c.obj"), "--target", str(tmp_path / "t.obj"),
               "--garment", str(tmp_path / "g.obj"), "--fabric", "silk", "--out", str(out), "--prior-only",
               "--png", str(tmp_path / "out.png")])
    assert rc == 0 and (tmp_path / "out.png").stat().st_size > 1000
    draped = trimesh.load(out, process=False)
    np.testing.assert_allclose(draped.vertices, np.asarray(garment.vertices) + [0, 0, 0.2], atol=1e-5)


def test_errors_are_reported_not_raised(tmp_path, capsys):
    rc = main(["drape", "--canonical", str(tmp_path / "missing.obj"), "--target", "x.obj", "--garment", "y.obj",
               "--out", str(tmp_path / "o.obj"), "--prior-only"])
    assert rc == 2 and "no such file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        build_parser().parse_args(["data", "generate", "--out", "x", "--shard", "3/2"])


@pytest.mark.slow
def test_demo(tmp_path):
    assert main(["demo", "--out", str(tmp_path), "--vertices", "600"]) == 0
    assert (tmp_path / "demo_grid.png").exists() and len(list(tmp_path.glob("*.obj"))) == 12
