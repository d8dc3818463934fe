import sys
from pathlib import Path

import numpy as np
import pytest

from garsim.data.store import DatasetStore, GarmentLevel, SequenceRecord
from garsim.eval.experiments import evaluate_split, format_group_table, format_table


def _store(tmp_path, metas=({}, {})):
    """Two tiny sequences on a unit-sphere 'body': truth 10 mm outside the prior; ``metas``: their metadata."""
    import trimesh

    body = trimesh.creation.icosphere(subdivisions=2)
    bv, bf = np.asarray(body.vertices, np.float32), np.asarray(body.faces)
    patch = trimesh.creation.icosphere(subdivisions=1)
    gv, gf = (np.asarray(patch.vertices) * 1.05).astype(np.float32), np.asarray(patch.faces)
    store = DatasetStore(tmp_path)
    for i, (kind, fabric) in enumerate([("skirt", "silk"), ("top", "denim")]):
        prior = gv[None].repeat(2, 0)
        truth = prior * (1.0 + 0.01 / 1.05)
        lv = GarmentLevel(gv, gf, np.zeros(len(gv), bool), prior, truth.astype(np.float32))
        rec = SequenceRecord(
            f"test-{i}", "test", kind, fabric, bv, bv[None].repeat(2, 0), bf, np.array([2, 9]), {"low": lv, "full": lv}
        )
        rec.meta.update(metas[i])
        store.append_manifest(store.write_sequence(rec))
    return tmp_path


def test_evaluate_prior_error_is_the_known_offset(tmp_path):
    res = evaluate_split(None, _store(tmp_path), "test")
    assert set(res) == {"prior", "nearest", "ground truth"} and set(res["prior"]) == {"all", "skirt", "top"}
    assert res["ground truth"]["all"]["euclidean_mm"] == 0.0
    assert abs(res["prior"]["all"]["euclidean_mm"] - 10.0) < 0.01
    assert res["nearest"]["all"]["euclidean_mm"] == res["prior"]["all"]["euclidean_mm"]  # the body does not move
    assert res["prior"]["all"]["frames"] == 4 and res["prior"]["all"]["collision_pct"] == 0.0
    # every vertex 5 cm out, but half the coarse patch's long edges dip into the sphere (midpoints down to r = 0.9986)
    assert res["prior"]["all"]["inside_pct"] == 0.0 and res["prior"]["all"]["edge_crossing_pct"] == 50.0
    assert "jitter_mm" not in res["prior"]["all"]  # settled poses, not an animation
    gt, prior = res["ground truth"]["all"], res["prior"]["all"]
    assert (gt["correction_cosine"], gt["correction_gain"]) == pytest.approx((1.0, 1.0))
    assert (prior["correction_cosine"], prior["correction_gain"]) == (0.0, 0.0)
    table = format_table(res)
    assert "| prior | skirt | 2 | 10.00 |" in table and "jitter" not in table


