"""The paper's experiments on a generated dataset, one command each (``garsim.eval.studies``): every variant is
trained under one protocol (data, split, schedule, seed) and scored per garment family on the test split.

    ARGS="--data ~/garsim-data/v4 --test-data ~/garsim-data/v4test --out runs/studies"
    .venv/bin/python examples/experiments.py heads $ARGS --budget 30
    .venv/bin/python examples/experiments.py baselines $ARGS --budget 30
    .venv/bin/python examples/experiments.py generalisation $ARGS --budget 30
    .venv/bin/python examples/experiments.py resolution $ARGS --budget 30
    .venv/bin/python examples/experiments.py scaling $ARGS --budget 30
    .venv/bin/python examples/experiments.py corrections $ARGS --model DIR
    .venv/bin/python examples/experiments.py capacity $ARGS --budget 100 --config garsim/weights/config.json
    .venv/bin/python examples/experiments.py oracle $ARGS --model garsim/weights   (trains nothing)
    .venv/bin/python examples/experiments.py anatomy $ARGS --model garsim/weights  (trains nothing)

Each writes <out>/<study>.json and <out>/<study>.md (its tables, headed by the command). Trained models go to
<out>/models/<key>/, keyed by what decides them, so a variant several studies share (the base model trained on
every family: heads, baselines, generalisation, scaling at 100%, resolution, corrections) is trained once, and a rerun
resumes. ``scaling`` also runs the external set's check.py on every model when the file exists.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path
from typing import Any

from garsim.atomic import atomic_write
from garsim.data.sample import GARMENT_TYPES
from garsim.eval import studies
from garsim.eval.experiments import format_table
from garsim.model.baselines import load_model
from garsim.model.config import HEADS, GarSimConfig
from garsim.model.weights import read_model_config
from garsim.train.trainer import TrainConfig

EXTERNAL = Path(__file__).resolve().parents[2] / "shared" / "external-eval" / "check.py"
TITLES = {
    "heads": "Table 2 analog: decoder heads and message-passing steps",
    "baselines": "Table 3 analog: GarSim beside the DeePSD-style baseline",
    "generalisation": "Generalisation: trained on some families, tested on all",
    "resolution": "Resolution: trained at low resolution, tested at 1x-8x",
    "scaling": "Data scaling: error vs training-set size",
    "corrections": "Corrections over the prior (Fig. 8)",
    "capacity": "Capacity: wider and deeper networks on the families v0.7 underfits",
    "oracle": "Smooth-correction oracle: how much of each family's error is finer than a length",
    "anatomy": "Error anatomy: along and across the body, by height, and the correction's direction",
}


def _size(text: str) -> tuple[int, int]:
    """``WIDTH:L`` of ``capacity --sizes``."""
    width, _, steps = text.partition(":")
    try:
        return int(width), int(steps)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTH:L (e.g. 128:5), got {text!r}") from None


def parser() -> argparse.ArgumentParser:
    """The driver's arguments: the protocol's options, then one subcommand per study."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--data", required=True, help="dataset folder made by `garsim data generate`")
    common.add_argument("--test-data", help="dataset folder of the scored split (default: --data)")
    common.add_argument("--out", required=True, help="study folder: results, models/, figures")
    common.add_argument("--budget", type=int, default=TrainConfig.epochs, help="training epochs of every variant")
    common.add_argument("--max-steps", type=int, help="cap on optimizer steps per epoch (smoke runs)")
    common.add_argument("--seed", type=int, default=TrainConfig.seed)
    common.add_argument("--batch-size", type=int, default=TrainConfig.batch_size)
    common.add_argument("--lr", type=float, default=TrainConfig.lr)
    common.add_argument("--threads", type=int, default=TrainConfig.threads, help="torch threads")
    common.add_argument("--device", default=TrainConfig.device)
    common.add_argument(
        "--collision-start",
        type=int,
        default=TrainConfig.collision_start_epoch,
        help="epoch the collision term starts (default: once validation stops improving)",
    )
    common.add_argument(
        "--config",
        help="base model: a GarSimConfig JSON file or a saved model's config.json (default: GarSimConfig())",
    )
    common.add_argument("--split", default="test", help="split scored")
    common.add_argument("--val-every", type=int, default=10, help="hold out every N-th training job")
    common.add_argument("--quiet", action="store_true", help="no progress bars")
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="study", required=True)
    s = sub.add_parser("heads", parents=[common], help=TITLES["heads"])
    s.add_argument("--heads", nargs="+", choices=HEADS, default=list(HEADS))
    s.add_argument("--steps", nargs="+", type=int, default=list(studies.STEPS), help="message-passing steps L")
    s = sub.add_parser("baselines", parents=[common], help=TITLES["baselines"])
    s.add_argument("--resolutions", nargs="+", choices=("low", "full"), default=["low", "full"])
    s = sub.add_parser("generalisation", parents=[common], help=TITLES["generalisation"])
    s.add_argument("--families", nargs="+", choices=GARMENT_TYPES, default=list(studies.SEEN_FAMILIES))
    s = sub.add_parser("resolution", parents=[common], help=TITLES["resolution"])
    s.add_argument("--factors", nargs="+", type=int, default=list(studies.FACTORS), help="powers of 2")
    s.add_argument("--model", help="a model trained at low resolution (default: train the base model)")
    s = sub.add_parser("scaling", parents=[common], help=TITLES["scaling"])
    s.add_argument("--fractions", nargs="+", type=float, default=list(studies.FRACTIONS))
    s.add_argument("--external", default=str(EXTERNAL), help="external set's check.py (skipped when absent)")
    s = sub.add_parser("capacity", parents=[common], help=TITLES["capacity"])
    s.add_argument(
        "--sizes",
        nargs="+",
        type=_size,
        default=list(studies.SIZES),
        metavar="WIDTH:L",
        help="variants: latent and MLP width, message-passing steps",
    )
    s.add_argument("--families", nargs="+", choices=GARMENT_TYPES, default=list(studies.UPPER_BODY))
    s = sub.add_parser("corrections", parents=[common], help=TITLES["corrections"])
    s.add_argument("--model", help="a trained model folder (default: train the base model)")
    s.add_argument("--per-family", type=int, default=1, help="random samples rendered per family")
    s.add_argument("--size", type=int, default=512, help="image height in pixels")
    s = sub.add_parser("oracle", parents=[common], help=TITLES["oracle"])
    s.add_argument("--model", help="a trained model folder scored beside the oracle (default: none)")
    s.add_argument("--sigmas", nargs="+", type=float, default=list(studies.SIGMAS), help="lengths in metres")
    s = sub.add_parser("anatomy", parents=[common], help=TITLES["anatomy"])
    s.add_argument("--model", required=True, help="a trained model folder (its raw network is scored)")
    s.add_argument(
        "--external-data", default=str(EXTERNAL.parent / "data"), help="the external set's data (skipped when absent)"
    )
    return p


