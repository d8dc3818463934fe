"""Processor: the paper's Algorithm 1 (L message-passing steps on the garment graph).

Each step: edge update Ψ_edge(π_k, η_{r_k}, η_{s_k}) for every edge, aggregation
Ω_edge->node of the updated edges at their receiver (mean, as the paper; any PyG
aggregation by name), node update Ψ_node(π̄'_i, η_i). Both updates are MLPs; as in
MeshGraphNets (Pfaff et al. 2021) each MLP ends in a LayerNorm and its output is added to
its input (residual connection); both can be switched off in the config.
"""

from __future__ import annotations

import torch
from torch import nn
from torch_geometric.nn.resolver import aggregation_resolver

from garsim.model.config import GarSimConfig
from garsim.model.encoders import MLP, activation


class EdgeUpdate(nn.Module):
    """Ψ_edge: MLP on [π_k, η_{r_k}, η_{s_k}].

    The first linear layer of the concatenation is split into three (mathematically the
    same layer) so the node terms are projected once per node, not once per edge.
    """

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        h, d = cfg.edge_latent, cfg.edge_latent  # edge MLP hidden width = edge latent width
        self.lin_edge = nn.Linear(d, h)
        self.lin_recv = nn.Linear(cfg.latent, h, bias=False)
        self.lin_send = nn.Linear(cfg.latent, h, bias=False)
        mods: list[nn.Module] = [activation(cfg.activation)]
        for _ in range(cfg.mlp_layers - 1):
            mods += [nn.Linear(h, h), activation(cfg.activation)]
        mods.append(nn.Linear(h, d))
        if cfg.layer_norm:
            mods.append(nn.LayerNorm(d))
        self.rest = nn.Sequential(*mods)

    def forward(self, edge: torch.Tensor, node: torch.Tensor, senders: torch.Tensor, receivers: torch.Tensor) -> torch.Tensor:
        hid = self.lin_edge(edge) + self.lin_recv(node)[receivers] + self.lin_send(node)[senders]
        return self.rest(hid)


class MessagePassingStep(nn.Module):
    """One iteration of Algorithm 1 (lines 2-11)."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.edge_update = EdgeUpdate(cfg)
        self.node_update = MLP(cfg.latent + cfg.edge_latent, cfg.mlp_hidden, cfg.latent, cfg.mlp_layers, cfg.activation, cfg.layer_norm)
        self.aggregate = aggregation_resolver(cfg.aggregation)
        self.residual = cfg.residual

    def forward(self, node: torch.Tensor, edge: torch.Tensor, edge_index: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        senders, receivers = edge_index[0], edge_index[1]
        new_edge = self.edge_update(edge, node, senders, receivers)
        agg = self.aggregate(new_edge, receivers, dim_size=node.shape[0])
        new_node = self.node_update(torch.cat([agg, node], dim=-1))
        if self.residual:
            return node + new_node, edge + new_edge
        return new_node, new_edge


class Processor(nn.Module):
    """L message-passing steps (unshared weights unless ``share_weights``)."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.num_steps = cfg.num_steps
        n_blocks = 1 if (cfg.share_weights and cfg.num_steps > 0) else cfg.num_steps
        self.steps = nn.ModuleList([MessagePassingStep(cfg) for _ in range(n_blocks)])

    def forward(self, node: torch.Tensor, edge: torch.Tensor, edge_index: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        for l in range(self.num_steps):
            node, edge = self.steps[l % len(self.steps)](node, edge, edge_index)
        return node, edge
