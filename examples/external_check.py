"""Run the external check set (../shared/external-eval/check.py) on a model with API options of your choice,
e.g. the raw network (no push-out) or with physical refinement, through the public API as the checker does.

Run: .venv/bin/python examples/external_check.py --model garsim/weights --raw --json docs/external_raw.json
     .venv/bin/python examples/external_check.py --model garsim/weights --refine --json docs/external_refine.json
     .venv/bin/python examples/external_check.py --prior-only --refine --json docs/external_prior_refine.json
(``--prior-only``: the checker's own prior-only run, ``GarSim.prior_only()``; with ``--refine`` the "prior + refine"
baseline.)
"""

from __future__ import annotations

import argparse
import runpy
import sys
from pathlib import Path

from garsim import GarSim


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--model", help="a trained model folder (GarSim.load)")
    group.add_argument("--prior-only", action="store_true", help="the skinning prior in the model's place")
    parser.add_argument("--raw", action="store_true", help="the network alone: collision_margin=None")
    parser.add_argument("--refine", action="store_true", help="GarSim(refine=True)")
    parser.add_argument("--json", required=True)
    parser.add_argument(
        "--checker", default=str(Path(__file__).resolve().parents[1].parent / "shared/external-eval/check.py")
    )
    args = parser.parse_args()
    options = {"collision_margin": None} if args.raw else {}
    if args.refine:
        options["refine"] = True
    if args.prior_only:
        refine = bool(options.get("refine"))
        GarSim.prior_only = classmethod(lambda cls, **kw: cls(model=None, **{"refine": refine, **kw}))  # type: ignore[method-assign]
        sys.argv = [args.checker, "--prior-only", "--json", args.json]
    else:
        load = GarSim.load
        GarSim.load = classmethod(lambda cls, d, **kw: load.__func__(cls, d, **{**options, **kw}))  # type: ignore[method-assign]
        sys.argv = [args.checker, "--model", args.model, "--json", args.json]
    runpy.run_path(args.checker, run_name="__main__")


if __name__ == "__main__":
    main()
