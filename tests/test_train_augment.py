"""Remeshing augmentation (garsim.train.augment): fewer vertices, the same surfaces, deterministic, trainable."""

import numpy as np
import pytest
import torch
from model_fixtures import make_sample

from garsim.model.config import GarSimConfig
from garsim.model.graph import build_graph, collate
from garsim.train.augment import RemeshAugmented, remesh_augmented, remesh_sample, remesh_variant
from garsim.train.losses import LossWeights, garsim_loss
from garsim.train.trainer import GraphDataset, TrainConfig

SMALL = GarSimConfig(latent=32, edge_latent=16, mlp_hidden=32, num_steps=2, head="displacement")


@pytest.fixture(scope="module")
def full():
    """Two 'full-resolution' ring skirts (384 and 320 vertices) with a smooth prior and truth."""
    return [
        make_sample(n_around=32, n_down=12, fabric="silk", pose_id=1, seed=3, name="a@0"),
        make_sample(n_around=32, n_down=10, fabric="denim", pose_id=2, seed=4, name="b@0"),
    ]


def _on_surface(values_coarse, values_full, faces_full, tol=1e-5):
    """Every coarse row is a convex combination of one full triangle's rows (the closest point on that triangle)."""
    tri = values_full[faces_full].astype(np.float64)  # (F, 3, 3)
    for p in values_coarse.astype(np.float64):
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        # least-squares barycentric coordinates of p in every triangle's plane, clamped into the triangle
        m = np.stack([b - a, c - a], axis=-1)  # (F, 3, 2)
        sol = np.einsum("fij,fj->fi", np.linalg.pinv(m), p - a)  # (F, 2)
        u, v = np.clip(sol[:, 0], 0, 1), np.clip(sol[:, 1], 0, 1)
        s = np.maximum(u + v, 1.0)
        q = a + (u / s)[:, None] * (b - a) + (v / s)[:, None] * (c - a)
        assert np.linalg.norm(q - p, axis=1).min() < tol


