"""Baselines: the LBS prior, the nearest-vertex client, the DeePSD-style network and the ablation variants."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch
from model_fixtures import make_sample

from garsim.data.sample import Sample
from garsim.data.store import DatasetStore
from garsim.model.baselines import (
    ABLATIONS,
    DeePSDBaseline,
    PriorBaseline,
    ablation_config,
    deepsd_graph,
    load_model,
    make_ablation,
    nearest_vertex_drape,
)
from garsim.model.config import GarSimConfig
from garsim.model.garsim import GarSimModel, WeightsError
from garsim.model.graph import build_graph


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


FIXTURE = Path(__file__).parent / "fixtures" / "dataset_v2"


@pytest.fixture(scope="module")
def fixture_samples():
    return DatasetStore(FIXTURE).samples(resolution="low")[:3]


def test_nearest_vertex_drape_moves_each_vertex_with_its_nearest_body_vertex():
    """Two body vertices moving by (0, 0, 1 cm) and (2 cm, 0, 0); garment vertices near one or the other."""
    body = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], np.float32)
    moved = body + np.array([[0.0, 0.0, 0.01], [0.02, 0.0, 0.0], [0.0, 0.0, 0.0]], np.float32)
    garment = np.array([[0.1, 0.0, 0.1], [0.9, 0.1, 0.0], [1.2, 0.0, 0.0]], np.float32)
    sample = Sample(
        body, moved, np.array([[0, 1, 2]]), garment, np.array([[0, 1, 2]]), np.zeros(3, bool), garment, "cotton", "top"
    )
    expected = garment + np.array([[0.0, 0.0, 0.01], [0.02, 0.0, 0.0], [0.02, 0.0, 0.0]], np.float32)
    np.testing.assert_allclose(nearest_vertex_drape(sample), expected, atol=1e-7)


def test_untrained_deepsd_is_the_mesh_pair_lbs_prior(fixture_samples):
    """Both heads start at zero: Anny's bones fitted from the meshes skin the template with the body's weights,
    which is the API's mesh-pair prior (up to the blend-weight floor) and within ~1 mm of the stored prior."""
    from garsim.bodies.prior import mesh_pair_prior

    model = DeePSDBaseline(GarSimConfig(latent=16)).eval()
    batched = model.predict(fixture_samples)
    for s, pred in zip(fixture_samples, batched):
        lbs = mesh_pair_prior(s.garment, s.body_canonical, s.body_target, s.body_faces)
        assert np.abs(pred - lbs).max() < 5e-4
        assert np.linalg.norm(pred - s.prior, axis=1).mean() < 0.002
    np.testing.assert_allclose(model.predict(fixture_samples[1]), batched[1], atol=1e-5)  # batching changes nothing


def test_deepsd_save_load_and_the_model_kind(tmp_path, fixture_samples):
    torch.manual_seed(0)
    model = DeePSDBaseline(GarSimConfig(latent=16)).eval()
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.01 * torch.randn_like(p))  # trained-looking weights: the output leaves the prior
    d = model.save(tmp_path / "w")
    back = DeePSDBaseline.load(d)
    np.testing.assert_array_equal(back.predict(fixture_samples[0]), model.predict(fixture_samples[0]))
    with pytest.raises(WeightsError, match="holds a 'deepsd' model, not 'garsim'"):
        GarSimModel.load(d)
    garsim_dir = GarSimModel(GarSimConfig(latent=16)).save(tmp_path / "g")
    with pytest.raises(WeightsError, match="holds a 'garsim' model, not 'deepsd'"):
        DeePSDBaseline.load(garsim_dir)
    assert type(load_model(d)) is DeePSDBaseline and type(load_model(garsim_dir)) is GarSimModel


def test_deepsd_needs_anny_topology():
    s = make_sample(12, 4)
    other = dataclasses.replace(s, body_faces=s.body_faces[::-1].copy())
    with pytest.raises(ValueError, match="Anny's topology"):
        deepsd_graph(other)
