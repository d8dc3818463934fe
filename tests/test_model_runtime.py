"""The numpy runtime against the torch model: same weights, same output, for every architecture option."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from garsim.model.config import GarSimConfig
from garsim.model.garsim import GarSimModel
from garsim.model.runtime import GarSimRuntime
from garsim.model.weights import WeightsError

sys.path.insert(0, str(Path(__file__).parent))
from model_fixtures import make_sample  # noqa: E402

WEIGHTS = Path(__file__).parents[1] / "garsim" / "weights"

SMALL = dict(latent=16, edge_latent=8, mlp_hidden=16, geo_hidden=8, geo_out=8, semantic_dim=8, num_steps=2)
CONFIGS = {
    "paper head, silu, film": dict(head="direction_magnitude", activation="silu"),
    "displacement, decoder film": dict(head="displacement", fabric_decoder_film=True),
    "displacement, relu, edge norm": dict(head="displacement", activation="relu", edge_layer_norm=True),
    "position, gelu, two layers": dict(head="position", activation="gelu", mlp_layers=2),
    "shared weights, no film, no residual": dict(share_weights=True, fabric_film=False, residual=False),
    "displacement, global context": dict(head="displacement", global_context=True),
    "target surface": dict(target_surface=True),
    "displacement, local rotation": dict(head="displacement", local_rotation=True),
    "no message passing, no norm": dict(num_steps=0, layer_norm=False),
}


def _perturbed(config: GarSimConfig, seed: int = 0) -> GarSimModel:
    """A model whose every weight (zero-initialised FiLM and gains included) is random, so every path counts."""
    torch.manual_seed(seed)
    model = GarSimModel(config).eval()
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.2 * torch.randn_like(p))
    return model


@pytest.mark.parametrize("chunk", [None, 7], ids=["one chunk", "chunks of 7 edges"])
@pytest.mark.parametrize("options", CONFIGS.values(), ids=CONFIGS.keys())
def test_runtime_matches_torch(options: dict, chunk: int | None, tmp_path: Path, monkeypatch) -> None:
    if chunk is not None:  # the message passing runs over the edges in chunks: several of them, a short last one
        monkeypatch.setattr("garsim.model.runtime.EDGE_CHUNK", chunk)
    model = _perturbed(GarSimConfig(**{**SMALL, **options}))
    runtime = GarSimRuntime.load(model.save(tmp_path / "m"))
    sample = make_sample(n_around=16, n_down=6, fabric="denim")
    expected = model.predict(sample)
    got = runtime.predict(sample)
    assert got.dtype == np.float32 and got.shape == expected.shape
    assert np.abs(got - expected).max() < 1e-5
    assert np.abs(expected - sample.prior).max() > 1e-3  # the network did move the garment: a real comparison


def test_runtime_matches_shipped_weights() -> None:
    sample = make_sample(fabric="leather", pose_id=2)
    expected = GarSimModel.load(WEIGHTS).predict(sample)
    got = GarSimRuntime.load(WEIGHTS).predict(sample)
    assert np.abs(got - expected).max() < 1e-5


def test_runtime_batch_predict_is_per_sample() -> None:
    runtime = GarSimRuntime.load(WEIGHTS)
    a, b = make_sample(fabric="silk"), make_sample(n_around=20, fabric="denim", pose_id=3)
    both = runtime.predict([a, b])
    assert np.array_equal(both[0], runtime.predict(a)) and np.array_equal(both[1], runtime.predict(b))


def test_runtime_refuses_what_it_does_not_implement(tmp_path: Path) -> None:
    d = GarSimModel(GarSimConfig(**SMALL, aggregation="max")).save(tmp_path / "max")
    with pytest.raises(ValueError, match="mean aggregation"):
        GarSimRuntime.load(d)


def test_runtime_load_checks_like_torch(tmp_path: Path) -> None:
    d = GarSimModel(GarSimConfig(**SMALL)).save(tmp_path / "m")
    cfg = json.loads((d / "config.json").read_text())
    (d / "config.json").write_text(json.dumps({**cfg, "weights_sha256": "0" * 64}))
    with pytest.raises(WeightsError, match="checksum mismatch"):
        GarSimRuntime.load(d)
    (d / "config.json").write_text(json.dumps({**cfg, "model": "deepsd"}))
    with pytest.raises(WeightsError, match="holds a 'deepsd' model"):
        GarSimRuntime.load(d)


def test_drape_path_imports_neither_torch_nor_trimesh(tmp_path: Path) -> None:
    """A cold `garsim drape` of OBJ files runs on the numpy runtime: torch (~1.3 s to import), torch_geometric
    (~2 s) and trimesh (~0.5 s) stay unloaded."""
    import subprocess

    from garsim.geometry.io import save_mesh

    sample = make_sample(fabric="silk")
    save_mesh(tmp_path / "a.obj", sample.body_canonical, sample.body_faces)
    save_mesh(tmp_path / "b.obj", sample.body_target, sample.body_faces)
    save_mesh(tmp_path / "g.obj", sample.garment, sample.garment_faces)
    code = (
        "import sys; from garsim.cli import main; "
        "rc = main(['drape', '--canonical', 'a.obj', '--target', 'b.obj', '--garment', 'g.obj', '--out', 'd.obj']); "
        "print(sorted(m for m in ('torch', 'torch_geometric', 'trimesh') if m in sys.modules), rc)"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.stdout.strip().splitlines()[-1] == "[] 0", out.stderr[-2000:]
    assert (tmp_path / "d.obj").exists()


def test_runtime_reuses_pose_free_features_across_poses() -> None:
    """A second pose of the same garment reuses the cached pose-free features and gives what a cold call gives."""
    import dataclasses

    from garsim.geometry.cache import clear_all

    runtime = GarSimRuntime.load(WEIGHTS)
    a = make_sample(fabric="cotton", pose_id=1)
    b = dataclasses.replace(a, body_target=make_sample(fabric="cotton", pose_id=3).body_target)
    b = dataclasses.replace(b, prior=make_sample(fabric="cotton", pose_id=3).prior)
    runtime.predict(a)
    warm = runtime.predict(b)
    clear_all()
    cold = runtime.predict(b)
    np.testing.assert_array_equal(warm, cold)
    assert np.abs(warm - runtime.predict(a)).max() > 1e-3  # the pose did change the output
