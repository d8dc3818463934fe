import numpy as np

from garsim.data.store import DatasetStore, GarmentLevel, SequenceRecord
from garsim.eval.experiments import evaluate_split, fabric_awareness, format_table, ground_truth_fabric_distances


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


class _Oracle:
    """A 'model' that returns the ground truth scaled by fabric (checks fabric plumbing)."""

    def predict(self, samples):
        scale = {"silk": 1.0, "cotton": 1.01, "denim": 1.02, "leather": 1.03}
        return [s.prior * scale[s.fabric] for s in samples]


def test_fabric_awareness_uses_each_fabric(tmp_path):
    d = fabric_awareness(_Oracle(), _store(tmp_path), garment_type="skirt")
    assert d["silk"] < d["cotton"] < d["denim"] < d["leather"]
    assert abs(d["silk"] - 50.0) < 1.0  # garment at radius 1.05 over a unit sphere (icosphere vertices)
    assert set(ground_truth_fabric_distances(tmp_path, garment_type="skirt")) == {"silk"}
