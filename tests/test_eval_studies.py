"""Every study of ``garsim.eval.studies`` and its driver ``examples/experiments.py`` on the committed fixture, with a
tiny model trained for one epoch: the code paths, not the numbers."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from mesh_fixtures import plane_grid

from garsim.data.store import DatasetStore
from garsim.eval.studies import (
    StudyConfig,
    anatomy_row,
    capacity,
    data_scaling,
    deepsd_comparison,
    error_anatomy,
    external_anatomy,
    family_table,
    generalisation,
    heads_and_steps,
    resolution_levels,
    smooth_oracle,
    subdivide_level,
    train_variant,
)
from garsim.model.config import GarSimConfig
from garsim.train.trainer import TrainConfig

FIXTURE = Path(__file__).parent / "fixtures" / "dataset_v2"
WEIGHTS = Path(__file__).parents[1] / "garsim" / "weights"
SMALL = GarSimConfig(latent=32, edge_latent=16, mlp_hidden=32, num_steps=2)
BASELINES = {"prior", "nearest", "ground truth"}
TEST_FAMILIES = {"all", "skirt", "top", "tshirt", "longsleeve", "trousers", "dress"}


def _study(folder: Path, **train) -> StudyConfig:
    cfg = TrainConfig(out_dir=str(folder), epochs=1, batch_size=2, warmup_steps=1, progress=False, **train)
    return StudyConfig(str(FIXTURE), cfg, SMALL, val_every=2)


def test_a_variant_is_trained_once_and_keyed_by_what_decides_it(tmp_path):
    model, info = train_variant(_study(tmp_path))
    again, same = train_variant(_study(tmp_path, threads=2))  # threads do not change what is learnt: reused
    assert same == info and (info["train_sequences"], info["val_sequences"]) == (2, 2)
    assert len((Path(info["dir"]).parent / "log.csv").read_text().splitlines()) == 2  # header + one epoch, not two
    assert all(np.array_equal(a, b) for a, b in zip(model.state_dict().values(), again.state_dict().values()))
    assert train_variant(_study(tmp_path, seed=1))[1]["dir"] != info["dir"]


def test_heads_and_message_passing_steps(tmp_path):
    out = heads_and_steps(_study(tmp_path), steps=(0, 1))
    labels = [f"{h}, L=2" for h in ("direction_magnitude", "displacement", "position")]
    labels += ["direction_magnitude, L=0", "direction_magnitude, L=1"]
    assert list(out["results"]) == [*labels, "ground truth", "nearest", "prior"]
    assert all(set(per) == TEST_FAMILIES for per in out["results"].values())
    assert (
        json.loads((Path(out["models"]["direction_magnitude, L=0"]["dir"]) / "config.json").read_text())["num_steps"]
        == 0
    )
    table = family_table(out["results"])
    assert table.splitlines()[0] == "| euclidean_mm | all | dress | longsleeve | skirt | top | trousers | tshirt |"
    assert "| position, L=2 | " in table
    json.dumps(out)  # the result is JSON-able as it is


def test_generalisation_trains_on_the_seen_families_only(tmp_path):
    out = generalisation(_study(tmp_path))
    seen, every = out["models"]["trained on skirt and top"], out["models"]["trained on all families"]
    assert (seen["train_sequences"], seen["val_sequences"]) == (1, 0)  # the fixture's one skirt job, no top
    assert every["train_sequences"] == 2 and set(out["results"]) == {*out["models"], *BASELINES}
    assert "skirt (trained on)" in family_table(out["results"], seen=out["seen"])


def test_capacity_trains_each_size_on_the_families_and_scores_its_fit(tmp_path):
    out = capacity(_study(tmp_path), sizes=((16, 1), (32, 2)), families=("skirt", "tshirt", "dress"))
    labels = ["width 16, L=1", "width 32, L=2"]
    assert list(out["results"])[:2] == labels and out["families"] == ["skirt", "tshirt", "dress"]
    config = json.loads((Path(out["models"]["width 32, L=2"]["dir"]) / "config.json").read_text())
    assert (config["latent"], config["mlp_hidden"], config["edge_latent"], config["num_steps"]) == (32, 32, 16, 2)
    fit = out["fit"]
    assert list(fit) == [*labels, "prior"]
    trained = out["models"]["width 16, L=1"]["train_samples"]  # one-frame sequences, each with its rest sample
    assert fit["prior"]["all"]["frames"] == trained // 2  # the fit is scored on the frames alone
    assert set(fit["prior"]) <= {"all", "skirt", "tshirt", "dress"}
    json.dumps(out)


def test_data_scaling_with_the_external_check(tmp_path):
    fake = tmp_path / "check.py"
    fake.write_text(
        "import json, sys, pathlib\n"
        "args = dict(zip(sys.argv[1::2], sys.argv[2::2]))\n"
        "assert (pathlib.Path(args['--model']) / 'model.safetensors').exists()\n"
        "summary = {'all': {'n': 1, 'prior': {'euclid_mm': 2.0}, 'pred': {'euclid_mm': 1.0}}}\n"
        "json.dump({'summary': summary}, open(args['--json'], 'w'))\n"
    )
    out = data_scaling(_study(tmp_path / "run"), fractions=(0.5, 1.0), external=fake)
    sizes = {k: v["train_sequences"] for k, v in out["models"].items()}
    assert sizes == {"50% of the training jobs": 1, "100% of the training jobs": 2}
    assert set(out["external"]) == set(sizes) and out["external"]["50% of the training jobs"]["all"]["n"] == 1


def test_subdivided_levels_carry_the_simulated_surface():
    rec = next(DatasetStore(FIXTURE).sequences("test"))
    low = rec.levels["low"]
    fine = subdivide_level(low)
    n = len(low.template)
    np.testing.assert_array_equal(fine.template[:n], low.template)
    np.testing.assert_array_equal(fine.targets[:, :n], low.targets)
    assert fine.priors.shape == fine.targets.shape == (len(low.targets), len(fine.template), 3)
    a, b = fine.faces[len(low.faces) :][:1].T[:2]  # the 2nd block of faces: (m01, b, m12): b is an old vertex
    assert (b < n).all() and (a >= n).all()
    assert fine.pinned[:n].tolist() == low.pinned.tolist() and fine.pinned[n:].sum() <= low.pinned.sum()
    levels = resolution_levels(rec, (1, 2, 4))
    assert levels[1] is low and len(levels[4].template) == len(subdivide_level(levels[2]).template)
    with pytest.raises(ValueError, match="powers of 2"):
        resolution_levels(rec, (3,))


@pytest.fixture(scope="module")
def driver():
    spec = importlib.util.spec_from_file_location(
        "experiments", Path(__file__).parents[1] / "examples" / "experiments.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def driver_args(tmp_path_factory):
    folder = tmp_path_factory.mktemp("studies")
    SMALL.to_json(folder / "small.json")
    common = ["--data", str(FIXTURE), "--out", str(folder), "--budget", "1", "--val-every", "2"]
    return folder, [*common, "--config", str(folder / "small.json"), "--quiet"]


def test_driver_resolution(driver, driver_args):
    folder, args = driver_args
    assert driver.main(["resolution", *args, "--factors", "1", "2"]) == 0
    out = json.loads((folder / "resolution.json").read_text())
    assert list(out["levels"]) == ["1", "2"] and 1.7 < out["levels"]["2"]["linear_factor"] < 2.05
    res = out["results"]
    assert set(res) == {f"{m} @ {f}x" for m in ("network", "network, decimated", "prior") for f in (1, 2)}
    assert res["network @ 1x"] == res["network, decimated @ 1x"]  # the training resolution needs no decimation
    assert res["prior @ 2x"]["all"]["euclidean_mm"] == pytest.approx(res["prior @ 1x"]["all"]["euclidean_mm"], rel=0.2)
    text = (folder / "resolution.md").read_text()
    assert "`python examples/experiments.py resolution --data" in text and "| network, decimated @ 2x |" in text


def test_driver_corrections(driver, driver_args):
    folder, args = driver_args
    assert driver.main(["corrections", *args, "--size", "64"]) == 0
    rows = json.loads((folder / "corrections.json").read_text())["samples"]
    assert {r["garment"] for r in rows} == TEST_FAMILIES - {"all"}
    assert all(Path(r["png"]).stat().st_size > 0 and r["network_max_mm"] >= r["network_mean_mm"] for r in rows)
    samples = {s.meta["name"]: s for s in DatasetStore(FIXTURE).samples("test")}
    for r in rows:
        s = samples[r["sample"]]
        assert r["simulation_mean_mm"] == pytest.approx(1000 * np.linalg.norm(s.target - s.prior, axis=1).mean())
    assert len(list((folder / "models").iterdir())) == 1  # the base model, trained by `resolution`, reused
    assert "corrections/" in (folder / "corrections.md").read_text()


def test_driver_scores_the_test_data_folder(driver, driver_args, tmp_path):
    """--test-data: the scored split comes from that folder (--data, the training folder, is not read)."""
    _, args = driver_args
    trained = train_variant(_study(tmp_path / "base"))[1]["dir"]  # this test's own model: independent of the others
    args = [a if a != str(FIXTURE) else str(tmp_path / "absent") for a in args]
    args = [*args, "--test-data", str(FIXTURE), "--model", trained, "--size", "64"]
    args[args.index("--out") + 1] = str(tmp_path)
    assert driver.main(["corrections", *args]) == 0
    assert not (tmp_path / "absent").exists()
    rows = json.loads((tmp_path / "corrections.json").read_text())["samples"]
    assert {r["garment"] for r in rows} == TEST_FAMILIES - {"all"}


def test_baselines_table3_trains_the_deepsd_style_baseline_under_the_same_protocol(tmp_path):
    out = deepsd_comparison(
        _study(tmp_path), resolutions=("low",)
    )  # the fixture's test split holds only the low meshes
    garsim_dir, deepsd_dir = (Path(out["models"][k]["dir"]) for k in ("GarSim", "DeePSD-style"))
    assert garsim_dir != deepsd_dir
    assert json.loads((deepsd_dir.parent / "variant.json").read_text())["train"]["model"] == "deepsd"
    assert out["models"]["GarSim"]["train_sequences"] == out["models"]["DeePSD-style"]["train_sequences"] == 2
    assert set(out["results"]) == {f"{m} @ low" for m in ("GarSim", "DeePSD-style", *BASELINES)}
    for res in ("low",):
        g, d = out["results"][f"GarSim @ {res}"], out["results"][f"DeePSD-style @ {res}"]
        assert set(out["garsim_over_deepsd"][res]) == set(g) == TEST_FAMILIES
        np.testing.assert_allclose(
            out["garsim_over_deepsd"][res]["all"], g["all"]["euclidean_mm"] / d["all"]["euclidean_mm"]
        )
    json.dumps(out)


def test_driver_baselines(driver, driver_args):
    folder, args = driver_args
    assert driver.main(["baselines", *args, "--resolutions", "low"]) == 0
    out = json.loads((folder / "baselines.json").read_text())
    assert set(out["garsim_over_deepsd"]) == {"low"} and "GarSim @ low" in out["results"]
    text = (folder / "baselines.md").read_text()
    assert "`python examples/experiments.py baselines --data" in text and "| DeePSD-style @ low |" in text
    assert "GarSim's error over the DeePSD-style baseline's (the paper: at most 0.5)" in text


def test_solver_convergence_budgets_keep_the_damping_per_second():
    """examples/solver_convergence.py varies only the solver's convergence: every budget damps velocity by the same
    factor per simulated second as SimConfig(), and the floor run scales gravity alone."""
    from garsim.physics.newton_sim import SimConfig

    spec = importlib.util.spec_from_file_location(
        "solver_convergence", Path(__file__).parents[1] / "examples" / "solver_convergence.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    base = SimConfig()
    per_second = base.damping ** (base.substeps * base.fps)
    for budget, (substeps, iterations) in {"10x4": (10, 4), "20x8": (20, 8), "80x8": (80, 8)}.items():
        cfg = module.budget_config(budget)
        assert (cfg.substeps, cfg.iterations, cfg.gravity) == (substeps, iterations, base.gravity)
        assert cfg.damping ** (cfg.substeps * cfg.fps) == pytest.approx(per_second, rel=1e-9)
    assert module.budget_config("40x8", 1.001).gravity == pytest.approx(1.001 * base.gravity)
    default = module.budget_config(f"{base.substeps}x{base.iterations}")
    assert (default.substeps, default.iterations, default.damping) == (base.substeps, base.iterations, base.damping)
    strict = module.budget_config("20x8", settle_speed=0.002, max_settle_frames=300)  # the stricter settling test
    assert (strict.settle_speed, strict.max_settle_frames, strict.substeps) == (0.002, 300, 20)


def test_driver_protocol_takes_the_collision_start(driver, driver_args):
    _, args = driver_args
    parse = driver.parser().parse_args
    assert driver.study_config(parse(["capacity", *args])).train.collision_start_epoch is None  # the patience rule
    config = driver.study_config(parse(["capacity", *args, "--collision-start", "3", "--sizes", "32:2"]))
    assert config.train.collision_start_epoch == 3 and parse(["capacity", *args, "--sizes", "32:2"]).sizes == [(32, 2)]
    with pytest.raises(SystemExit):
        parse(["capacity", *args, "--sizes", "wide"])


def test_smooth_oracle_leaves_little_below_a_short_length_and_scores_the_model(tmp_path):
    """A correction smoothed at 1 mm leaves almost nothing of the prior's error, a longer length leaves more; the
    model's column is its mean error over the samples."""
    import torch

    from garsim.model.garsim import GarSimModel

    torch.manual_seed(0)
    model = GarSimModel(SMALL).eval()
    out = smooth_oracle(_study(tmp_path), model, sigmas=(0.001, 0.05, 0.2))["oracle"]
    assert set(out) == TEST_FAMILIES and list(out)[0] == "all"
    samples = DatasetStore(FIXTURE).samples("test")
    assert out["all"]["samples"] == len(samples)
    for row in out.values():
        assert row["oracle@0.001"] < 0.05 * row["prior"]
        assert row["oracle@0.001"] < row["oracle@0.05"] < row["oracle@0.2"]
    want = np.mean(
        [1000 * np.linalg.norm(p - s.target, axis=1).mean() for p, s in zip(model.predict(samples), samples)]
    )
    assert out["all"]["model"] == pytest.approx(want)
    prior = np.mean([1000 * np.linalg.norm(s.prior - s.target, axis=1).mean() for s in samples])
    assert out["all"]["prior"] == pytest.approx(prior)
    assert "model" not in smooth_oracle(_study(tmp_path), None, sigmas=(0.05,))["oracle"]["all"]


