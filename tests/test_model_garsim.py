"""GarSimModel: batching, permutation/translation/yaw equivariance, heads, save/load, speed."""

import dataclasses
import time

import numpy as np
import pytest
import torch
from model_fixtures import _body_weights, _posed, make_sample, ring_garment, rot_z, transform_sample

from garsim.data.sample import Sample
from garsim.geometry.skinning import lbs_prior, transfer_weights
from garsim.model.config import GarSimConfig
from garsim.model.garsim import GarSimModel
from garsim.model.graph import build_graph, collate


def _model(**kw) -> GarSimModel:
    torch.manual_seed(0)
    m = GarSimModel(GarSimConfig(**kw)).eval()
    with torch.no_grad():  # make the decoder output non-trivial so equivariance tests bite
        m.decoder.mlp[-1].weight.mul_(30.0)
        m.decoder.mlp[-1].bias[3:] = 0.5
    return m


@pytest.fixture(scope="module")
def samples():
    return make_sample(20, 6, "silk", 1, seed=1), make_sample(13, 5, "leather", 4, seed=2)


def test_batch_of_two_topologies_equals_single(samples):
    m = _model()
    a, b = samples
    with torch.no_grad():
        pa, pb = m(build_graph(a)), m(build_graph(b))
        pab = m(collate([build_graph(a), build_graph(b)]))
    assert pab.shape == (len(a.garment) + len(b.garment), 3)
    torch.testing.assert_close(pab[: len(a.garment)], pa, atol=1e-6, rtol=0)
    torch.testing.assert_close(pab[len(a.garment) :], pb, atol=1e-6, rtol=0)
    assert (pa - torch.from_numpy(a.prior)).norm(dim=1).mean() > 1e-3  # a real correction, not the prior


def test_permuting_vertices_permutes_output(samples):
    m = _model()
    s = samples[0]
    perm = np.random.default_rng(0).permutation(len(s.garment))
    inv = np.argsort(perm)
    ps = Sample(
        s.body_canonical,
        s.body_target,
        s.body_faces,
        s.garment[perm],
        inv[s.garment_faces],
        s.pinned[perm],
        s.prior[perm],
        s.fabric,
        s.garment_type,
        s.target[perm],
    )
    out, out_p = m.predict(s), m.predict(ps)
    np.testing.assert_allclose(out_p, out[perm], atol=2e-6)


@pytest.mark.parametrize(
    "options",
    [dict(head="direction_magnitude"), dict(head="displacement"), dict(head="position"), dict(local_rotation=True)],
    ids=["direction_magnitude", "displacement", "position", "local rotation"],
)
def test_translation_and_yaw_equivariance(samples, options):
    m = _model(**options)
    s = samples[0]
    rz, t = rot_z(0.9), np.array([0.35, -0.6, 0.2])
    out = m.predict(s).astype(np.float64)
    moved = m.predict(transform_sample(s, rz, t)).astype(np.float64)
    np.testing.assert_allclose(moved, out @ rz.T + t, atol=3e-5)
    shifted = m.predict(transform_sample(s, None, t)).astype(np.float64)
    np.testing.assert_allclose(shifted, out + t, atol=3e-6)


def test_without_body_frame_yaw_is_not_equivariant(samples):
    """What the body frame buys: with raw world vectors a yaw of the scene changes the prediction."""
    m = _model(canonicalize_yaw=False)
    s = samples[0]
    rz = rot_z(0.9)
    out = m.predict(s).astype(np.float64)
    moved = m.predict(transform_sample(s, rz)).astype(np.float64)
    assert np.abs(moved - out @ rz.T).max() > 1e-3


def test_decoder_direction_unit_magnitude_nonnegative(samples):
    m = _model()
    g = build_graph(samples[1])
    with torch.no_grad():
        pred, parts = m(g, return_parts=True)
    torch.testing.assert_close(parts["direction"].norm(dim=1), torch.ones(g.num_nodes))
    assert (parts["magnitude"] >= 0).all()
    disp = torch.einsum("ij,ni->nj", g.rot[0], parts["direction"] * parts["magnitude"][:, None])
    torch.testing.assert_close(pred, g.prior + disp)


