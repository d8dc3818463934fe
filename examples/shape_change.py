"""A garment draped onto another body shape: the simulator against the prior, the raw network and the API's defaults.

Every training sample keeps its job's body shape (the canonical and target bodies share one phenotype), yet the API
takes any target body of the canonical body's topology. Here a test sample's settled template is simulated, with the
generator's simulator and the dataset's settings, onto the same body with one phenotype value moved by ``--delta``
towards the other end of its range (weight, height): first in the canonical pose (the shape alone: the body morphs
linearly over one motion), then on into the sample's own target pose (shape and pose). A ``control`` row runs the
same two segments without a change of shape: its states are what the shape rows are read against
(``stored_truth_vs_pose_state_mm``: how far its pose state lies from the stored ground truth, which was simulated in
one motion, at full resolution, with the pins skinned by the known pose). ``--resolution low`` simulates the stored
low-resolution mesh (~4x faster). Pinned vertices follow the API's prior in the simulation and in every drape.
``prior_rigfree`` is the API's rig-free prior (what a body in another vertex order or topology gets).

Rows are appended to ``--out`` (JSON lines) as they finish; a rerun skips the rows already there.

Run: OMP_NUM_THREADS=1 .venv/bin/python examples/shape_change.py --data ~/garsim-data/v5test --per-family 2 \
         --resolution low --out docs/studies/shape_change/v5test_low.jsonl
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from garsim.api import GarSim, make_sample
from garsim.bodies.anny import AnnyBody
from garsim.bodies.poses import batched_matrices, interpolate_poses, stack_poses
from garsim.data.store import DatasetStore
from garsim.garments.fabrics import fabric_from_values, get_fabric
from garsim.geometry.inside import inside_mask
from garsim.geometry.mesh import edge_lengths
from garsim.physics.generate import CONFIG_FILE, GenerateConfig, _arm_pose
from garsim.physics.newton_sim import SimConfig, SimulationRejected, check_result, simulate_poses

CHANGES = ("control", "weight", "height")
BODY_TOLERANCE = 1e-4  # m: the rebuilt Anny body must be the stored one


def moved_phenotype(phenotype: dict[str, float], key: str, delta: float) -> dict[str, float]:
    """``phenotype`` with ``key`` moved by ``delta`` towards the far end of [0, 1] (unchanged for ``control``)."""
    out = dict(phenotype)
    if key != "control":
        out[key] = round(out[key] + (delta if out[key] < 0.5 else -delta), 4)
    return out


def mean_error_mm(x: np.ndarray, truth: np.ndarray) -> float:
    return 1000.0 * float(np.linalg.norm(np.asarray(x, np.float64) - truth, axis=1).mean())


def pick_samples(store: DatasetStore, per_family: int, resolution: str) -> list:
    """The first ``per_family`` test samples of distinct jobs in each family."""
    picked, jobs, count = [], set(), defaultdict(int)
    for s in store.samples("test", resolution):
        if count[s.garment_type] < per_family and s.meta["job"] not in jobs:
            picked.append(s)
            jobs.add(s.meta["job"])
            count[s.garment_type] += 1
    return picked


def simulate(s, body: AnnyBody, target_pose: dict, sim_cfg: SimConfig, frames: int, fabric) -> tuple:
    """(shape state, shape-and-pose state, info) of the template moved onto ``body``: a linear morph from the
    sample's canonical body to ``body`` in the canonical pose, then the pose motion on ``body``."""
    arm_pose = _arm_pose(float(s.meta["canonical_arm"]))
    canonical = body.pose(arm_pose).vertices
    w = np.linspace(0.0, 1.0, frames + 1)[:, None, None]
    morph = (1.0 - w) * s.body_canonical[None] + w * canonical[None]
    motion = body.pose_batch(batched_matrices(stack_poses(interpolate_poses(arm_pose, target_pose, frames + 1))))[0]
    garment = (s.garment, s.garment_faces)
    pins = [
        np.stack(
            [
                make_sample((s.body_canonical, s.body_faces), (b, s.body_faces), garment, pinned=s.pinned).prior[
                    s.pinned
                ]
                for b in seg
            ]
        )
        for seg in (morph, motion)
    ]
    states, infos = simulate_poses(
        s.garment, s.garment_faces, s.pinned, [morph, motion], s.body_faces, pins, [fabric], sim_cfg
    )
    rest = edge_lengths(s.garment, s.garment_faces)
    for k, (state, info) in enumerate(zip(states, infos)):
        if not info.get("settled"):
            raise SimulationRejected("unsettled", f"segment {k}: mean speed {info.get('final_speed')} m/s")
        body_k = canonical if k == 0 else motion[-1]
        check_result(state[0], s.garment_faces, rest, body_k, s.body_faces, pinned=s.pinned)
    if len(states) < 2:
        raise SimulationRejected(infos[-1].get("aborted") or "aborted", "the chain stopped")
    return states[0][0].astype(np.float64), states[1][0].astype(np.float64), canonical, motion[-1]


METHODS = ("template", "prior", "prior_rigfree", "raw", "defaults")