def test_driver_oracle(driver, driver_args):
    folder, args = driver_args
    assert driver.main(["oracle", *args, "--sigmas", "0.02", "0.08"]) == 0
    text = (folder / "oracle.md").read_text()
    assert "| all |" in text and "oracle@0.08" in text and "(0." in text


def test_anatomy_row_by_hand():
    """Over a flat body (normal +Z): a prior off by 1-4 mm across the normal, by height band, and a prediction 2 mm
    above the truth; the correction points the right way (cosine > 0), none at all scores 0."""
    body, faces = plane_grid()
    target = np.stack([np.linspace(-0.1, 0.1, 8), np.zeros(8), np.full(8, 0.05)], axis=1)
    template = target + np.array([0.0, 0.0, 1.0]) * np.arange(8)[::-1, None]  # heights descending: bands 3,3,2,..0
    band = np.array([3, 3, 2, 2, 1, 1, 0, 0])
    prior = target + np.array([0.0, 0.001, 0.0]) * (band + 1)[:, None]
    pred = target + np.array([0.0, 0.0, 0.002])
    row = anatomy_row(template, prior, pred, target, body, faces)
    assert row["prior_mm"] == pytest.approx(2.5) and row["prior_tangential_mm"] == pytest.approx(2.5)
    assert row["prior_normal_mm"] == pytest.approx(0.0, abs=1e-9)
    assert row["model_normal_mm"] == pytest.approx(2.0) and row["model_tangential_mm"] == pytest.approx(0.0, abs=1e-9)
    assert [row[f"prior_band{b}_mm"] for b in range(4)] == pytest.approx([1.0, 2.0, 3.0, 4.0])
    assert 0.0 < row["cosine"] < 1.0
    assert anatomy_row(template, prior, target, target, body, faces)["cosine"] == pytest.approx(1.0)
    assert anatomy_row(template, prior, prior, target, body, faces)["cosine"] == 0.0
    summary = error_anatomy([("top", row), ("skirt", {**row, "cosine": 0.0})])
    assert list(summary) == ["all", "skirt", "top"] and summary["all"]["samples"] == 2
    assert summary["all"]["cosine"] == pytest.approx(row["cosine"] / 2)