def test_processor_aggregation_and_steps_are_configurable(samples):
    g = build_graph(samples[1])
    outs = {}
    for aggr in ("mean", "sum", "max"):
        m = _model(aggregation=aggr)
        with torch.no_grad():
            outs[aggr] = m(g)
        assert torch.isfinite(outs[aggr]).all()
    assert not torch.allclose(outs["mean"], outs["sum"])
    assert len(_model(num_steps=5).processor.steps) == 5
    assert len(_model(num_steps=5, share_weights=True).processor.steps) == 1


def test_save_load_reproduces_outputs_exactly(tmp_path, samples):
    m = _model(latent=32, edge_latent=16, head="displacement")
    m.save(tmp_path / "w")
    assert sorted(p.name for p in (tmp_path / "w").iterdir()) == ["config.json", "model.safetensors"]
    m2 = GarSimModel.load(tmp_path / "w")
    assert m2.config == m.config
    g = build_graph(samples[0])
    with torch.no_grad():
        assert torch.equal(m(g), m2(g))
    with pytest.raises(FileNotFoundError, match="model.safetensors"):
        GarSimModel.load(tmp_path)


def test_model_size_small():
    m = GarSimModel()
    size_mb = sum(p.numel() * p.element_size() for p in m.parameters()) / 1e6
    print(f"\nGarSim default: {m.num_parameters()} parameters, {size_mb:.2f} MB float32")
    assert size_mb < 20


def _end_to_end(model, can, tgt, garment, faces, pinned, weights, body_faces):
    """Meshes in memory -> predicted vertices: weight transfer + LBS prior + graph + forward."""
    w = transfer_weights(garment, can.vertices, weights)
    prior = lbs_prior(garment, w, can.transforms, tgt.transforms)
    s = Sample(can.vertices, tgt.vertices, body_faces, garment, faces, pinned, prior, "cotton", "skirt")
    return model.predict(s)


def test_speed_600_and_2400_vertices(samples):
    """Prints end-to-end timings (median of 7, one torch thread) as ratios to the paper's 0.1 s / 1.0 s.

    Wall time on a shared 2-core machine is dominated by other jobs, so CPU time of this process is
    reported too, and only CPU time is asserted (never slower than the paper).
    """
    torch.manual_seed(0)
    m = GarSimModel().eval()
    can, tgt = _posed(0), _posed(1)
    weights = _body_weights()
    body_faces = samples[0].body_faces
    report = []
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for (na, nd), paper in (((40, 15), 0.1), ((80, 30), 1.0)):
            g, f, pin = ring_garment(can.vertices, na, nd)
            _end_to_end(m, can, tgt, g, f, pin, weights, body_faces)  # warm up (body KD-tree cache)
            wall, cpu = [], []
            for _ in range(7):
                t0, c0 = time.perf_counter(), time.process_time()
                out = _end_to_end(m, can, tgt, g, f, pin, weights, body_faces)
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            w_med, c_med = float(np.median(wall)), float(np.median(cpu))
            assert out.shape == (na * nd, 3) and np.isfinite(out).all()
            report.append(
                f"{na * nd} v: wall {w_med * 1000:.1f} ms, cpu {c_med * 1000:.1f} ms "
                f"(paper {paper:.1f} s: {paper / c_med:.1f}x by cpu time)"
            )
            assert c_med < paper
    finally:
        torch.set_num_threads(threads)
    print("\nend-to-end speed (1 thread) | " + "; ".join(report))


def test_inference_path_equals_training_path(samples):
    """No-grad inference (CSR mean, in-place edge residual, inference_mode) = the autograd path."""
    m = _model()
    g = build_graph(samples[0])
    with torch.enable_grad():
        ref = m(g)
    with torch.inference_mode():
        fast = m(g)
    torch.testing.assert_close(fast, ref.detach(), atol=1e-6, rtol=0)
    np.testing.assert_array_equal(m.predict(samples[0]), fast.numpy())


