import numpy as np
import pytest

from garsim.data.store import DatasetStore, GarmentLevel, SequenceRecord
from garsim.eval.experiments import evaluate_split, format_table


def _store(tmp_path):
    """Two tiny sequences on a unit-sphere 'body': truth 10 mm outside the prior."""
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
        store.append_manifest(store.write_sequence(rec))
    return tmp_path


def test_evaluate_prior_error_is_the_known_offset(tmp_path):
    res = evaluate_split(None, _store(tmp_path), "test")
    assert set(res) == {"prior", "ground truth"} and set(res["prior"]) == {"all", "skirt", "top"}
    assert res["ground truth"]["all"]["euclidean_mm"] == 0.0
    assert abs(res["prior"]["all"]["euclidean_mm"] - 10.0) < 0.01
    assert res["prior"]["all"]["frames"] == 4 and res["prior"]["all"]["collision_pct"] == 0.0
    assert "| prior | skirt | 2 | 10.00 |" in format_table(res)


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

    good = paired_fabric_agreement(Truth(), tmp_path)
    assert good["groups"] == 1 and good["ordering_agreement"] == 1.0 and good["spread_ratio"] == pytest.approx(1.0)
    assert paired_fabric_agreement(Reversed(), tmp_path)["ordering_agreement"] == 0.0
