"""``examples/train_v1.sh``, the documented training recipe, runs its stages end to end on the fixture, as documented:
two DDP processes (each on its shard of the samples, paired groups whole) and mirror images (the fixture holds no
full-resolution training meshes to remesh)."""

import json
import os
import subprocess
from pathlib import Path

import pytest

from garsim.model.garsim import GarSimModel

ROOT = Path(__file__).parents[1]


@pytest.mark.slow
def test_recipe_runs_every_stage_and_averages_the_fine_tunes(tmp_path):
    env = {
        **os.environ,
        "DATA": str(ROOT / "tests" / "fixtures" / "dataset_v2"),
        "OUT": str(tmp_path),
        **dict(PROCS="2", BATCH="2", STAGE1_EPOCHS="1", FINETUNE_EPOCHS="1", FABRIC_EPOCHS="1", STAGE2_EPOCHS="0"),
        **dict(SOUP="1", PAIR="1", MIRROR="1"),
    }
    r = subprocess.run(["bash", "examples/train_v1.sh"], cwd=ROOT, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    model = Path(r.stdout.strip().splitlines()[-1])
    assert model == tmp_path / "fabric" / "soup"  # the last stage's average, printed for shipping
    assert json.loads((tmp_path / "fabric" / "train_config.json").read_text())["losses"]["fold"] == 0.3
    fine, fabric, soup = (
        GarSimModel.load(p).state_dict() for p in (tmp_path / "finetune" / "soup", tmp_path / "fabric" / "best", model)
    )
    key = next(iter(soup))
    assert (soup[key] - 0.5 * (fine[key] + fabric[key])).abs().max() < 1e-6  # averaged with the stage's start


@pytest.mark.slow
def test_recipe_with_init_skips_stage1_and_fine_tunes_that_model(tmp_path):
    init = ROOT / "garsim" / "weights"
    run = tmp_path / "run"
    env = {
        **os.environ,
        "DATA": str(ROOT / "tests" / "fixtures" / "dataset_v2"),
        "OUT": str(run),
        "INIT": str(init),
        **dict(PROCS="1", BATCH="2", FINETUNE_EPOCHS="1", FABRIC_EPOCHS="0", STAGE2_EPOCHS="0", SOUP="1"),
    }
    r = subprocess.run(["bash", "examples/train_v1.sh"], cwd=ROOT, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    model = Path(r.stdout.strip().splitlines()[-1])
    assert model == run / "finetune" / "soup"
    assert not (run / "stage1").exists()
    start, fine, soup = (GarSimModel.load(p).state_dict() for p in (init, run / "finetune" / "best", model))
    key = next(iter(soup))
    assert (fine[key] - start[key]).abs().max() > 0  # trained from the given model...
    assert (soup[key] - 0.5 * (start[key] + fine[key])).abs().max() < 1e-6  # ...and averaged with it
