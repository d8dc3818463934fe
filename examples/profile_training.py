"""What a training stage costs: graph building, seconds per epoch and peak memory per process, on a share of a
dataset with the recipe's augmentations (remeshed variants, mirror images) and loss terms, from the shipped weights,
and the cached graphs' memory (``cached_mb``; ``unshared_mb`` without the sharing of equal tensors).

Run (two DDP processes on CPU, as ``examples/train_v1.sh`` trains):
    OMP_NUM_THREADS=1 .venv/bin/torchrun --nproc_per_node=2 examples/profile_training.py \\
        --data ~/garsim-data/v5snap1 --fraction 0.1 --json docs/studies/training_cost/after.json
or one process with ``.venv/bin/python examples/profile_training.py ...``. The same command on another checkout
measures it before a change (``docs/studies/training_cost.md``); the validation errors must match when only the
speed changed.
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from pathlib import Path

import torch.distributed as dist

from garsim.atomic import atomic_write
from garsim.model.garsim import GarSimModel
from garsim.train.augment import MirrorAugmented, remesh_augmented
from garsim.train.data import train_val_samples
from garsim.train.losses import LossWeights
from garsim.train.trainer import TrainConfig, Trainer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True, help="a dataset folder with a train split")
    parser.add_argument("--fraction", type=float, default=0.1, help="share of the training jobs (whole jobs)")
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--remesh-copies", type=int, default=2)
    parser.add_argument("--no-mirror", action="store_true")
    parser.add_argument("--model", default="garsim/weights", help="the weights the run starts from")
    parser.add_argument("--json", type=Path, help="write the figures here (rank 0)")
    args = parser.parse_args()

    t0 = time.perf_counter()
    train, val = train_val_samples(args.data, "low", fraction=args.fraction)
    if args.remesh_copies:
        full, _ = train_val_samples(args.data, "full", fraction=args.fraction)
        train = remesh_augmented(train, full, args.remesh_copies, seed=0)
    if not args.no_mirror:
        train = MirrorAugmented(train)
    model = GarSimModel.load(args.model)
    with tempfile.TemporaryDirectory() as out:
        config = TrainConfig(
            out_dir=out,
            epochs=args.epochs,
            lr=1e-4,
            progress=False,
            resume=False,
            collision_start_epoch=0,
            losses=LossWeights(col=10.0, eps=0.002, pair=1.0),
        )
        trainer = Trainer(model.config, config, train, val[:16], init=model)
        loaded = time.perf_counter()
        getattr(trainer, "build_graphs", lambda: None)()  # checkouts before 2026-12-06 build inside the epochs
        built = time.perf_counter()
        history = trainer.fit()
    row = {
        "rank": trainer.rank,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024,
        "graphs_cached": len(trainer.train_set._graphs),  # the cache itself: older checkouts have no accessor
    }
    if hasattr(trainer.train_set, "cached_bytes"):  # since 2026-12-07: the cache shares equal tensors
        row["cached_mb"] = round(trainer.train_set.cached_bytes() / 2**20, 1)
        row["unshared_mb"] = round(trainer.train_set.cached_bytes(shared=False) / 2**20, 1)
    rows = [row] * trainer.world
    if trainer.world > 1:
        dist.all_gather_object(rows, row)
    if trainer.rank == 0:
        figures = {
            "data": str(args.data),
            "processes": trainer.world,
            "graphs": len(train),
            "steps_per_epoch": trainer.steps_per_epoch(),
            "load_s": round(loaded - t0, 1),
            "build_s": round(built - loaded, 1),
            "epoch_s": [round(h["seconds"], 1) for h in history],
            "total_s": round(time.perf_counter() - t0, 1),
            "val_err_mm": [round(h["val_err_mm"], 3) for h in history],
            "per_process": rows,
        }
        print(json.dumps(figures, indent=1))
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            atomic_write(args.json, lambda p: Path(p).write_text(json.dumps(figures, indent=1)))


if __name__ == "__main__":
    main()