def study_config(args: argparse.Namespace) -> studies.StudyConfig:
    """The protocol of the command line's options (resolution and corrections train at the low resolution)."""
    train = TrainConfig(
        out_dir=args.out,
        epochs=args.budget,
        max_steps_per_epoch=args.max_steps,
        seed=args.seed,
        batch_size=args.batch_size,
        lr=args.lr,
        threads=args.threads,
        device=args.device,
        collision_start_epoch=args.collision_start,
        progress=not args.quiet,
    )
    model = read_model_config(args.config)[0] if args.config else GarSimConfig()
    return studies.StudyConfig(
        args.data, train, model, split=args.split, val_every=args.val_every, test_data=args.test_data
    )


def run(args: argparse.Namespace) -> tuple[dict[str, Any], list[str]]:
    """Run the chosen study; its JSON-able result and the Markdown sections of its report."""
    study = study_config(args)
    if args.study == "heads":
        result = studies.heads_and_steps(study, args.heads, args.steps)
    elif args.study == "baselines":
        result = studies.deepsd_comparison(study, args.resolutions)
    elif args.study == "generalisation":
        result = studies.generalisation(study, args.families)
    elif args.study == "capacity":
        result = studies.capacity(study, args.sizes, args.families)
    elif args.study == "oracle":
        result = studies.smooth_oracle(study, load_model(args.model) if args.model else None, args.sigmas)
        return result, [
            "Mean Euclidean error (mm) and its ratio to the prior's:\n\n" + studies.oracle_table(result["oracle"])
        ]
    elif args.study == "anatomy":
        result = {
            "protocol": study.to_dict(),
            "split": studies.error_anatomy(studies.dataset_anatomy(study, load_model(args.model))),
        }
        sections = [
            f"The {args.split} split, raw network (prior -> model, mm):\n\n" + studies.anatomy_table(result["split"])
        ]
        if Path(args.external_data).exists():
            result["external"] = studies.error_anatomy(studies.external_anatomy(args.external_data, args.model))
            sections.append(
                "The external set, raw network through the API (prior -> model, mm):\n\n"
                + studies.anatomy_table(result["external"])
            )
        return result, sections
    elif args.study == "scaling":
        external = args.external if Path(args.external).exists() else None
        if external is None:
            print(f"{args.external} not found: the external set is left out")
        result = studies.data_scaling(study, args.fractions, external)
    else:
        model = load_model(args.model) if args.model else studies.train_variant(study)[0]
        if args.study == "resolution":
            result = studies.resolution_study(study, model, args.factors)
        else:
            result = studies.corrections(study, model, args.per_family, args.size)
    if args.study == "corrections":
        sections = [
            f"![{r['sample']}]({Path(r['png']).relative_to(args.out)}) {r['garment']}/{r['fabric']}: network "
            f"{r['network_mean_mm']:.1f} mm mean, {r['network_max_mm']:.0f} max; simulation "
            f"{r['simulation_mean_mm']:.1f} / {r['simulation_max_mm']:.0f} mm; error {r['error_mm']:.1f} mm"
            for r in result["samples"]
        ]
        return result, sections
    sections = [
        "Mean Euclidean error (mm) per family:\n\n"
        + studies.family_table(result["results"], seen=result.get("seen", ())),
        "Every metric:\n\n" + format_table(result["results"]),
    ]
    if "fit" in result:
        sections.insert(
            1,
            "On the samples each variant was trained on (fit), mean Euclidean error (mm):\n\n"
            + studies.family_table(result["fit"]),
        )
    if "levels" in result:
        sections.insert(
            0,
            "Levels: "
            + "; ".join(
                f"{f}x: {lv['vertices']:.0f} vertices on average, measured linear factor {lv['linear_factor']:.2f}"
                for f, lv in result["levels"].items()
            ),
        )
    if "garsim_over_deepsd" in result:
        sections.append(
            "GarSim's error over the DeePSD-style baseline's (the paper: at most 0.5):\n\n"
            + "\n".join(
                f"- {res}: " + ", ".join(f"{k} {v:.2f}" for k, v in per.items())
                for res, per in result["garsim_over_deepsd"].items()
            )
        )
    if result.get("external"):
        sections.append("External set (`check.py`, API defaults):\n\n" + studies.external_table(result["external"]))
    return result, sections


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    result, sections = run(args)
    out = Path(args.out)
    command = shlex.join(["python", "examples/experiments.py", *(sys.argv[1:] if argv is None else argv)])
    atomic_write(out / f"{args.study}.json", lambda p: Path(p).write_text(json.dumps(result, indent=1)))
    text = "\n\n".join([f"# {TITLES[args.study]}", f"`{command}`", *sections]) + "\n"
    atomic_write(out / f"{args.study}.md", lambda p: Path(p).write_text(text))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
