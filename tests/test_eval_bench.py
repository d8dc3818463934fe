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
    assert r["api_wall_ms"] > 0 and r["api_new_pose_cpu_ms"] > 0 and r["api_new_pose_wall_ms"] > 0
    assert r["drape_peak_mb"] > 0  # forward_peak_mb: see test_forward_peak_counts_the_numpy_forward
    parts = r["prior_cpu_ms"] + r["graph_cpu_ms"] + r["forward_cpu_ms"]
    assert 0 < parts <= r["cpu_ms"] * 1.05 + 0.5  # the three stages make up (almost all of) the call
    assert torch.get_num_threads() == threads and model.training  # state restored
    assert "200 (actual" in format_bench(res)
    with pytest.raises(ValueError, match="repeats"):
        bench_inference(model, sizes=(200,), repeats=0, body=anny_body)


def test_forward_peak_counts_the_numpy_forward(anny_body, model):
    """With the numpy runtime (whose arrays tracemalloc sees; torch's tensors it does not) the forward's peak holds
    its two per-edge work buffers, (E, mlp_hidden) float32 each with E >= 2N directed edges, and grows by them with
    the garment."""
    from garsim.model.runtime import GarSimRuntime

    runtime = GarSimRuntime(model.config, {k: v.numpy() for k, v in model.state_dict().items()})
    res = bench_inference(runtime, sizes=(200, 800), repeats=1, body=anny_body)
    per_vertex_mb = 2 * 2 * model.config.mlp_hidden * 4 / 2**20
    for r in res.values():
        assert r["forward_peak_mb"] > r["vertices"] * per_vertex_mb
    small, large = res[200], res[800]
    assert large["forward_peak_mb"] - small["forward_peak_mb"] > (large["vertices"] - small["vertices"]) * per_vertex_mb


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


def test_bench_garment_past_the_template_limit(anny_body):
    """Above 30,000 vertices the template is subdivided: ~4x the vertices, pinned only between pinned ends."""
    from garsim.eval.bench import bench_garment
    from garsim.garments.templates import MAX_TARGET_VERTICES

    g = bench_garment("skirt", anny_body, MAX_TARGET_VERTICES + 4000)
    assert 0.85 * (MAX_TARGET_VERTICES + 4000) <= len(g.vertices) <= 1.2 * (MAX_TARGET_VERTICES + 4000)
    assert g.faces.max() == len(g.vertices) - 1 and g.params["subdivided"]
    assert 0 < g.pinned.sum() < 0.1 * len(g.vertices)


def test_peak_memory_counts_numpy():
    from garsim.eval.bench import peak_memory_mb

    assert 7.5 < peak_memory_mb(lambda: np.ones(2**20)) < 8.5  # 8 MiB of float64


def test_cli_bench_tiny_writes_json_table_and_plot(tmp_path, monkeypatch):
    """`garsim bench` on tiny garments: every new field present and positive, the .md table and the .png plot."""
    import json

    from garsim.api import WEIGHTS_DIR
    from garsim.cli import main
    from garsim.model.weights import WEIGHTS_FILE

    if not (WEIGHTS_DIR / WEIGHTS_FILE).exists():
        pytest.skip("no shipped weights")
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    out = tmp_path / "b.json"
    args = ["bench", "--sizes", "200", "300", "--repeats", "1", "--cold-max", "200", "--newton", "--newton-max", "0"]
    assert main([*args, "--out", str(out)]) == 0
    report = json.loads(out.read_text())
    m = report["machine"]
    assert m["cpu"] and m["logical_cores"] > 0 and m["usable_cores"] > 0 and m["torch_threads"] == 1
    assert m["thread_env"]["OMP_NUM_THREADS"] == "1" and m["python"] and m["numpy"] == np.__version__
    assert set(report["garsim"]) == {"200", "300"}
    for r in report["garsim"].values():
        for key in (
            "forward_cpu_ms",
            "reference_forward_cpu_ms",
            "api_cpu_ms",
            "api_wall_ms",
            "api_new_pose_cpu_ms",
            "api_new_pose_wall_ms",
            "sequence_fps_cpu",
            "forward_peak_mb",
            "drape_peak_mb",
        ):
            assert r[key] > 0, key
    assert set(report["cold"]) == {"200"}  # --cold-max 200
    cold = report["cold"]["200"]
    assert cold["vertices"] == report["garsim"]["200"]["vertices"]
    assert cold["cold_call_wall_ms"] > report["garsim"]["200"]["api_wall_ms"] and cold["cold_call_peak_rss_mb"] > 50
    assert report["ratios"]["200"]["cold_over_api"] > 1 and report["ratios"]["300"]["torch_over_numpy_forward"] > 0
    assert "cold_over_api" not in report["ratios"]["300"] and "paper_s" not in report["ratios"]["200"]
    table = out.with_suffix(".md").read_text()
    assert "newton" not in report  # --newton-max 0: no size simulated
    assert "garsim bench --sizes 200 300" in table and "--newton-max 0" in table and "Machine:" in table
    assert table.count("\n| ") >= 6  # two headers + two rows in each table
    png = out.with_suffix(".png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_ratios_and_markdown_with_paper_sizes_and_newton():
    from garsim.eval.bench import bench_ratios, format_bench_markdown

    row = {
        "vertices": 576,
        "forward_cpu_ms": 5.0,
        "cpu_ms": 10.0,
        "wall_ms": 20.0,
        "api_cpu_ms": 40.0,
        "api_wall_ms": 50.0,
        "sequence_fps_cpu": 30.0,
        "refine_correct_cpu_ms": 3.0,
    }
    report = {"garsim": {600: row}, "newton": {600: {"wall_ms": 5000.0}}}
    q = bench_ratios(report)[600]
    assert q == pytest.approx(
        {"paper_s": 0.1, "paper_over_api": 2.0, "paper_over_network": 5.0, "newton_over_api": 100}
    )
    md = format_bench_markdown({**report, "ratios": {600: q}})
    assert "| 576 |" in md and "2.0x" in md and "100x" in md and "| 5.0 |" in md
