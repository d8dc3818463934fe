"""The ``garsim`` command line: thin wrappers that parse, call the library, and report."""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from pathlib import Path

from garsim.atomic import atomic_write_bytes
from garsim.data.sample import FABRICS


def _shard(text: str) -> tuple[int, int]:
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--shard must look like K/N (e.g. 0/4), got {text!r}") from None
    if not (n >= 1 and 0 <= k < n):
        raise argparse.ArgumentTypeError(f"--shard K/N needs 0 <= K < N, got {text!r}")
    return k, n


def _write_json(path: str | Path, obj: object) -> Path:
    return atomic_write_bytes(path, json.dumps(obj, indent=1).encode())


def cmd_demo(args: argparse.Namespace) -> int:
    from garsim.demo import DemoConfig, run_demo

    outputs = run_demo(
        DemoConfig(out=Path(args.out), seed=args.seed, target_vertices=args.vertices, frames=args.frames)
    )
    for path in outputs:
        print(path)
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from garsim.view import ViewerUnavailable, serve

    try:
        serve(args.path, host=args.host, port=args.port, block=True)
    except ViewerUnavailable as exc:
        print(exc, file=sys.stderr)
        return 2
    return 0


def cmd_drape(args: argparse.Namespace) -> int:
    import numpy as np

    from garsim.api import GarSim
    from garsim.geometry.io import load_mesh, save_mesh

    sim = GarSim.pretrained() if not args.prior_only else GarSim.prior_only()
    garment = load_mesh(args.garment)
    pinned = np.loadtxt(args.pinned, dtype=np.int64, ndmin=1) if args.pinned else None
    verts = sim.drape(
        args.canonical, args.target, garment, fabric=args.fabric, pinned=pinned, up=args.up, units=args.units
    )
    save_mesh(args.out, verts, garment[1], y_up=args.y_up)
    print(args.out)
    if args.png:
        from garsim.geometry.render import render_views

        print(render_views(args.png, [load_mesh(args.target), (verts, garment[1])]))
    return 0


def cmd_animate(args: argparse.Namespace) -> int:
    import numpy as np

    from garsim.api import GarSim
    from garsim.export import SUPPORTED_EXTENSIONS, export_animation
    from garsim.geometry.io import as_mesh, load_mesh

    out = Path(args.out)
    if out.suffix.lower() not in SUPPORTED_EXTENSIONS:  # checked before any work
        raise ValueError(
            f"cannot write {out.suffix or 'a file without extension'!r}; use one of {', '.join(SUPPORTED_EXTENSIONS)}"
        )
    garment = load_mesh(args.garment)
    if args.motion:
        from garsim.bodies.anny import AnnyBody
        from garsim.bodies.poses import batched_matrices, motion, stack_poses

        body = AnnyBody()
        canonical = (body.canonical().vertices, body.faces)
        targets = list(body.pose_batch(batched_matrices(stack_poses(motion(args.motion, args.frames))))[0])
        faces = body.faces
    else:
        if not (args.canonical and args.targets):
            raise ValueError(
                "give --motion NAME (the default Anny body), or --canonical and --targets (a folder of "
                "body OBJs or an .npz with an array 'vertices' of shape (T, V, 3))"
            )
        canonical = as_mesh(args.canonical, "canonical body")
        faces = canonical[1]
        src = Path(args.targets)
        if src.is_dir():
            targets = [load_mesh(p)[0] for p in sorted(src.glob("*.obj"))]
        else:
            with np.load(src, allow_pickle=False) as z:
                targets = list(z["vertices"])
    sim = GarSim.prior_only() if args.prior_only else GarSim.pretrained()
    frames = sim.drape_sequence(canonical, targets, garment, fabric=args.fabric, progress=not args.quiet)
    written = export_animation(out, frames, garment[1], body_frames=np.stack(targets), body_faces=faces, fps=args.fps)
    for path in written:
        print(path)
    return 0


