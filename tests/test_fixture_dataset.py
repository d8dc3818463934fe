"""The committed fixture: real settled Newton samples (low resolution, last settled state) exported from the 40 x 4
v4 datasets by `examples/make_fixture.py --data ~/garsim-data/v4test --train-data ~/garsim-data/v4` (one test record
per family and construction, every canonical pose, physical fabric values, one paired-fabric group; four training
records)."""

from pathlib import Path

import numpy as np

from garsim.data.store import DatasetStore
from garsim.eval.metrics import collision_pct, euclidean_error_mm

FIXTURE = Path(__file__).parent / "fixtures" / "dataset_v2"


def test_fixture_is_intact_settled_and_physical():
    store = DatasetStore(FIXTURE)
    assert store.verify() == []
    records = list(store.sequences())
    assert {r.meta["construction"] for r in records} == {"template", "implicit"}
    assert len({r.garment_type for r in records}) >= 5
    assert len({r.meta["canonical_pose"] for r in records}) == 3
    samples = store.samples(resolution="low")
    for s in samples:
        assert np.isfinite(s.target).all() and s.meta["settled"][-1] and max(s.meta["final_speed"]) < 0.02
        assert collision_pct(s.target, s.body_target, s.body_faces) < 5.0  # the simulator kept cloth outside
        assert 1.0 < euclidean_error_mm(s.prior, s.target) < 400.0  # the prior misses the cloth's response
        assert s.fabric_values and s.fabric_values["bending"] > 0  # physical values stored with every sample


def test_fixture_holds_a_paired_group_ordered_like_real_fabrics():
    """One template in four fabrics, same body and pose: the stiffest stands off the body at least as far."""
    from garsim.physics.newton_sim import mean_body_distance

    store = DatasetStore(FIXTURE)
    groups: dict[str, dict[str, float]] = {}
    for rec in store.sequences():
        if rec.meta.get("paired"):
            lv = rec.levels["low"]
            dist = mean_body_distance(lv.targets[-1], rec.body_targets[-1])
            groups.setdefault(rec.meta["job"], {})[rec.fabric] = dist
    full = [g for g in groups.values() if len(g) == 4]
    assert full, "the fixture needs one complete paired group"
    g = full[0]
    assert g["leather"] >= g["silk"] - 0.002, g


def test_info_reads_a_store_with_only_the_low_level():
    """The fixture keeps the decimated level only: ``data info`` reports its vertex range from it."""
    info = DatasetStore(FIXTURE).info()
    assert info["settled_samples"] == 21
    assert 100 < info["vertices"]["min"] <= info["vertices"]["max"] < 1000