def test_external_anatomy_drapes_through_the_api(tmp_path):
    """A folder in the external set's format (one fixture sample): the raw network through ``GarSim.drape``."""
    s = DatasetStore(FIXTURE).samples("test")[0]
    np.save(tmp_path / "body_faces.npy", s.body_faces)
    np.savez(
        tmp_path / "h000.npz",
        body_canonical=s.body_canonical,
        body_target=s.body_target,
        garment_template=s.garment,
        garment_faces=s.garment_faces,
        garment_prior=s.prior,
        garment_target_gt=s.target,
        garment_type=s.garment_type,
        fabric=s.fabric,
    )
    [(family, row)] = external_anatomy(tmp_path, WEIGHTS)
    assert family == s.garment_type
    assert row["prior_mm"] == pytest.approx(1000 * np.linalg.norm(s.prior - s.target, axis=1).mean())
    assert row["model_mm"] != row["prior_mm"] and -1.0 <= row["cosine"] <= 1.0


def test_driver_anatomy(driver, driver_args):
    folder, args = driver_args
    assert driver.main(["anatomy", *args, "--model", str(WEIGHTS), "--external-data", str(folder / "none")]) == 0
    text = (folder / "anatomy.md").read_text()
    assert "| all |" in text and "tangential" in text and "The external set" not in text


def test_prior_bands_groups_the_priors_error_by_family_construction_and_pose():
    """examples/prior_bands.py: every sample counted once per group, the overall error the mean prior error."""
    spec = importlib.util.spec_from_file_location(
        "prior_bands", Path(__file__).parents[1] / "examples" / "prior_bands.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    samples = DatasetStore(FIXTURE).samples("test")
    families = tuple(sorted({s.garment_type for s in samples}))
    result = module.prior_bands(FIXTURE, "test", families)
    alls = {k: r for k, r in result.items() if k.endswith("/all")}
    assert sum(r["samples"] for r in alls.values()) == len(samples)
    assert sum(r["samples"] for k, r in result.items() if not k.endswith("/all")) == len(samples)
    for key, r in alls.items():
        family, construction, _ = key.split("/")
        errs = [
            1000 * np.linalg.norm(s.target - s.prior, axis=1).mean()
            for s in samples
            if s.garment_type == family and s.meta["construction"] == construction
        ]
        assert r["prior_mm"] == pytest.approx(np.mean(errs), abs=0.06)  # rounded to 0.1 mm
    with pytest.raises(ValueError, match="no 'ood' samples of shirt"):
        module.prior_bands(FIXTURE, "ood", ("shirt",))
