"""bench_inference: end-to-end timing on Anny + a template garment (tiny size here), state restored."""

import numpy as np
import pytest
import torch

from garsim.bodies.prior import garment_prior
from garsim.data.sample import Sample
from garsim.eval.bench import DEFAULT_POSE, bench_inference, drape_once, format_bench
from garsim.garments.templates import make_garment
from garsim.model.config import GarSimConfig
from garsim.model.garsim import GarSimModel


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return GarSimModel(GarSimConfig())


def test_bench_inference_tiny(anny_body, model):
    model.train()
    threads = torch.get_num_threads()
    res = bench_inference(model, sizes=(200,), repeats=2, body=anny_body)
    assert list(res) == [200]
    r = res[200]
    assert abs(r["vertices"] - 200) <= 0.2 * 200  # the template hits its vertex budget within 20 %
    assert r["repeats"] == 2 and r["cpu_ms"] > 0 and r["wall_ms"] > 0 and r["first_call_wall_ms"] > 0
    assert r["api_cpu_ms"] > 0 and r["sequence_fps_cpu"] > 0 and r["sequence_fps_wall"] > 0
    assert r["refine_correct_cpu_ms"] > 0 and r["refine_valid_cpu_ms"] > 0
    assert r["pose_seq_cpu_ms"] > 0 and r["pose_seq_wall_ms"] > 0
    parts = r["prior_cpu_ms"] + r["graph_cpu_ms"] + r["forward_cpu_ms"]
    assert 0 < parts <= r["cpu_ms"] * 1.05 + 0.5  # the three stages make up (almost all of) the call
    assert torch.get_num_threads() == threads and model.training  # state restored
    assert "200 (actual" in format_bench(res)
    with pytest.raises(ValueError, match="repeats"):
        bench_inference(model, sizes=(200,), repeats=0, body=anny_body)


def test_drape_once_matches_predict(anny_body, model):
    """The timed path is the model's own inference path: same vertices as GarSimModel.predict."""
    model.eval()
    can = anny_body.canonical()
    tgt = anny_body.pose({**anny_body.t_pose(), **{k: np.asarray(v) for k, v in DEFAULT_POSE.items()}})
    g = make_garment("skirt", anny_body, target_vertices=200)
    pred, parts = drape_once(model, anny_body, can, tgt, g.vertices, g.faces, g.pinned)
    prior = garment_prior(anny_body, can, tgt, g.vertices)
    s = Sample(can.vertices, tgt.vertices, anny_body.faces, g.vertices, g.faces, g.pinned, prior, "cotton", "skirt")
    np.testing.assert_array_equal(pred, model.predict(s))
    assert set(parts) == {"prior_cpu_ms", "graph_cpu_ms", "forward_cpu_ms"}


def test_bench_newton_tiny(anny_body):
    pytest.importorskip("newton")
    from garsim.eval.bench import bench_newton

    res = bench_newton((200,), motion_frames=4, body=anny_body)
    r = res[200]
    assert r["wall_ms"] > 0 and r["cpu_ms"] > 0 and r["frames"] >= 4
