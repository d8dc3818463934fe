"""Decoder (Sec. 3.4): per-vertex unit direction d̂ and non-negative magnitude m, Ḡ = G^prior + d̂ m.

Alternative heads for the paper's ablation (Sec. 4.2, Table 2): ``"displacement"`` predicts
d directly (Ḡ = G^prior + d); ``"position"`` predicts the vertex position directly, without
the prior. So that the prediction stays translation/yaw equivariant, the direct position is
expressed relative to the anchor B̄_q (the target-body vertex under the template vertex's
nearest canonical one): Ḡ = B̄_q + x. All vectors come out in the body frame and are
rotated back to the world by the model.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from garsim.model.config import FABRIC_FEATURES, GarSimConfig
from garsim.model.encoders import MLP


class Decoder(nn.Module):
    """Node latents -> a 3-vector per vertex in the body frame (metres), per the configured head."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.head = cfg.head
        self.scale = float(cfg.pos_scale)
        d_out = 4 if cfg.head == "direction_magnitude" else 3
        self.mlp = MLP(cfg.latent, cfg.mlp_hidden, d_out, cfg.mlp_layers, cfg.activation, norm=False)
        # log-scale of the magnitude (only the direction + magnitude head has one)
        self.fabric_gain = (
            nn.Linear(FABRIC_FEATURES, 1) if cfg.fabric_film and cfg.head == "direction_magnitude" else None
        )
        # per-channel scale/shift of the node latents by the fabric (zero-initialised): the processor's FiLM acts on
        # the edge updates, whose scale the node update's LayerNorm takes out again; here nothing normalises it away
        self.fabric_film = nn.Linear(FABRIC_FEATURES, 2 * cfg.latent) if cfg.fabric_decoder_film else None
        for lin in (self.fabric_gain, self.fabric_film):
            if lin is not None:
                nn.init.zeros_(lin.weight)
                nn.init.zeros_(lin.bias)
        last = self.mlp[-1]
        with torch.no_grad():
            last.weight.mul_(0.1)
            last.bias.zero_()
            if cfg.head == "direction_magnitude":
                last.bias[3] = cfg.magnitude_bias_init  # start near the prior (softplus(-3)/10 = 5 mm)

    def forward(
        self, node: torch.Tensor, fabric: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
        """Return (vector, direction, magnitude); direction/magnitude are None for the alternative heads."""
        if self.fabric_film is not None and fabric is not None:
            scale, shift = self.fabric_film(fabric).chunk(2, dim=-1)
            node = node * (1.0 + scale) + shift
        out = self.mlp(node)
        if self.head == "direction_magnitude":
            direction = F.normalize(out[:, :3], dim=-1, eps=1e-8)
            magnitude = F.softplus(out[:, 3:4]) / self.scale
            if self.fabric_gain is not None and fabric is not None:
                magnitude = magnitude * torch.exp(self.fabric_gain(fabric))
            return direction * magnitude, direction, magnitude[:, 0]
        return out / self.scale, None, None