def cmd_data_generate(args: argparse.Namespace) -> int:
    from garsim.physics.generate import GenerateConfig, generate

    given = {
        "num_train": args.train,
        "num_test": args.test,
        "num_ood": args.ood,
        "min_vertices": args.min_vertices,
        "max_vertices": args.max_vertices,
        "targets_per_job": args.targets,
    }
    cfg = GenerateConfig(
        out=Path(args.out),
        seed=args.seed,
        workers=args.workers,
        shard=args.shard,
        limit=args.limit,
        **{k: v for k, v in given.items() if v is not None},
    )
    summary = generate(cfg, progress=not args.quiet)
    secs = summary.pop("seconds")
    if secs:
        summary["mean_seconds_per_sequence"] = round(sum(secs) / len(secs), 2)
    print(json.dumps(summary, indent=2))
    return 0


def cmd_data_info(args: argparse.Namespace) -> int:
    from garsim.data.store import DatasetStore

    info = DatasetStore(args.dir).info()
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(
        f"{info['root']}: {info['samples']} samples ({info['settled_samples']} settled) in {info['sequences']} "
        f"sequences of {info['garment_instances']} garment instances, {info['rejected_sequences']} rejected"
    )
    for key, n in info["samples_by"].items():
        print(f"  {key:40s} {n:6d} samples")
    for fam, f in info["per_family"].items():
        print(
            f"  {fam:12s} acceptance {f['acceptance_rate']:.0%} of {f['jobs']} jobs, "
            f"{f['cpu_seconds_per_settled_sample']:.1f} CPU s per settled sample"
        )
    return 0


def cmd_data_verify(args: argparse.Namespace) -> int:
    from garsim.data.store import DatasetStore

    problems = DatasetStore(args.dir).verify()
    for p in problems:
        print(p)
    print(f"{len(problems)} problem(s) found" if problems else "ok: every listed file is complete and intact")
    return 1 if problems else 0


