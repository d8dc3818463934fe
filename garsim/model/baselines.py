"""Baselines and ablation variants: the LBS prior alone, and GarSim with other heads / no message passing."""

from __future__ import annotations

from dataclasses import replace

import torch
from torch import nn
from torch_geometric.data import Data

from garsim.model.config import GarSimConfig
from garsim.model.garsim import GarSimModel

ABLATIONS: tuple[str, ...] = ("full", "displacement", "position", "no_message_passing")


class PriorBaseline(nn.Module):
    """Predicts the LBS deformation prior G^prior itself (the paper's 'prior' row)."""

    def forward(self, data: Data) -> torch.Tensor:
        return data.prior


def ablation_config(name: str, base: GarSimConfig | None = None) -> GarSimConfig:
    """Config of an ablation variant (Sec. 4.2): 'full', 'displacement', 'position', 'no_message_passing'."""
    cfg = base or GarSimConfig()
    if name == "full":
        return replace(cfg)
    if name in ("displacement", "position"):
        return replace(cfg, head=name)
    if name == "no_message_passing":
        return replace(cfg, num_steps=0)
    raise ValueError(f"unknown ablation {name!r}; choose one of {ABLATIONS}")


def make_ablation(name: str, base: GarSimConfig | None = None) -> GarSimModel:
    """A fresh GarSimModel for an ablation variant."""
    return GarSimModel(ablation_config(name, base))