def test_mean_aggregator_matches_brute_force():
    from garsim.model.processor import MeanAggregator

    rng = np.random.default_rng(3)
    recv = torch.from_numpy(rng.integers(0, 6, size=40))  # unsorted, node 6 has no edge
    vals = torch.from_numpy(rng.normal(size=(40, 3)).astype(np.float32))
    want = torch.zeros(7, 3)
    for v in range(6):
        sel = recv == v
        if sel.any():
            want[v] = vals[sel].mean(dim=0)
    agg = MeanAggregator(recv, 7)
    with torch.no_grad():
        torch.testing.assert_close(agg(vals), want, atol=1e-6, rtol=0)  # CSR product
    v2 = vals.clone().requires_grad_(True)
    out = agg(v2)  # training path (index_add) with a gradient: d mean / d value = 1/deg
    out.sum().backward()
    torch.testing.assert_close(out.detach(), want, atol=1e-6, rtol=0)
    deg = torch.bincount(recv, minlength=7).float()
    torch.testing.assert_close(v2.grad, (1.0 / deg[recv])[:, None].expand(-1, 3))


def test_widened_model_keeps_the_weights_and_starts_its_new_layer_at_zero():
    """``widened``: the same prediction with the decoder FiLM and the global context added (zero-initialised); a
    config that changes a weight's shape is refused."""

    model = GarSimModel(GarSimConfig(latent=16, edge_latent=8, mlp_hidden=16, num_steps=2)).eval()
    wide = model.widened(dataclasses.replace(model.config, fabric_decoder_film=True, global_context=True))
    assert wide.config.fabric_decoder_film and wide.decoder.fabric_film.weight.abs().sum() == 0
    assert len(wide.processor.glob) == 2 and all(g.mlp[-1].weight.abs().sum() == 0 for g in wide.processor.glob)
    sample = make_sample(fabric="denim")
    np.testing.assert_array_equal(wide.predict(sample), model.predict(sample))
    with pytest.raises(ValueError, match="no place"):
        model.widened(dataclasses.replace(model.config, latent=32))


def test_deepened_model_starts_as_it_was_and_its_new_steps_learn():
    """``deepened``: appended steps are the identity (the same prediction), their zeroed layers get gradients;
    fewer steps or shared weights are refused."""
    torch.manual_seed(0)
    model = GarSimModel(GarSimConfig(latent=16, edge_latent=8, mlp_hidden=16, num_steps=2, head="displacement"))
    model.eval()
    deep = model.deepened(4)
    sample = make_sample(fabric="denim")
    assert deep.config.num_steps == 4 and len(deep.processor.steps) == 4
    np.testing.assert_array_equal(deep.predict(sample), model.predict(sample))
    deep.train()
    graph = build_graph(sample, deep.config)
    opt = torch.optim.SGD(deep.parameters(), lr=0.1)
    for _ in range(2):  # first the new steps' output gains, then (through them) the rest of the steps
        opt.zero_grad()
        (deep(graph) - graph.target).square().sum().backward()
        assert all(s.node_update[-1].weight.grad.abs().sum() > 0 for s in deep.processor.steps[2:])
        opt.step()
    assert all(s.edge_update.rest[-1].weight.grad.abs().sum() > 0 for s in deep.processor.steps[2:])
    with pytest.raises(ValueError, match="append"):
        model.deepened(1)
    with pytest.raises(ValueError, match="shared"):
        GarSimModel(GarSimConfig(latent=16, edge_latent=8, mlp_hidden=16, share_weights=True)).deepened(8)


def test_graph_pool_takes_each_graphs_mean_and_max():
    """Hand-computed: graph 0 holds rows (1, 4) and (3, 0), graph 1 the row (-2, 5); one graph = the batch of one."""
    from garsim.model.processor import graph_pool

    node = torch.tensor([[1.0, 4.0], [-2.0, 5.0], [3.0, 0.0]])
    pooled = graph_pool(node, torch.tensor([0, 1, 0]), 2)
    torch.testing.assert_close(pooled, torch.tensor([[2.0, 2.0, 3.0, 4.0], [-2.0, 5.0, -2.0, 5.0]]))
    torch.testing.assert_close(graph_pool(node, None, 1), graph_pool(node, torch.zeros(3, dtype=torch.long), 1))