def cmd_train(args: argparse.Namespace) -> int:
    from garsim.model.config import GarSimConfig
    from garsim.model.garsim import GarSimModel
    from garsim.train.data import train_val_samples
    from garsim.train.losses import LossWeights
    from garsim.train.trainer import TrainConfig, Trainer

    train, val = train_val_samples(args.data, resolution=args.resolution, val_every=args.val_every)
    init = GarSimModel.load(args.init) if args.init else None
    given = {
        "epochs": args.epochs,
        "batch_size": args.batch_size,
        "lr": args.lr,
        "seed": args.seed,
        "threads": args.threads,
    }
    losses = {"col": args.collision_weight, "eps": args.collision_eps}
    cfg = TrainConfig(
        out_dir=args.out,
        collision_start_epoch=args.collision_start,
        losses=LossWeights(**{k: v for k, v in losses.items() if v is not None}),
        progress=not args.quiet,
        resume=not args.restart,
        **{k: v for k, v in given.items() if v is not None},
    )
    print(f"training on {len(train)} samples, validating on {len(val)} ({args.resolution} resolution)")
    if int(os.environ.get("RANK", "0")) == 0:  # record which sequences this run saw (the store may grow later)
        ids = {name: sorted({s.meta["seq_id"] for s in part}) for name, part in (("train", train), ("val", val))}
        _write_json(Path(args.out) / "sequences.json", ids)
    model_config = init.config if init is not None else GarSimConfig(**({"head": args.head} if args.head else {}))
    history = Trainer(model_config, cfg, train, val, init=init).fit()
    if history:
        print(json.dumps(history[-1], indent=2))
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    from garsim.api import GarSim
    from garsim.eval.experiments import evaluate_split, format_table, paired_fabric_agreement

    sim = GarSim.load(args.model) if args.model else GarSim.default()
    report: dict = {"model": args.model or sim.name, "resolution": args.resolution}
    for split in args.splits:
        report[split] = evaluate_split(sim.model, args.data, split, args.resolution, refine=args.refine)
        print(f"## {split} split ({args.resolution} resolution)\n{format_table(report[split])}\n")
    if sim.model is not None:
        fab = paired_fabric_agreement(sim.model, args.data, resolution=args.resolution)
        report["paired_fabrics"] = fab
        print(
            f"paired-fabric groups (test): {fab['groups']}, ordering agreement {fab['ordering_agreement']} over "
            f"{fab['pairs_over_gap']} neighbouring pairs past the gap, spread ratio {fab['spread_ratio']}"
        )
    if args.out:
        print(_write_json(args.out, report))
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from garsim.api import GarSim
    from garsim.eval.bench import bench_inference, bench_newton, format_bench

    sim = GarSim.load(args.model) if args.model else GarSim.pretrained()
    report: dict = {"garsim": bench_inference(sim.model, args.sizes, repeats=args.repeats, garment=args.garment)}
    print(format_bench(report["garsim"]))
    paper_s = {600: 0.1, 2400: 1.0}  # the paper's reported inference times (Sec. 5)
    for n, r in report["garsim"].items():
        if n in paper_s:
            print(f"{n} v: {1000 * paper_s[n] / r['wall_ms']:.1f}x faster than the paper's {paper_s[n]} s")
    if args.newton:
        report["newton"] = bench_newton(args.sizes, garment=args.garment)
        for n, r in report["newton"].items():
            ratio = r["wall_ms"] / report["garsim"][n]["wall_ms"]
            print(f"{n} v: Newton {r['wall_ms'] / 1000:.1f} s ({r['frames']} frames) = {ratio:.0f}x GarSim's time")
    if args.out:
        print(_write_json(args.out, report))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="garsim", description=__doc__)
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser(
        "demo",
        help="drape six garment families on two body shapes in everyday poses; write OBJ, "
        "a PNG grid, and a walk animation as GLB, USDC and GIF",
    )
    p.add_argument("--out", default="demo_out", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the target poses")
    p.add_argument(
        "--vertices",
        type=int,
        default=800,
        help="garment resolution (vertices; the shipped model was trained at ~230 and tested at 800)",
    )
    p.add_argument("--frames", type=int, default=24, help="frames of the walk animation")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser(
        "view",
        help="interactive browser viewer of a drape or animation (needs garsim[view])",
        epilog="example: garsim view demo_out/walk_dress.npz  (then open http://127.0.0.1:8080)",
    )
    p.add_argument(
        "path",
        help="a .glb/.gltf written by garsim, an .npz with 'frames' and 'faces' (optional "
        "'body_frames', 'body_faces', 'prior_frames'), a .pc2, an OBJ, or a folder of OBJs",
    )
    p.add_argument("--port", type=int, default=8080, help="port (the next free one if taken)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (0.0.0.0: every interface)")
    p.set_defaults(func=cmd_view)

    p = sub.add_parser("drape", help="drape a garment mesh from a canonical body onto a target body")
    p.add_argument("--canonical", required=True, help="canonical body mesh (OBJ/PLY/GLB)")
    p.add_argument("--target", required=True, help="target body mesh, same topology as --canonical")
    p.add_argument("--garment", required=True, help="garment mesh draped on the canonical body")
    p.add_argument("--fabric", default="cotton", choices=FABRICS)
    p.add_argument("--pinned", help="text file of pinned garment vertex indices (optional)")
    p.add_argument("--out", required=True, help="output garment mesh path")
    p.add_argument("--png", help="also render target body + draped garment to this PNG")
    p.add_argument("--y-up", action="store_true", help="write the output Y-up (Blender/glTF)")
    p.add_argument("--up", choices=("z", "y"), default="z", help="up axis of the input meshes (Blender/glTF: y)")
    p.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="length unit of the input meshes")
    p.add_argument("--prior-only", action="store_true", help="use the skinning prior, not the model")
    p.set_defaults(func=cmd_drape)

    p = sub.add_parser(
        "animate",
        help="drape a garment over a pose sequence; write GLB, USD, PC2 (+OBJ), MP4 or GIF",
        epilog="example: garsim animate --garment skirt.obj --motion walk --out walk.glb",
    )
    p.add_argument("--garment", required=True, help="garment mesh draped on the canonical body")
    p.add_argument(
        "--motion", help="a motion of the library on the default Anny body: walk, raise_arms, turn, sit_down"
    )
    p.add_argument("--frames", type=int, default=30, help="frames of a --motion")
    p.add_argument("--canonical", help="canonical body mesh (with --targets)")
    p.add_argument("--targets", help="folder of target body OBJs (sorted by name) or an .npz with 'vertices' (T, V, 3)")
    p.add_argument("--fabric", default="cotton", choices=FABRICS)
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--out", required=True, help="output file: .glb/.gltf, .usd/.usda/.usdc, .pc2, .mp4 or .gif")
    p.add_argument("--prior-only", action="store_true", help="use the skinning prior, not the model")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_animate)

    p = sub.add_parser("train", help="train GarSim on a generated dataset (resumable; torchrun for DDP)")
    p.add_argument("--data", required=True, help="dataset folder made by `garsim data generate`")
    p.add_argument("--out", required=True, help="run folder: checkpoints, CSV log, best model")
    # unset values take TrainConfig's / LossWeights' defaults (garsim/train), declared once there
    p.add_argument("--epochs", type=int)
    p.add_argument("--batch-size", type=int)
    p.add_argument("--lr", type=float)
    p.add_argument("--seed", type=int)
    p.add_argument(
        "--resolution",
        choices=("low", "full", "both"),
        default="low",
        help="train on the ~4x decimated meshes (the paper's choice), the full ones, or both",
    )
    p.add_argument("--val-every", type=int, default=10, help="hold out every N-th training sequence")
    p.add_argument(
        "--collision-start",
        type=int,
        default=None,
        help="epoch that switches the collision loss on (default: when validation plateaus)",
    )
    p.add_argument("--collision-weight", type=float, help="α_col of Eq. 7 (the paper: 1)")
    p.add_argument("--collision-eps", type=float, help="ε of Eq. 6 in metres (margin kept off the body)")
    p.add_argument("--init", help="start from this trained model folder's weights (fine-tuning)")
    p.add_argument(
        "--head",
        choices=("direction_magnitude", "displacement", "position"),
        help="decoder head of a new model (default: GarSimConfig's, the paper's direction + magnitude)",
    )
    p.add_argument("--restart", action="store_true", help="ignore an existing checkpoint in --out")
    p.add_argument("--threads", type=int, help="torch threads per process")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("eval", help="the paper's metrics on a dataset split: GarSim vs the LBS prior")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--model", help="a trained model folder (default: the shipped model)")
    p.add_argument("--splits", nargs="+", default=["test", "ood"])
    p.add_argument("--refine", action="store_true", help="also score garsim+refine and prior+refine")
    p.add_argument("--resolution", choices=("low", "full"), default="low")
    p.add_argument("--out", help="write the results as JSON here")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("bench", help="end-to-end inference speed (one thread), optionally against Newton")
    p.add_argument("--model", help="a trained model folder (default: the shipped model)")
    p.add_argument("--sizes", type=int, nargs="+", default=[600, 2400], help="garment vertex counts")
    p.add_argument("--garment", default="skirt")
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument("--newton", action="store_true", help="also time the Newton simulation of the same drape")
    p.add_argument("--out", help="write the timings as JSON here")
    p.set_defaults(func=cmd_bench)

    data = sub.add_parser("data", help="ground-truth datasets").add_subparsers(dest="data_command", required=True)
    p = data.add_parser("generate", help="simulate a dataset with Newton (resumable)")
    p.add_argument("--out", required=True, help="dataset folder (outside the source tree)")
    p.add_argument("--seed", type=int, default=0)
    # unset values take physics.generate.GenerateConfig's defaults (not imported here: the simulator stays off the
    # CLI's inference path; `garsim data generate` prints the settings it used in DIR/config.json)
    p.add_argument("--train", type=int, help="training jobs (garment instances)")
    p.add_argument("--test", type=int, help="test jobs: unseen instances, bodies, poses")
    p.add_argument("--ood", type=int, help="out-of-distribution jobs: parameters outside every training range")
    p.add_argument("--min-vertices", type=int, help="garment resolution, lower end")
    p.add_argument("--max-vertices", type=int, help="garment resolution, upper end")
    p.add_argument("--targets", type=int, help="chained target poses per job, each settled")
    p.add_argument("--workers", type=int, default=2, help="parallel simulation processes")
    p.add_argument("--shard", type=_shard, default=(0, 1), help="K/N: run every N-th job from K")
    p.add_argument("--limit", type=int, help="stop after this many sequences (smoke runs)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_data_generate)
    p = data.add_parser("info", help="counts per split / family / fabric / pose, acceptance, cost, ranges")
    p.add_argument("dir")
    p.add_argument("--json", action="store_true", help="print everything as JSON")
    p.set_defaults(func=cmd_data_info)
    p = data.add_parser("verify", help="find missing, truncated or corrupt files")
    p.add_argument("dir")
    p.set_defaults(func=cmd_data_verify)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"garsim: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
