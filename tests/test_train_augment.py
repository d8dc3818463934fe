"""Remeshing augmentation (garsim.train.augment): fewer vertices, the same surfaces, deterministic, trainable."""

import dataclasses

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
    losses = _train_losses(batch)
    assert all(np.isfinite(losses)) and losses[-1] < 0.9 * losses[0]  # 9.3e-3 -> 7.4e-3 here


def _train_losses(batch, steps: int = 15) -> list[float]:
    """The loss of a small fresh model over ``steps`` Adam steps on one batch, clipped as the trainer does."""
    from garsim.model.garsim import GarSimModel

    torch.manual_seed(0)
    model = GarSimModel(SMALL)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    losses = []
    for _ in range(steps):
        opt.zero_grad()
        loss, _ = garsim_loss(model(batch), batch, LossWeights(), use_collision=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        losses.append(loss.item())
    return losses


def test_cli_flag_defaults_to_train_config_and_refuses_negative(tmp_path, capsys):
    from garsim.cli import main

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--remesh-copies" in text and f"(default: {TrainConfig().remesh_copies})" in text.split("--remesh-copies")[2]
    code = main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "run"), "--remesh-copies", "-1"])
    assert code == 2 and "--remesh-copies must be >= 0" in capsys.readouterr().err


def _normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    v = v.astype(np.float64)
    return np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])


def test_mirror_reflects_every_position_across_the_lateral_plane_and_keeps_normals_outward(full):
    from garsim.model.inputs import body_yaw_frame
    from garsim.train.augment import mirror_sample

    src = full[0]
    m = mirror_sample(src)
    lateral = body_yaw_frame(src.body_canonical)[0]
    centre = src.body_canonical.astype(np.float64).mean(axis=0)
    for name in ("body_canonical", "body_target", "garment", "prior", "target"):
        a, b = getattr(src, name).astype(np.float64), getattr(m, name).astype(np.float64)
        # by hand: the lateral coordinate about the centroid changes sign, the other two stay
        np.testing.assert_allclose((b - centre) @ lateral, -((a - centre) @ lateral), atol=1e-5)
        np.testing.assert_allclose(
            b - ((b - centre) @ lateral)[:, None] * lateral, a - ((a - centre) @ lateral)[:, None] * lateral, atol=1e-5
        )
        assert getattr(m, name).dtype == getattr(src, name).dtype
    # reversed winding: every face normal is the mirror image of the original one (outward stays outward)
    for (va, fa), (vb, fb) in (
        ((src.garment, src.garment_faces), (m.garment, m.garment_faces)),
        ((src.body_canonical, src.body_faces), (m.body_canonical, m.body_faces)),
    ):
        na, nb = _normals(va, fa), _normals(vb, fb)
        np.testing.assert_allclose(nb, na - 2.0 * (na @ lateral)[:, None] * lateral, atol=1e-6)
    # one reversed copy per body topology, not per faces array (the store loads a new array for every sample)
    twin = dataclasses.replace(src, body_faces=src.body_faces.copy())
    assert mirror_sample(twin).body_faces is m.body_faces
    twice = mirror_sample(m)
    np.testing.assert_allclose(twice.garment, src.garment, atol=1e-5)
    np.testing.assert_array_equal(twice.garment_faces, src.garment_faces)
    np.testing.assert_array_equal(m.pinned, src.pinned)
    assert m.meta["name"] == "a@0~mirror" and m.meta["mirror"] and "mirror" not in src.meta


def test_a_mirrored_anny_sample_is_an_anny_body_and_a_geometric_prior_follows_the_mirror():
    """On a real sample: the mirrored canonical body is the same Anny body (its shape is left-right symmetric to
    under a millimetre), and a prior that depends on geometry alone (the rig-free one), computed on the mirrored
    meshes, is the mirror of the original's. (The stored prior is Anny's LBS, whose skinning weights follow vertex
    indices: it is reflected with the scene, the prior of the mirrored pose on a symmetric rig.)"""
    from pathlib import Path

    from scipy.spatial import cKDTree

    from garsim.bodies.prior import rigfree_prior
    from garsim.data.store import DatasetStore
    from garsim.train.augment import mirror_sample

    s = DatasetStore(Path(__file__).parent / "fixtures" / "dataset_v2").samples("test", resolution="low")[0]
    m = mirror_sample(s)
    gap, _ = cKDTree(s.body_canonical).query(m.body_canonical)
    assert 1000 * gap.max() < 1.0  # mm: measured 0.22
    s.prior = rigfree_prior(s.garment, s.body_canonical, s.body_target, s.body_faces)
    again = rigfree_prior(m.garment, m.body_canonical, m.body_target, m.body_faces)
    assert 1000 * np.abs(again - mirror_sample(s).prior).max() < 0.01  # mm
    assert 1000 * np.abs(m.target - s.target).max() > 10.0  # and the mirror is another scene


def test_mirror_augmented_doubles_the_set_and_trains(full):
    from garsim.train.augment import MirrorAugmented

    aug = MirrorAugmented(remesh_augmented(full, full, copies=1, seed=1))
    assert len(aug) == 8 and aug[1] is full[1] and aug[-1].meta["name"] == "b@0~remesh0~mirror"
    with pytest.raises(IndexError):
        aug[8]
    data = GraphDataset(aug, SMALL, with_collision=True, make_graph=build_graph)
    losses = _train_losses(collate([data[i] for i in range(len(data))]))
    assert all(np.isfinite(losses)) and losses[-1] < 0.9 * losses[0]
    assert TrainConfig().mirror is False and TrainConfig.from_dict({"mirror": True}).mirror


def test_cli_mirror_trains_on_the_mirrored_set_too(tmp_path, capsys):
    """`garsim train --mirror` doubles the training set (the fixture's one skirt job and its rest sample) and
    records the choice in the run's config."""
    import json
    from pathlib import Path

    from garsim.cli import main

    fixture = str(Path(__file__).parent / "fixtures" / "dataset_v2")
    run = tmp_path / "run"
    args = ["train", "--data", fixture, "--out", str(run), "--families", "skirt", "--epochs", "1", "--quiet"]
    assert main(args) == 0
    plain = int(capsys.readouterr().out.split("training on ")[1].split()[0])
    assert main([*args[:4], str(tmp_path / "mirrored"), *args[5:], "--mirror"]) == 0
    assert int(capsys.readouterr().out.split("training on ")[1].split()[0]) == 2 * plain
    assert json.loads((tmp_path / "mirrored" / "train_config.json").read_text())["mirror"] is True
    assert json.loads((run / "train_config.json").read_text())["mirror"] is False