def test_rows_grouped_by_canonical_pose_construction_and_pose_mode(tmp_path):
    """The two sequences of the sphere store tagged with their metadata: every grouping splits the 4 frames the
    same way as the family does (a 10 mm prior error each), sequences without the key fall under 'unknown',
    and the per-frame pose mode comes from the sequence's list."""
    modes = ["walk", "everyday"]
    metas = [
        {"canonical_pose": "apose", "construction": "implicit", "pose_modes": modes, "paired": True},
        {"canonical_pose": "tpose", "construction": "template", "pose_modes": modes, "paired": False},
    ]
    root = _store(tmp_path, metas)
    res = evaluate_split(None, root, "test", by=("canonical_pose", "construction", "pose_mode", "paired"))
    prior = res["prior"]
    assert set(prior) == {
        "all",
        "canonical_pose=apose",
        "canonical_pose=tpose",
        "construction=implicit",
        "construction=template",
        "pose_mode=walk",
        "pose_mode=everyday",
        "paired=paired",
        "paired=single",
    }
    assert prior["canonical_pose=apose"]["frames"] == prior["pose_mode=walk"]["frames"] == 2
    assert prior["all"]["frames"] == 4 and prior["pose_mode=everyday"]["euclidean_mm"] == pytest.approx(10.0, abs=0.01)
    table = format_group_table(res, "nearest")
    assert table.splitlines()[2] == "| all | 4 | 10.00 | 10.00 | 1.000 | 0.00 | 50.00 |"
    assert table.splitlines()[3].startswith("| canonical_pose=apose | 2 | 10.00 |")
    untagged = evaluate_split(None, _store(tmp_path / "plain"), "test", by=("canonical_pose", "fabric"))["prior"]
    assert set(untagged) == {"all", "canonical_pose=unknown", "fabric=silk", "fabric=denim"}
    crossed = evaluate_split(None, root, "test", by=("family/construction",))["prior"]
    assert set(crossed) == {"all", "family/construction=skirt/implicit", "family/construction=top/template"}
    with pytest.raises(ValueError, match="cannot group results by \\['colour'\\]"):
        evaluate_split(None, root, "test", by=("family/colour",))


def test_post_processed_rows_leave_out_what_their_post_process_enforces(tmp_path):
    """A model 10 mm inside the sphere: every raw collision figure is 100%; the push-out's row has no DeePSD
    count (it enforces it) but still the winding-number and HOOD counts, now 0."""

    class Inside:
        def predict(self, samples):
            return [s.prior * 0.95 for s in samples]

    res = evaluate_split(Inside(), _store(tmp_path), "test", name="shrunk")
    raw, pushed = res["shrunk"]["all"], res["shrunk+push"]["all"]
    assert raw["collision_pct"] == raw["hood_collision_pct"] == raw["inside_pct"] == 100.0
    assert "collision_pct" not in pushed and pushed["inside_pct"] == pushed["hood_collision_pct"] == 0.0
    assert list(res)[:2] == ["shrunk", "shrunk+push"]
    assert "| shrunk+push | all | 4 |" in format_table(res) and " - |" in format_table(res)


def test_refined_rows_take_the_margin_and_a_plus_in_a_model_s_name_keeps_its_raw_figures(tmp_path, monkeypatch):
    """``collision_margin`` reaches both post-processes (the refinement too), None leaves the post-processed rows
    out, and a raw model whose name holds a "+" keeps every collision figure: only the text after the last "+" names
    a post-process."""
    import garsim.eval.experiments as experiments

    margins = []

    def recorded(pred, sample, collision_margin=0.002, refine=True, **kwargs):
        margins.append((collision_margin, refine))
        return pred

    monkeypatch.setattr(experiments, "postprocess", recorded)

    class Inside:
        def predict(self, samples):
            return [s.prior * 0.95 for s in samples]

    root = _store(tmp_path)
    res = evaluate_split(Inside(), root, "test", name="m+v2", refine=True, collision_margin=0.005)
    assert set(margins) == {(0.005, False), (0.005, True)} and len(margins) == 3 * 4  # push, refine, prior+refine
    assert {"collision_pct", "inside_pct", "edge_crossing_pct"} <= set(res["m+v2"]["all"])
    assert "inside_pct" not in res["m+v2+refine"]["all"] and "collision_pct" not in res["m+v2+push"]["all"]
    margins.clear()
    res = evaluate_split(Inside(), root, "test", refine=True, collision_margin=None)
    assert not margins and set(res) == {"garsim", "prior", "nearest", "ground truth"}


