"""GarSimConfig: JSON round trip and input validation."""

import pytest

from garsim.model.config import GarSimConfig


def test_json_round_trip(tmp_path):
    cfg = GarSimConfig(latent=48, semantic_grid=(6, 3, 10), head="displacement", num_steps=3)
    assert GarSimConfig.from_json(cfg.to_json()) == cfg
    cfg.to_json(tmp_path / "c.json")
    back = GarSimConfig.from_json(tmp_path / "c.json")
    assert back == cfg and back.semantic_grid == (6, 3, 10)
    assert back.semantic_input_dim == 6 * 3 * 10


def test_bad_values_are_rejected():
    with pytest.raises(ValueError, match="unknown head"):
        GarSimConfig(head="velocity")
    with pytest.raises(ValueError, match="num_body_vertices"):
        GarSimConfig(semantic="vertex")
    with pytest.raises(ValueError, match="unknown GarSimConfig keys"):
        GarSimConfig.from_dict({"latnet": 3})
    assert GarSimConfig(semantic="vertex", num_body_vertices=13718).semantic_input_dim == 13718
