"""How strapped garments hang: the parametric tops and dresses are held by their bodice's top ring
(``garments/templates/builders.py: _band_pins``), so their straps carry no load and slide on the shoulders. This runs
the first template tops and dresses of a generation plan (training split, unpaired, under 900 vertices) through the
generator's own ``simulate_job`` in three pin set-ups: the band pins; no pins at all (the garment hangs on its straps
by contact and friction); pins where the straps cross the shoulders, skinned by the torso alone (``crest``). Per run:
accepted or the rejection, and per settled target the mean error of the skinning prior against the simulation (mm)
overall and in the template's top height quartile (straps and neckline), the bodice's mean drop below the prior (mm)
and the CPU seconds. ``--families tshirt`` tries the crest pins on the parametric t-shirts too (pinned across the
middle of their shoulder panels, ``_strap_pins``, and skinned by every bone in the generator).

    .venv/bin/python examples/strap_support.py --json docs/studies/anatomy/strap_support.json   # ~10 CPU minutes
"""

import argparse
import json
import time
from dataclasses import replace
from unittest import mock

import numpy as np

from garsim.physics import generate
from garsim.physics.generate import GenerateConfig, JobSpec, plan_jobs, simulate_job

VARIANTS = ("band", "none", "crest")
"""Pin set-ups: ``GenerateConfig.strap_pins`` "band" and "crest", and "none" (every pin released)."""


def jobs(
    config: GenerateConfig, per_family: int, max_vertices: int, families: tuple[str, ...], skip: int = 0
) -> list[JobSpec]:
    """The unpaired template jobs of each of ``families`` in the training split under ``max_vertices``, after the
    first ``skip`` of each family, ``per_family`` of each, family by family."""
    picked: dict[str, list[JobSpec]] = {f: [] for f in families}
    for job in plan_jobs(config):
        if job.split == "train" and not job.paired and job.construction == "template" and job.vertices < max_vertices:
            if job.family in picked:
                picked[job.family].append(job)
    return [j for f in families for j in picked[f][skip : skip + per_family]]


def unpinned(build):
    """``build_garment`` with every pin released."""

    def build_free(job, body, strap_pins):
        g = build(job, body, strap_pins)
        g.pinned[:] = False
        return g

    return build_free


def run(job: JobSpec, config: GenerateConfig, variant: str) -> dict:
    """One job under one pin variant: acceptance and the prior's error against each settled target."""
    t = time.process_time()
    free = variant == "none"
    patch = mock.patch.object(generate, "build_garment", unpinned(generate.build_garment)) if free else None
    if variant == "crest" and job.family not in generate.STRAPPED_FAMILIES:  # crest pins tried on another family
        patch = mock.patch.object(generate, "STRAPPED_FAMILIES", generate.STRAPPED_FAMILIES | {job.family})
    try:
        if patch:
            patch.start()
        records, rejections = simulate_job(job, replace(config, strap_pins="band" if free else variant))
    except Exception as exc:  # noqa: BLE001 - a rejected template is a result here
        return {"job": job.job_id, "family": job.family, "variant": variant, "rejected": f"{type(exc).__name__}: {exc}"}
    finally:
        if patch:
            patch.stop()
    row = {"job": job.job_id, "family": job.family, "variant": variant, "cpu_s": time.process_time() - t}
    row["rejections"] = [f"{r['reason']}: {r['detail']}" for r in rejections]
    targets = []
    for rec in records:
        lv = rec.levels["full"]
        z = lv.template[:, 2]
        top = z >= np.quantile(z, 0.75)
        for prior, gt in zip(lv.priors, lv.targets):
            e = 1000 * np.linalg.norm(gt - prior, axis=1)
            targets.append(
                {
                    "prior_mm": float(e.mean()),
                    "prior_top_quartile_mm": float(e[top].mean()),
                    "drop_mm": float(1000 * (prior[~top, 2] - gt[~top, 2]).mean()),
                }
            )
    row["targets"] = targets
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", required=True)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--per-family", type=int, default=3)
    parser.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    parser.add_argument("--max-vertices", type=int, default=900, help="skip larger garments (cheaper runs)")
    parser.add_argument("--families", nargs="+", choices=("top", "dress", "tshirt"), default=["top", "dress"])
    parser.add_argument("--train-jobs", type=int, default=600, help="training jobs of the plan drawn from")
    parser.add_argument("--skip", type=int, default=0, help="leave out the first N jobs of each family (resume)")
    args = parser.parse_args()
    config = GenerateConfig(out="unused", seed=args.seed, num_train=args.train_jobs)
    rows = []
    for job in jobs(config, args.per_family, args.max_vertices, tuple(args.families), args.skip):
        for variant in args.variants:
            rows.append(run(job, config, variant))
            print(json.dumps(rows[-1]), flush=True)
    with open(args.json, "w") as f:
        json.dump(rows, f, indent=1)
    for variant in args.variants:
        for family in args.families:
            mine = [r for r in rows if r["variant"] == variant and r["family"] == family]
            ok = sum("rejected" not in r and not r["rejections"] for r in mine)
            print(f"{variant} {family}: {ok} of {len(mine)} jobs accepted")


if __name__ == "__main__":
    main()