def test_jitter_of_an_animation_beside_the_truth(tmp_path):
    """A dynamic sequence of 3 consecutive frames: the truth at +0, +0.5 and +2 mm along Z (second difference
    1 mm/frame²), the prior standing still (0)."""
    import trimesh

    body = trimesh.creation.icosphere(subdivisions=2)
    bv, bf = np.asarray(body.vertices, np.float32), np.asarray(body.faces)
    patch = trimesh.creation.icosphere(subdivisions=1)
    gv, gf = (np.asarray(patch.vertices) * 1.05).astype(np.float32), np.asarray(patch.faces)
    shift = np.array([0.0, 0.0005, 0.002])[:, None, None] * np.array([0.0, 0.0, 1.0])
    truth = (gv[None] + shift).astype(np.float32)
    lv = GarmentLevel(gv, gf, np.zeros(len(gv), bool), gv[None].repeat(3, 0), truth)
    rec = SequenceRecord(
        "test-anim",
        "test",
        "skirt",
        "silk",
        bv,
        bv[None].repeat(3, 0),
        bf,
        np.arange(3),
        {"low": lv},
        meta={"dynamic": [True] * 3},
    )
    store = DatasetStore(tmp_path)
    store.append_manifest(store.write_sequence(rec))
    res = evaluate_split(None, tmp_path, "test")
    assert res["ground truth"]["all"]["jitter_mm"] == pytest.approx(1.0, abs=1e-3)  # float32 positions
    assert res["prior"]["skirt"]["jitter_mm"] == 0.0 and res["prior"]["all"]["sequences"] == 1
    assert "jitter (mm/frame²)" in format_table(res)


def test_paired_fabric_agreement_of_an_oracle_and_of_a_reversed_model(tmp_path):
    """A paired group whose simulated drapes stand 10, 20, 30, 40 mm off a sphere: the truth agrees 100%."""
    import trimesh

    from garsim.eval.experiments import paired_fabric_agreement

    body = trimesh.creation.icosphere(subdivisions=3)
    bv, bf = np.asarray(body.vertices, np.float32), np.asarray(body.faces)
    patch = trimesh.creation.icosphere(subdivisions=1)
    gv, gf = np.asarray(patch.vertices, np.float32), np.asarray(patch.faces)
    store = DatasetStore(tmp_path)
    for k, fabric in enumerate(["silk", "cotton", "denim", "leather"]):
        truth = (gv * (1.0 + 0.01 * (k + 1)))[None].astype(np.float32)
        lv = GarmentLevel(gv * 1.01, gf, np.zeros(len(gv), bool), gv[None] * 1.01, truth)
        rec = SequenceRecord(
            f"test-0-{fabric}",
            "test",
            "skirt",
            fabric,
            bv,
            bv[None],
            bf,
            np.array([0]),
            {"low": lv},
            meta={"paired": True, "job": "test-0"},
        )
        store.append_manifest(store.write_sequence(rec))

    class Truth:
        def predict(self, samples):
            return [s.target for s in samples]

    class Reversed:
        def predict(self, samples):
            return [s.target for s in samples][::-1]

    class Overshoot:  # the presets right, a fabric given by physical values drapes 30% further out than either
        def predict(self, samples):
            return [s.target * (1.3 if s.fabric == "custom" else 1.0) for s in samples]

    good = paired_fabric_agreement(Truth(), tmp_path)
    assert good["groups"] == 1 and good["ordering_agreement"] == 1.0 and good["spread_ratio"] == pytest.approx(1.0)
    assert good["midway_between"] == 1.0  # a midway fabric scored on its neighbours' own targets: between them
    assert paired_fabric_agreement(Reversed(), tmp_path)["ordering_agreement"] == 0.0
    over = paired_fabric_agreement(Overshoot(), tmp_path)
    # the distances of all 3 midway fabrics fall outside their presets'; a scaled patch keeps its fold angles: 3 of 6
    assert over["ordering_agreement"] == 1.0 and over["midway_between"] == 0.5
    # examples/fabric_spread.py's per-fabric means: the patch's vertices are the sphere's, 10 .. 40 mm out
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
    try:
        from fabric_spread import fabric_deviation, summarise
    finally:
        sys.path.pop(0)
    s = summarise(good)
    assert s["sim_distance_mm"] == pytest.approx({"silk": 10.0, "cotton": 20.0, "denim": 30.0, "leather": 40.0})
    assert s["pred_distance_mm"] == s["sim_distance_mm"] and s["sim_distance_spread"] == pytest.approx(30.0)
    assert summarise(paired_fabric_agreement(Reversed(), tmp_path))["pred_distance_spread"] == pytest.approx(-30.0)
    # each fabric's drape is 15, 5, 5, 15 mm from the group's mean (radial offsets of a unit-sphere patch)
    from garsim.eval.experiments import paired_groups

    dev = fabric_deviation(Truth(), paired_groups(tmp_path))
    assert (
        dev["sim_deviation_mm"] == pytest.approx(10.0, abs=1e-3) and dev["pred_deviation_mm"] == dev["sim_deviation_mm"]
    )
    assert dev["residual_deviation_mm"] == 0.0
    assert dev["sim_deviation_smoothed80_mm"] < dev["sim_deviation_smoothed5_mm"] < dev["sim_deviation_mm"]
    assert fabric_deviation(Reversed(), paired_groups(tmp_path))["residual_deviation_mm"] == pytest.approx(
        20.0, abs=1e-3
    )


