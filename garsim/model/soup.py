"""Weight-space averages of models fine-tuned from one another (a "model soup"; WiSE-FT, Wortsman et al. 2022):
the average of a model and its fine-tune keeps part of what the fine-tune gained at less cost to what the model
already did well (docs/studies/soups.md), and runs as fast as either (one set of weights)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from garsim.model.baselines import load_model
from garsim.model.garsim import GraphModel


def average_models(directories: Sequence[str | Path], weights: Sequence[float]) -> GraphModel:
    """The saved models of ``directories`` (one kind and config) averaged tensor by tensor with ``weights``
    (non-negative, summing to 1). Raises ValueError naming what differs."""
    if len(directories) < 2 or len(directories) != len(weights):
        raise ValueError(f"give two or more models and one weight each (got {len(directories)} and {len(weights)})")
    if any(not math.isfinite(w) or w < 0 for w in weights) or abs(sum(weights) - 1.0) > 1e-6:
        raise ValueError(f"the weights must be non-negative and sum to 1, got {list(weights)}")
    models = [load_model(d) for d in directories]
    first = models[0]
    for d, m in zip(directories[1:], models[1:]):
        if m.kind != first.kind or m.config != first.config:
            raise ValueError(
                f"{d} is not the model of {directories[0]} (kind or config differs): they cannot be averaged"
            )
    states = [m.state_dict() for m in models]  # every tensor a float weight (GarSim and DeePSD have no buffers)
    first.load_state_dict(
        {k: sum(w * s[k].double() for w, s in zip(weights, states)).to(v.dtype) for k, v in states[0].items()}
    )
    return first
