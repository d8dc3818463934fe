"""Mirror averaging at test time (docs/studies/soups.md): the raw network's prediction of each sample averaged with
its prediction of the mirrored sample (``garsim.train.augment.mirror_sample``), mirrored back.

Run: .venv/bin/python examples/mirror_tta.py test --model garsim/weights --data ~/garsim-data/v4test --json t.json
     .venv/bin/python examples/mirror_tta.py external --model garsim/weights --json e.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import runpy
import sys
from pathlib import Path
from typing import Any

import numpy as np

from garsim import GarSim
from garsim.data.sample import Sample
from garsim.eval.experiments import evaluate_split
from garsim.model.baselines import load_model
from garsim.train.augment import mirror_sample


class MirrorAveraged:
    """A model whose prediction is the mean of ``model``'s on the sample and, mirrored back, on its mirror image."""

    def __init__(self, model: Any) -> None:
        self.model, self.config = model, model.config

    def _one(self, sample: Sample) -> np.ndarray:
        mirrored = mirror_sample(sample)
        back = mirror_sample(dataclasses.replace(mirrored, target=self.model.predict(mirrored))).target
        return (0.5 * (self.model.predict(sample) + back)).astype(np.float32)

    def predict(self, sample: Sample | list[Sample]) -> np.ndarray | list[np.ndarray]:
        return self._one(sample) if isinstance(sample, Sample) else [self._one(s) for s in sample]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("where", choices=("test", "external"))
    parser.add_argument("--model", default="garsim/weights")
    parser.add_argument("--data", help="dataset folder (test)")
    parser.add_argument("--json", required=True)
    parser.add_argument(
        "--checker", default=str(Path(__file__).resolve().parents[1].parent / "shared/external-eval/check.py")
    )
    args = parser.parse_args()
    if args.where == "test":
        model = load_model(args.model)
        scores = {
            label: evaluate_split(m, args.data, "test", collision_margin=None, baselines=False)["garsim"]["all"]
            for label, m in (("plain", model), ("mirror", MirrorAveraged(model)))
        }
        Path(args.json).write_text(json.dumps(scores, indent=1))
        for label, s in scores.items():
            print(f"{label}: {s['euclidean_mm']:.2f} mm, raw inside {s['inside_pct']:.2f}%")
        return
    load = GarSim.load

    def averaged(cls: type[GarSim], directory: str, **kw: Any) -> GarSim:  # the raw network, mirror-averaged
        sim = load.__func__(cls, directory, **{"collision_margin": None, **kw})
        sim.model = MirrorAveraged(sim.model)
        return sim

    GarSim.load = classmethod(averaged)  # type: ignore[method-assign, assignment]
    sys.argv = [args.checker, "--model", args.model, "--json", args.json]
    runpy.run_path(args.checker, run_name="__main__")


if __name__ == "__main__":
    main()