def test_cluster_bootstrap_resamples_whole_clusters():
    from garsim.eval.experiments import cluster_bootstrap

    # one cluster's samples always move together: every resample of {a, a, b} by cluster is a mix of a=1, b=4
    mean, low, high = cluster_bootstrap(np.array([1.0, 1.0, 4.0]), ["a", "a", "b"], resamples=500)
    assert mean == pytest.approx(2.0)  # the per-sample mean, not the per-cluster one (2.5)
    assert low == pytest.approx(1.0) and high == pytest.approx(4.0)  # all-a and all-b resamples occur
    mean, low, high = cluster_bootstrap(np.full(6, -0.5), list("aabbcc"))
    assert (mean, low, high) == pytest.approx((-0.5, -0.5, -0.5))  # no spread, no interval


def test_compare_models_gives_the_difference_per_group(tmp_path):
    """On the sphere store (prior 10 mm from the truth): a model that is the truth is 10 mm better than the prior on
    every sample, and the interval is that exactly."""
    from garsim.eval.experiments import compare_models, format_comparison

    class Truth:
        def predict(self, samples):
            return [s.target for s in samples]

    table = compare_models(Truth(), None, _store(tmp_path), "test")
    assert list(table) == ["all", "skirt", "top"] and table["all"]["frames"] == 4
    row = table["skirt"]
    assert row["model_mm"] == 0.0 and row["other_mm"] == pytest.approx(10.0, abs=0.01)
    assert (row["diff_mm"], row["diff_low_mm"], row["diff_high_mm"]) == pytest.approx((-10.0,) * 3, abs=0.01)
    assert row["better_share"] == 1.0
    text = format_comparison(table, "truth", "prior")
    assert "| skirt | 2 | 0.00 | 10.00 | -10.00 | [-10.00, -10.00] | 100% |" in text


def test_the_fabric_spread_ratio_is_a_ratio_of_means_by_hand():
    """Groups with simulated spreads 2.04 and -10 mm (leather nearer the body), predicted 1 and -3 mm: (1 + 3) /
    12.04, where a mean of per-group ratios (0.49, 0.3) would weigh the group that barely passes the gap as much;
    a predicted spread the wrong way counts against it."""
    from garsim.eval.experiments import _spread_ratio

    assert _spread_ratio([(1.0, 2.04), (-3.0, -10.0)]) == pytest.approx(4.0 / 12.04)
    assert _spread_ratio([(1.0, 2.04), (3.0, -10.0)]) == pytest.approx(-2.0 / 12.04)
    assert _spread_ratio([]) is None