def test_global_context_sees_the_whole_garment_but_not_the_other_graphs_of_a_batch():
    """One message-passing step: a change of one vertex's prior reaches only its mesh 1-ring without the global
    context and every vertex with it; batched with another garment, each prediction equals its own."""

    from scipy.sparse.csgraph import shortest_path

    from garsim.geometry.mesh import unique_edges

    torch.manual_seed(0)
    cfg = GarSimConfig(latent=16, edge_latent=8, mlp_hidden=16, num_steps=1, head="displacement")
    plain = GarSimModel(cfg).eval()
    wide = plain.widened(dataclasses.replace(cfg, global_context=True))
    with torch.no_grad():
        wide.processor.glob[0].mlp[-1].weight.normal_(0.0, 0.3)
    a, b = make_sample(fabric="silk"), make_sample(fabric="leather", seed=3)
    poked = dataclasses.replace(a, prior=a.prior.copy())
    poked.prior[0] += np.float32(0.01)
    e = unique_edges(a.garment_faces)
    n = len(a.garment)
    adj = np.zeros((n, n))
    adj[e[:, 0], e[:, 1]] = adj[e[:, 1], e[:, 0]] = 1
    far = shortest_path(adj, unweighted=True, indices=0) >= 2
    assert far.sum() > n // 2
    moved = {
        name: np.abs(m.predict(poked) - m.predict(a)).max(axis=1) for name, m in (("plain", plain), ("wide", wide))
    }
    assert moved["plain"][far].max() == 0.0
    assert moved["wide"][far].min() > 0.0
    both = wide.predict([a, b])
    np.testing.assert_allclose(both[0], wide.predict(a), atol=1e-6)
    np.testing.assert_allclose(both[1], wide.predict(b), atol=1e-6)


def test_target_surface_starts_at_zero_and_learns():
    """A model widened by ``target_surface`` predicts as before, and its encoder's zeroed last layer gets a
    gradient."""

    torch.manual_seed(0)
    cfg = GarSimConfig(latent=16, edge_latent=8, mlp_hidden=16, num_steps=1, head="displacement")
    plain = GarSimModel(cfg).eval()
    wide = plain.widened(dataclasses.replace(cfg, target_surface=True))
    sample = make_sample(fabric="cotton")
    np.testing.assert_array_equal(wide.predict(sample), plain.predict(sample))
    wide.train()
    graph = build_graph(sample, wide.config)
    (wide(graph) - graph.target).square().sum().backward()
    assert wide.surface_encoder.mlp[-1].weight.grad.abs().sum() > 0


def test_local_rotation_turns_the_correction_with_a_rigidly_turned_prior(samples):
    """With ``local_rotation`` and the prior the template turned rigidly by R (and moved), every vertex's correction
    is R times the one the same weights give without it; at rest (prior = template) the two models agree."""
    plain = _model(head="displacement")
    turned = plain.widened(dataclasses.replace(plain.config, local_rotation=True)).eval()
    s = samples[0]
    r = rot_z(0.7) @ np.array([[1.0, 0.0, 0.0], [0.0, np.cos(0.5), -np.sin(0.5)], [0.0, np.sin(0.5), np.cos(0.5)]])
    moved = dataclasses.replace(s, prior=(s.garment.astype(np.float64) @ r.T + [0.1, -0.2, 0.05]).astype(np.float32))
    np.testing.assert_allclose(
        build_graph(moved, turned.config).local_rot.numpy(),
        np.broadcast_to(r, (len(s.garment), 3, 3)),
        atol=2e-5,
    )
    base = moved.prior.astype(np.float64)
    correction = plain.predict(moved).astype(np.float64) - base
    assert np.abs(correction).max() > 1e-3
    np.testing.assert_allclose(turned.predict(moved) - base, correction @ r.T, atol=2e-5)
    rest = dataclasses.replace(s, prior=s.garment.copy())
    np.testing.assert_allclose(turned.predict(rest), plain.predict(rest), atol=1e-6)
