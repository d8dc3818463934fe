import pytest
import torch

from garsim.model.config import GarSimConfig
from garsim.model.garsim import GarSimModel
from garsim.model.soup import average_models

TINY = {"latent": 16, "edge_latent": 8, "mlp_hidden": 16, "num_steps": 2}


def _saved(tmp_path, name, seed, **kw):
    torch.manual_seed(seed)
    model = GarSimModel(GarSimConfig(**{**TINY, **kw}))
    return model, model.save(tmp_path / name)


def test_the_average_is_each_tensor_weighted(tmp_path):
    a, da = _saved(tmp_path, "a", 0)
    b, db = _saved(tmp_path, "b", 1)
    soup = average_models([da, db], [0.25, 0.75]).state_dict()
    for k, v in a.state_dict().items():
        torch.testing.assert_close(soup[k], 0.25 * v + 0.75 * b.state_dict()[k])
    same = average_models([da, da], [0.5, 0.5]).state_dict()
    assert all(torch.equal(same[k], v) for k, v in a.state_dict().items())  # a model with itself is itself
    assert all(torch.equal(average_models([da, db], [1.0, 0.0]).state_dict()[k], v) for k, v in a.state_dict().items())


def test_models_that_cannot_be_averaged_are_refused(tmp_path):
    _, da = _saved(tmp_path, "a", 0)
    _, wide = _saved(tmp_path, "wide", 0, latent=32)
    with pytest.raises(ValueError, match="kind or config differs"):
        average_models([da, wide], [0.5, 0.5])
    with pytest.raises(ValueError, match="sum to 1"):
        average_models([da, da], [0.5, 0.6])
    with pytest.raises(ValueError, match="non-negative"):
        average_models([da, da], [1.5, -0.5])
    with pytest.raises(ValueError, match="two or more models"):
        average_models([da], [1.0])


def test_the_average_command_writes_a_loadable_model_and_refuses_a_lone_one(tmp_path, capsys):
    from garsim.cli import main
    from garsim.model.baselines import load_model

    a, da = _saved(tmp_path, "a", 0)
    b, db = _saved(tmp_path, "b", 1)
    assert main(["average", "--models", str(da), str(db), "--out", str(tmp_path / "soup")]) == 0
    soup = load_model(tmp_path / "soup").state_dict()  # checksum verified
    k = next(iter(soup))
    torch.testing.assert_close(soup[k], 0.5 * (a.state_dict()[k] + b.state_dict()[k]))
    assert main(["average", "--models", str(da), "--out", str(tmp_path / "lone")]) == 2
    assert "two or more models" in capsys.readouterr().err and not (tmp_path / "lone").exists()
