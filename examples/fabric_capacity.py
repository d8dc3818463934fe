"""Can the network represent how the fabric changes the folds? Fit a model to a few paired-fabric groups (one
template, body and pose in all four presets) with the paired-fabric and fold-depth terms, training either every
weight or only the named ones (``--trainable``, e.g. the FiLM layers), and print each group's simulated and predicted
mean fold angle per fabric (deg, silk to leather) and mean error (mm) before and after.

A spread that even memorising two groups cannot reproduce is a limit of the architecture (or of the trained
pathway), not of the data. ``docs/studies/fabric_folds.md`` ran:

    .venv/bin/python examples/fabric_capacity.py --data ~/garsim-data/v4 --fold-weight 1.0
    .venv/bin/python examples/fabric_capacity.py --data ~/garsim-data/v4 --fold-weight 1.0 --trainable processor.film
    .venv/bin/python examples/fabric_capacity.py --data ~/garsim-data/v4 --fold-weight 0
    .venv/bin/python examples/fabric_capacity.py --data ~/garsim-data/v4 --fold-weight 1.0 --decoder-film \\
        --trainable processor.film decoder.fabric_film

(``--decoder-film``: the model's weights widened by ``fabric_decoder_film``, the new FiLM layer at zero.)
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile

import numpy as np

from garsim.eval.experiments import paired_groups
from garsim.model.garsim import GarSimModel
from garsim.physics.newton_sim import mean_fold_angle
from garsim.train.losses import LossWeights
from garsim.train.trainer import TrainConfig, Trainer


def report(model: GarSimModel, groups: list, tag: str) -> None:
    """One line per group: simulated and predicted mean fold angle per fabric and the mean error."""
    for group in groups:
        preds = model.predict(group)
        sim = [mean_fold_angle(s.target, s.garment_faces) for s in group]
        pred = [mean_fold_angle(p, s.garment_faces) for s, p in zip(group, preds)]
        err = [1000.0 * float(np.linalg.norm(p - s.target, axis=1).mean()) for s, p in zip(group, preds)]
        print(
            f"{tag:6s} {group[0].garment_type:10s} fold sim {np.round(sim, 2).tolist()} "
            f"pred {np.round(pred, 2).tolist()}  error mm {np.round(err, 1).tolist()}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="a dataset folder with complete paired groups")
    parser.add_argument("--split", default="train")
    parser.add_argument("--groups", type=int, default=2, help="fit the first N complete groups")
    parser.add_argument("--init", default="garsim/weights", help="the model to start from")
    parser.add_argument("--decoder-film", action="store_true", help="add the decoder FiLM (at zero) to --init")
    parser.add_argument("--trainable", nargs="*", default=[], help="parameter-name prefixes to train (default: all)")
    parser.add_argument("--fold-weight", type=float, default=1.0)
    parser.add_argument("--pair-weight", type=float, default=20.0)
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--lr", type=float, default=1e-3)
    args = parser.parse_args()
    groups = paired_groups(args.data, args.split)[: args.groups]
    if not groups:
        raise SystemExit(f"{args.data} has no complete paired group in its {args.split!r} split")
    init = GarSimModel.load(args.init)
    if args.decoder_film:
        init = init.widened(dataclasses.replace(init.config, fabric_decoder_film=True))
    with tempfile.TemporaryDirectory() as out:
        cfg = TrainConfig(
            out_dir=out,
            epochs=args.epochs,
            batch_size=4,
            lr=args.lr,
            warmup_steps=5,
            progress=False,
            resume=False,
            losses=LossWeights(pair=args.pair_weight, fold=args.fold_weight),
            trainable=tuple(args.trainable),
        )
        trainer = Trainer(init.config, cfg, [s for g in groups for s in g], None, init=init)
        report(trainer.model, groups, "before")
        history = trainer.fit()
        report(trainer.model, groups, "after")
    print(f"training loss {history[0]['train_loss']:.4f} -> {history[-1]['train_loss']:.4f}")


if __name__ == "__main__":
    main()
