"""Baselines: the LBS prior and the ablation variants of Sec. 4.2."""

import pytest
import torch
from model_fixtures import make_sample

from garsim.model.baselines import ABLATIONS, PriorBaseline, ablation_config, make_ablation
from garsim.model.inputs import build_graph


def test_prior_baseline_returns_prior():
    g = build_graph(make_sample(12, 4))
    assert torch.equal(PriorBaseline()(g), g.prior)


def test_ablation_variants():
    assert ablation_config("displacement").head == "displacement"
    assert ablation_config("position").head == "position"
    assert ablation_config("no_message_passing").num_steps == 0
    assert ablation_config("full").head == "direction_magnitude"
    g = build_graph(make_sample(12, 4))
    for name in ABLATIONS:
        model = make_ablation(name)
        with torch.no_grad():
            out = model(g)
            assert out.shape == g.pos.shape and torch.isfinite(out).all()
            last = model.decoder.mlp[-1]  # a silent decoder: each head's base is what comes out
            last.weight.zero_()
            last.bias.zero_()
            out = model(g)
        head = model.config.head
        if head == "displacement":
            torch.testing.assert_close(out, g.prior)
        elif head == "position":
            torch.testing.assert_close(out, g.anchor)
        else:  # direction x magnitude with a zero direction: the prior again
            torch.testing.assert_close(out, g.prior)
    with pytest.raises(ValueError, match="unknown ablation"):
        ablation_config("gnn")
