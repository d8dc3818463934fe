"""Encoders of the paper's Sec. 3.2: geometry (PointNet++-style), body semantic, garment/body-aware, node, edge."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from garsim.model.config import SURFACE_FEATURES, GarSimConfig

_ACTIVATIONS = {"relu": nn.ReLU, "silu": nn.SiLU, "gelu": nn.GELU}


def activation(name: str) -> nn.Module:
    """An activation module by name (relu, silu, gelu)."""
    try:
        return _ACTIVATIONS[name]()
    except KeyError:
        raise ValueError(f"unknown activation {name!r}; choose one of {sorted(_ACTIVATIONS)}") from None


class MLP(nn.Sequential):
    """Linear -> act (x ``layers`` hidden) -> Linear, optionally followed by LayerNorm (as MeshGraphNets)."""

    def __init__(self, d_in: int, d_hidden: int, d_out: int, layers: int = 1, act: str = "silu", norm: bool = True):
        mods: list[nn.Module] = []
        d = d_in
        for _ in range(layers):
            mods += [nn.Linear(d, d_hidden), activation(act)]
            d = d_hidden
        mods.append(nn.Linear(d, d_out))
        if norm:
            mods.append(nn.LayerNorm(d_out))
        super().__init__(*mods)


class GeometryEncoder(nn.Module):
    """PointNet++ set abstraction over a k-neighbourhood: shared MLP on relative positions, max-pooled.

    One instance is shared by garment points and body points (Sec. 3.2: "using the same
    geometry encoder"). Input (N, k, 3) relative positions -> (N, geo_out).
    """

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.scale = float(cfg.pos_scale)
        self.mlp = nn.Sequential(
            nn.Linear(3, cfg.geo_hidden),
            activation(cfg.activation),
            nn.Linear(cfg.geo_hidden, cfg.geo_out),
            activation(cfg.activation),
        )

        self.pool_first = cfg.activation == "relu"  # relu is monotonic: max(relu(x)) = relu(max(x))

    def forward(self, rel: torch.Tensor) -> torch.Tensor:
        lin1, act1, lin2, act2 = self.mlp
        h = act1(F.linear(rel, lin1.weight * self.scale, lin1.bias))  # scale folded into the weights
        h = lin2(h)
        if self.pool_first:  # pool before the last activation: k times fewer activations, same result
            return act2(h.amax(dim=1))
        return act2(h).amax(dim=1)


class BodySemanticEncoder(nn.Module):
    """MLP from the body-semantic mask (per graph) to the latent body-semantic vector S."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.mlp = MLP(cfg.semantic_input_dim, cfg.mlp_hidden, cfg.semantic_dim, cfg.mlp_layers, cfg.activation)

    def forward(self, mask: torch.Tensor) -> torch.Tensor:
        return self.mlp(mask)


class GarmentAwareEncoder(nn.Module):
    """(X^gar, f, p, p^prior) -> χ."""

    def __init__(self, cfg: GarSimConfig, num_fabrics: int = 4):
        super().__init__()
        self.scale = float(cfg.pos_scale)
        self.mlp = MLP(cfg.geo_out + num_fabrics + 6, cfg.mlp_hidden, cfg.latent, cfg.mlp_layers, cfg.activation)

    def forward(
        self, x_gar: torch.Tensor, fabric: torch.Tensor, p: torch.Tensor, p_prior: torch.Tensor
    ) -> torch.Tensor:
        return self.mlp(torch.cat([x_gar, fabric, p * self.scale, p_prior * self.scale], dim=-1))


class BodyAwareEncoder(nn.Module):
    """(X^body at q, δ, S) -> μ."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.scale = float(cfg.pos_scale)
        self.mlp = MLP(cfg.geo_out + 3 + cfg.semantic_dim, cfg.mlp_hidden, cfg.latent, cfg.mlp_layers, cfg.activation)

    def forward(self, x_body: torch.Tensor, delta: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        return self.mlp(torch.cat([x_body, delta * self.scale, s], dim=-1))


class NodeEncoder(nn.Module):
    """(χ, μ) -> η."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.mlp = MLP(2 * cfg.latent, cfg.mlp_hidden, cfg.latent, cfg.mlp_layers, cfg.activation)

    def forward(self, chi: torch.Tensor, mu: torch.Tensor) -> torch.Tensor:
        return self.mlp(torch.cat([chi, mu], dim=-1))


class EdgeEncoder(nn.Module):
    """(E, E^prior) -> π."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.scale = float(cfg.pos_scale)
        self.mlp = MLP(6, cfg.edge_latent, cfg.edge_latent, cfg.mlp_layers, cfg.activation, cfg.edge_layer_norm)

    def forward(self, edge_attr: torch.Tensor) -> torch.Tensor:
        return self.mlp(edge_attr * self.scale)


class TargetSurfaceEncoder(nn.Module):
    """``GarSimConfig.target_surface``: (offset, normal, signed distance) on the target body -> a term added to η.
    Its last layer starts at zero, so a model widened by it (``GraphModel.widened``) starts as it was."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.register_buffer("scale", torch.tensor(cfg.surface_scale), persistent=False)
        self.mlp = MLP(SURFACE_FEATURES, cfg.mlp_hidden, cfg.latent, cfg.mlp_layers, cfg.activation, norm=False)
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, surface: torch.Tensor) -> torch.Tensor:
        return self.mlp(surface * self.scale)
