"""The shipped model: loads offline through the public API and beats the LBS prior on the fixture."""

from pathlib import Path

import numpy as np

from garsim import GarSim
from garsim.api import WEIGHTS_DIR
from garsim.data.store import DatasetStore
from garsim.eval.metrics import euclidean_error_mm

FIXTURE = Path(__file__).parent / "fixtures" / "dataset_v2"


def test_shipped_weights_are_small_safetensors():
    files = {p.name: p.stat().st_size for p in WEIGHTS_DIR.iterdir()}
    assert "model.safetensors" in files and "config.json" in files and "MODEL_CARD.md" in files
    assert files["model.safetensors"] < 20 * 2**20
    assert not any(name.endswith((".pt", ".pth", ".pkl", ".bin")) for name in files)  # nothing to unpickle


def test_shipped_model_beats_the_prior_on_the_fixture():
    sim = GarSim.pretrained()
    samples = [s for s in DatasetStore(FIXTURE).samples(resolution="low") if s.garment_type in ("skirt", "top")]
    preds = sim.model.predict(samples)
    model_err = np.mean([euclidean_error_mm(p, s.target) for p, s in zip(preds, samples)])
    prior_err = np.mean([euclidean_error_mm(s.prior, s.target) for s in samples])
    assert model_err < prior_err, (model_err, prior_err)


def test_pretrained_drape_through_the_public_api(anny_body):
    from garsim.bodies.poses import PoseSampler
    from garsim.garments.templates import make_garment

    c = anny_body.canonical()
    t = anny_body.pose(PoseSampler(seed=4).sample(1)[0])
    g = make_garment("skirt", anny_body, target_vertices=600)
    out = GarSim.pretrained().drape(
        (c.vertices, anny_body.faces), (t.vertices, anny_body.faces), (g.vertices, g.faces), fabric="denim"
    )
    assert out.shape == g.vertices.shape and np.isfinite(out).all()
    # the drape stays on the body: no vertex more than 5 cm farther from it than the prior's farthest
    # (a wide-legged pose carries the hem ~25-30 cm off the nearest body vertex already in the prior)
    from garsim.geometry.proximity import nearest_vertices

    prior = GarSim.prior_only().drape(
        (c.vertices, anny_body.faces), (t.vertices, anny_body.faces), (g.vertices, g.faces)
    )
    far = nearest_vertices(prior, t.vertices)[1].max()
    assert nearest_vertices(out, t.vertices)[1].max() < far + 0.05, far