def test_variant_is_coarser_and_carries_truth_and_prior(full):
    src = full[0]
    low, mapping = remesh_sample(src, 0.4)
    n, m = len(src.garment), len(low.garment)
    assert m < n and low.pinned.shape == (m,) and low.pinned.any()
    assert low.garment_faces.max() == m - 1 and low.body_target is src.body_target
    # by hand: the carried values are the barycentric blend of the original triangle's values
    for i in (0, m // 2, m - 1):
        tri, w = mapping.triangles[i], mapping.weights[i]
        assert w.sum() == pytest.approx(1.0) and (w >= 0).all()
        for coarse, orig in ((low.target, src.target), (low.prior, src.prior), (low.garment, src.garment)):
            expect = w[0] * orig[tri[0]].astype(np.float64) + w[1] * orig[tri[1]] + w[2] * orig[tri[2]]
            np.testing.assert_allclose(coarse[i], expect, atol=1e-6)
    # and they lie on the original target / prior surfaces
    _on_surface(low.target, src.target, src.garment_faces)
    _on_surface(low.prior, src.prior, src.garment_faces)
    # pins come from the nearest original vertex of the carrying triangle
    nearest = mapping.triangles[np.arange(m), np.argmax(mapping.weights, axis=1)]
    np.testing.assert_array_equal(low.pinned, src.pinned[nearest])


def test_variants_are_deterministic_sized_and_order_free(full):
    a = remesh_variant(full[0], 1, seed=7, min_vertices=100)
    b = remesh_variant(full[0], 1, seed=7, min_vertices=100)
    np.testing.assert_array_equal(a.garment, b.garment)
    np.testing.assert_array_equal(a.garment_faces, b.garment_faces)
    np.testing.assert_array_equal(a.target, b.target)
    np.testing.assert_array_equal(a.prior, b.prior)
    assert a.meta["name"] == "a@0~remesh1" and a.meta["remesh"]["source_vertices"] == 384
    sizes = {len(remesh_variant(full[0], v, seed=7, min_vertices=100).garment) for v in range(6)}
    assert len(sizes) > 1 and max(sizes) < 0.8 * 384 and min(sizes) >= 0.2 * 384  # random, coarser than full
    # the list order does not change a variant; another seed does
    fwd = RemeshAugmented(full, full, copies=2, seed=7)
    rev = RemeshAugmented(full[::-1], full[::-1], copies=2, seed=7)
    assert len(fwd) == 6
    np.testing.assert_array_equal(fwd[2].garment, rev[4].garment)  # a@0 variant 0 in both
    other = RemeshAugmented(full, full, copies=2, seed=8)
    assert any(len(other[i].garment) != len(fwd[i].garment) for i in range(2, 6))
    np.testing.assert_array_equal(fwd[3].garment, fwd[3].garment)  # rebuilt alike on every access
    np.testing.assert_array_equal(fwd[3].target, RemeshAugmented(full, full, copies=2, seed=7)[3].target)


def test_graph_dataset_builds_each_variant_once(full, monkeypatch):
    """The graph cache is the only copy: indexing the dataset again does not rebuild a variant."""
    import garsim.train.augment as augment

    built = []

    def counted(sample, variant, *args):
        built.append((sample.meta["name"], variant))
        return remesh_variant(sample, variant, *args)

    monkeypatch.setattr(augment, "remesh_variant", counted)
    data = GraphDataset(remesh_augmented(full, full, copies=2, seed=1), SMALL, make_graph=build_graph)
    first = [data[i] for i in range(len(data))]
    assert all(data[i] is graph for i, graph in enumerate(first))
    assert sorted(built) == [("a@0", 0), ("a@0", 1), ("b@0", 0), ("b@0", 1)]


def test_remesh_augmented_pairs_levels_by_name(full):
    coarse = [remesh_sample(s, 0.3)[0] for s in full]  # a stand-in for the stored low level, same names
    aug = remesh_augmented(coarse, full, copies=3, seed=0)
    assert len(aug) == 2 + 2 * 3 and aug[0] is coarse[0] and aug[1] is coarse[1]
    assert aug.min_vertices == [len(c.garment) for c in coarse]
    assert remesh_augmented(coarse, full, copies=0) is coarse
    with pytest.raises(ValueError, match=">= 0"):
        RemeshAugmented(coarse, full, copies=-1)
    assert TrainConfig().remesh_copies == 0 and TrainConfig.from_dict({"remesh_copies": 2}).remesh_copies == 2


def test_training_on_a_batch_of_originals_and_variants_reduces_loss(full):
    samples = remesh_augmented(full, full, copies=2, seed=1)
    data = GraphDataset(samples, SMALL, with_collision=True, make_graph=build_graph)
    batch = collate([data[i] for i in range(len(data))])  # 2 originals + 4 variants of different sizes
    assert len({int(n) for n in torch.bincount(batch.batch)}) >= 3
    from garsim.model.garsim import GarSimModel

    torch.manual_seed(0)
    model = GarSimModel(SMALL)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    losses = []
    for _ in range(15):
        opt.zero_grad()
        loss, _ = garsim_loss(model(batch), batch, LossWeights(), use_collision=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)  # as the trainer does
        opt.step()
        losses.append(loss.item())
    assert all(np.isfinite(losses)) and losses[-1] < 0.9 * losses[0]  # 9.3e-3 -> 7.4e-3 here


def test_cli_flag_defaults_to_train_config_and_refuses_negative(tmp_path, capsys):
    from garsim.cli import main

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--remesh-copies" in text and f"(default: {TrainConfig().remesh_copies})" in text.split("--remesh-copies")[2]
    code = main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "run"), "--remesh-copies", "-1"])
    assert code == 2 and "--remesh-copies must be >= 0" in capsys.readouterr().err
