"""Saved weights prove they are intact: sha256 in config.json, one-line WeightsError for every defect."""

import json
import logging
from pathlib import Path

import pytest
import torch

from garsim.data.store import DatasetStore
from garsim.model.config import GarSimConfig
from garsim.model.garsim import CHECKSUM_KEY, CONFIG_FILE, WEIGHTS_FILE, GarSimModel, WeightsError
from garsim.model.graph import build_graph

FIXTURE = Path(__file__).parent / "fixtures" / "dataset_v2"
SMALL = {
    "latent": 16,
    "edge_latent": 8,
    "mlp_hidden": 16,
    "geo_hidden": 8,
    "geo_out": 8,
    "semantic_dim": 8,
    "num_steps": 2,
}


@pytest.fixture()
def saved(tmp_path) -> tuple[GarSimModel, Path]:
    torch.manual_seed(0)
    model = GarSimModel(GarSimConfig(**SMALL)).eval()
    return model, model.save(tmp_path / "w")


def _one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg, msg
    return msg


def test_round_trip_gives_identical_outputs(saved):
    model, d = saved
    config = json.loads((d / CONFIG_FILE).read_text())
    assert len(config[CHECKSUM_KEY]) == 64
    assert GarSimConfig.from_dict({k: v for k, v in config.items() if k != CHECKSUM_KEY}) == model.config
    back = GarSimModel.load(d)
    assert back.config == model.config
    sample = next(iter(DatasetStore(FIXTURE).samples(resolution="low")))
    g = build_graph(sample, model.config)
    with torch.no_grad():
        assert torch.equal(model(g), back(g))


def test_flipped_bytes_fail_the_checksum(saved):
    _, d = saved
    path = d / WEIGHTS_FILE
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 100] = bytes(b ^ 0xFF for b in data[mid : mid + 100])
    path.write_bytes(bytes(data))
    with pytest.raises(WeightsError, match="checksum") as exc:
        GarSimModel.load(d)
    assert WEIGHTS_FILE in _one_line(exc)


def test_truncated_weights_are_refused(saved):
    _, d = saved
    path = d / WEIGHTS_FILE
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(WeightsError, match="truncated") as exc:
        GarSimModel.load(d)
    assert WEIGHTS_FILE in _one_line(exc)


def test_truncated_weights_without_checksum_are_refused(saved):
    _, d = saved
    config = json.loads((d / CONFIG_FILE).read_text())
    del config[CHECKSUM_KEY]
    (d / CONFIG_FILE).write_text(json.dumps(config))
    path = d / WEIGHTS_FILE
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(WeightsError, match="truncated") as exc:
        GarSimModel.load(d)
    assert WEIGHTS_FILE in _one_line(exc)


@pytest.mark.parametrize(
    "edit",
    [
        lambda text, c: text[: len(text) // 2],  # torn JSON
        lambda text, c: "[1, 2, 3]",  # not an object
        lambda text, c: json.dumps({**c, "no_such_key": 1}),  # unknown key
        lambda text, c: json.dumps({**c, "latent": "sixteen"}),  # wrong type
        lambda text, c: json.dumps({**c, "residual": 1}),  # wrong type
        lambda text, c: json.dumps({**c, "semantic_grid": [8, 4]}),  # invalid value
        lambda text, c: json.dumps({**c, CHECKSUM_KEY: 5}),  # malformed checksum
    ],
)
def test_malformed_config_names_config_json(saved, edit):
    _, d = saved
    text = (d / CONFIG_FILE).read_text()
    (d / CONFIG_FILE).write_text(edit(text, json.loads(text)))
    with pytest.raises(WeightsError, match="config") as exc:
        GarSimModel.load(d)
    assert CONFIG_FILE in _one_line(exc)


def test_config_that_does_not_fit_the_weights(saved):
    _, d = saved
    config = json.loads((d / CONFIG_FILE).read_text())
    (d / CONFIG_FILE).write_text(json.dumps({**config, "latent": 24}))  # checksum still matches the weights
    with pytest.raises(WeightsError, match="do not match") as exc:
        GarSimModel.load(d)
    assert WEIGHTS_FILE in _one_line(exc)
    (d / CONFIG_FILE).write_text(json.dumps({**config, "num_steps": 3}))  # an extra processor step
    with pytest.raises(WeightsError, match="missing"):
        GarSimModel.load(d)


def test_config_without_checksum_loads_with_a_warning(saved, caplog):
    model, d = saved
    config = json.loads((d / CONFIG_FILE).read_text())
    del config[CHECKSUM_KEY]
    (d / CONFIG_FILE).write_text(json.dumps(config))
    assert GarSimConfig.from_json(d / CONFIG_FILE) == model.config  # a plain config file still reads
    with caplog.at_level(logging.WARNING, logger="garsim.model.garsim"):
        back = GarSimModel.load(d)
    assert back.config == model.config
    assert any(CHECKSUM_KEY in r.getMessage() for r in caplog.records)