def summary(rows: list[dict]) -> str:
    """Markdown tables of the rows: mean error (mm) of each method per change and case, and per family."""
    lines = []
    for case in ("shape", "shape_pose"):
        lines += [
            f"**{case}** (mean error against the simulation, mm; samples with every change simulated)",
            "",
            "| change | n | " + " | ".join(METHODS) + " | raw / prior | defaults / prior |",
            "|---|---|" + "---|" * (len(METHODS) + 2),
        ]
        done = defaultdict(set)
        for r in rows:
            if "rejected" not in r:
                done[r["sample"]].add(r["change"])
        complete = {name for name, changes in done.items() if changes >= set(CHANGES)}
        for change in CHANGES:
            sel = [r for r in rows if r["change"] == change and r["sample"] in complete]
            if not sel:
                continue
            keys = {m: f"{case}/{m}_mm" for m in METHODS}  # a method is shown where every row has it
            mean = {m: np.mean([r[k] for r in sel]) if all(k in r for r in sel) else np.nan for m, k in keys.items()}
            cells = " | ".join("-" if np.isnan(mean[m]) else f"{mean[m]:.1f}" for m in METHODS)
            lines.append(
                f"| {change} | {len(sel)} | {cells} | {mean['raw'] / mean['prior']:.2f} | "
                f"{mean['defaults'] / mean['prior']:.2f} |"
            )
        lines.append("")
    lines += ["| sample | family | change | " + " | ".join(f"{m} (shape / pose)" for m in METHODS) + " |"]
    lines += ["|---|---|---|" + "---|" * len(METHODS)]
    for r in rows:
        if "rejected" in r:
            lines.append(f"| {r['sample']} | {r['family']} | {r['change']} | rejected: {r['rejected']} |")
            continue
        cells = " | ".join(
            " / ".join(f"{r[k]:.1f}" if k in r else "-" for k in (f"shape/{m}_mm", f"shape_pose/{m}_mm"))
            for m in METHODS
        )
        lines.append(f"| {r['sample']} | {r['family']} | {r['change']} | {cells} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True, help="a garsim dataset folder with a test split")
    parser.add_argument("--per-family", type=int, default=2, help="test samples (distinct jobs) per family")
    parser.add_argument("--delta", type=float, default=0.3, help="phenotype change (Anny's 0..1 scale)")
    parser.add_argument("--changes", nargs="+", default=list(CHANGES), choices=CHANGES)
    parser.add_argument(
        "--resolution", default="full", choices=("full", "low"), help="the simulated mesh (full: the stored truth's)"
    )
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--out", required=True, help="JSON lines file (appended; rows already there are skipped)")
    parser.add_argument("--summary", action="store_true", help="print the tables of the rows in --out and stop")
    args = parser.parse_args()
    if args.summary:
        print(summary([json.loads(line) for line in Path(args.out).read_text().splitlines()]))
        return

    config_file = Path(args.data) / CONFIG_FILE  # the generator's settings (a committed fixture has none: defaults)
    settings = json.loads(config_file.read_text()) if config_file.exists() else {}
    sim_cfg = SimConfig(**settings.get("sim", {}))
    frames = int(settings.get("motion_frames", GenerateConfig.motion_frames))
    load = (lambda **o: GarSim.load(args.model, **o)) if args.model else GarSim.pretrained
    methods = {"prior": GarSim.prior_only(), "raw": load(collision_margin=None), "defaults": load()}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = (
        {(r["sample"], r["change"]) for r in map(json.loads, out.read_text().splitlines())} if out.exists() else set()
    )
    for s in pick_samples(DatasetStore(args.data), args.per_family, args.resolution):
        name, phenotype = s.meta["name"], s.meta["phenotype"]
        target_pose = {b: np.asarray(v) for b, v in s.meta["target_poses"][int(s.meta["frame"])].items()}
        fabric = fabric_from_values(s.fabric_values, s.fabric) if s.fabric_values else get_fabric(s.fabric)
        user_fabric = dict(s.fabric_values) if s.fabric_values else s.fabric
        rebuilt = AnnyBody(phenotype).pose(target_pose).vertices
        if np.abs(rebuilt - s.body_target).max() > BODY_TOLERANCE:
            print(f"{name}: Anny does not rebuild the stored target body; skipped", flush=True)
            continue
        for change in args.changes:
            if (name, change) in done:
                continue
            moved = moved_phenotype(phenotype, change, args.delta)
            row = {"sample": name, "family": s.garment_type, "change": change, "phenotype": moved}
            try:
                shape_gt, pose_gt, canonical, target = simulate(
                    s, AnnyBody(moved), target_pose, sim_cfg, frames, fabric
                )
            except SimulationRejected as exc:
                row["rejected"] = f"{exc.reason}: {exc.detail.splitlines()[0]}"
            else:
                # the bodies in another vertex order get the API's rig-free prior (Anny's order: the recovered bones)
                order = np.random.default_rng(0).permutation(len(s.body_canonical))
                reordered = np.argsort(order)[s.body_faces]
                for case, body, truth in (("shape", canonical, shape_gt), ("shape_pose", target, pose_gt)):
                    for method, sim in (*methods.items(), ("prior_rigfree", methods["prior"])):
                        bodies = ((s.body_canonical, s.body_faces), (body, s.body_faces))
                        if method == "prior_rigfree":
                            bodies = ((s.body_canonical[order], reordered), (body[order], reordered))
                        pred = sim.drape(*bodies, (s.garment, s.garment_faces), fabric=user_fabric, pinned=s.pinned)
                        row[f"{case}/{method}_mm"] = round(mean_error_mm(pred, truth), 3)
                        row[f"{case}/{method}_inside_pct"] = round(
                            100.0 * float(inside_mask(pred, body, s.body_faces).mean()), 3
                        )
                    row[f"{case}/template_mm"] = round(mean_error_mm(s.garment, truth), 3)
                row["stored_truth_vs_pose_state_mm"] = round(mean_error_mm(pose_gt, s.target), 3)
            print(json.dumps(row), flush=True)
            with out.open("a") as f:
                f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
