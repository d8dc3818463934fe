"""Processor: the paper's Algorithm 1 (L message-passing steps on the garment graph).

Each step: edge update Ψ_edge(π_k, η_{r_k}, η_{s_k}) for every edge, aggregation
Ω_edge->node of the updated edges at their receiver (mean, as the paper; any PyG
aggregation by name), node update Ψ_node(π̄'_i, η_i). Both updates are MLPs; as in
MeshGraphNets (Pfaff et al. 2021) each MLP can end in a LayerNorm (``layer_norm`` for the
node update, ``edge_layer_norm`` for the edge update) and its output is added to its input
(residual connection, ``residual``).

Speed (CPU inference is the target): the edge MLP's first layer is split per input so node
terms are projected once per node and gathered with ``index_select``; the mean aggregation
is one sparse CSR product with weights 1/deg built once per forward (not per step); without
gradients the activations run in place.
"""

from __future__ import annotations

import warnings

import torch
import torch.nn.functional as F
from torch import nn
from torch_geometric.nn.resolver import aggregation_resolver
from torch_geometric.utils import scatter

from garsim.model.config import FABRIC_FEATURES, GarSimConfig
from garsim.model.encoders import MLP, activation


class MeanAggregator:
    """Mean of edge values at their receiver, precomputed for one edge_index (reused by all L steps)."""

    def __init__(self, receivers: torch.Tensor, num_nodes: int):
        e = receivers.shape[0]
        if e > 1 and not bool((receivers[1:] >= receivers[:-1]).all()):
            order = torch.argsort(receivers, stable=True)
        else:
            order = None
        counts = torch.bincount(receivers, minlength=num_nodes)
        self.num_nodes = num_nodes
        self.receivers = receivers
        self.inv_deg = 1.0 / counts.clamp(min=1).to(torch.float32)
        self._csr: torch.Tensor | None = None
        self._order = order
        self._counts = counts

    def csr(self) -> torch.Tensor:
        """(N, E) sparse CSR matrix with 1/deg(receiver) at (receiver, edge)."""
        if self._csr is None:
            crow = torch.zeros(self.num_nodes + 1, dtype=torch.long, device=self.receivers.device)
            torch.cumsum(self._counts, 0, out=crow[1:])
            e = self.receivers.shape[0]
            col = self._order if self._order is not None else torch.arange(e, device=self.receivers.device)
            val = self.inv_deg.index_select(0, self.receivers.index_select(0, col))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "sparse CSR support is in beta"
                self._csr = torch.sparse_csr_tensor(crow, col, val, (self.num_nodes, e), check_invariants=False)
        return self._csr

    def __call__(self, edge_values: torch.Tensor) -> torch.Tensor:
        if (
            (torch.is_grad_enabled() and edge_values.requires_grad)
            or edge_values.dtype != torch.float32
            or edge_values.device.type != "cpu"
        ):
            # training (cheap backward), other dtypes/devices: plain index_add
            out = edge_values.new_zeros(self.num_nodes, edge_values.shape[1]).index_add_(0, self.receivers, edge_values)
            return out * self.inv_deg.to(out.dtype)[:, None]
        return self.csr() @ edge_values


class EdgeUpdate(nn.Module):
    """Ψ_edge: MLP on [π_k, η_{r_k}, η_{s_k}].

    The first linear layer of the concatenation is split into three (mathematically the
    same layer; its bias lives in ``lin_recv``) so the node terms are projected once per
    node, not once per edge.
    """

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        h, d = cfg.edge_latent, cfg.edge_latent  # edge MLP hidden width = edge latent width
        self.lin_edge = nn.Linear(d, h, bias=False)
        self.lin_recv = nn.Linear(cfg.latent, h)
        self.lin_send = nn.Linear(cfg.latent, h, bias=False)
        self.act_name = cfg.activation
        mods: list[nn.Module] = []
        for _ in range(cfg.mlp_layers - 1):
            mods += [nn.Linear(h, h), activation(cfg.activation)]
        mods.append(nn.Linear(h, d))
        if cfg.edge_layer_norm:
            mods.append(nn.LayerNorm(d))
        self.rest = nn.Sequential(*mods)

    def forward(
        self, edge: torch.Tensor, node: torch.Tensor, senders: torch.Tensor, receivers: torch.Tensor
    ) -> torch.Tensor:
        # in-place accumulation into the gathered receiver term: every op here is autograd-safe
        # (index_select/add_/addmm_ save no tensor that is later overwritten)
        hid = self.lin_recv(node).index_select(0, receivers)
        hid.add_(F.linear(node, self.lin_send.weight).index_select(0, senders))
        hid.addmm_(edge, self.lin_edge.weight.t())
        return self.rest(_act(self.act_name, hid, inplace=True))


def _act(name: str, x: torch.Tensor, inplace: bool) -> torch.Tensor:
    if name == "relu":
        return F.relu(x, inplace=inplace)
    if name == "silu":
        return F.silu(x, inplace=inplace and not x.requires_grad)  # SiLU's backward needs its input
    if name == "gelu":
        return F.gelu(x)
    raise ValueError(f"unknown activation {name!r}")


class MessagePassingStep(nn.Module):
    """One iteration of Algorithm 1 (lines 2-11)."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.edge_update = EdgeUpdate(cfg)
        self.node_update = MLP(
            cfg.latent + cfg.edge_latent, cfg.mlp_hidden, cfg.latent, cfg.mlp_layers, cfg.activation, cfg.layer_norm
        )
        self.mean = cfg.aggregation == "mean"
        self.aggregate = None if self.mean else aggregation_resolver(cfg.aggregation)
        self.residual = cfg.residual

    def forward(
        self,
        node: torch.Tensor,
        edge: torch.Tensor,
        edge_index: torch.Tensor,
        mean: MeanAggregator | None = None,
        own_edge: bool = False,
        film: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One step; ``own_edge`` lets inference (no grad) update ``edge`` in place; ``film`` (N, 2 * edge_latent)
        per-node scale and shift of the edge update, applied at each edge's sender."""
        senders, receivers = edge_index[0], edge_index[1]
        new_edge = self.edge_update(edge, node, senders, receivers)
        if film is not None:
            scale, shift = film.index_select(0, senders).chunk(2, dim=-1)
            new_edge = new_edge * (1.0 + scale) + shift
        if self.mean:
            agg = (mean or MeanAggregator(receivers, node.shape[0]))(new_edge)
        else:
            agg = self.aggregate(new_edge, receivers, dim_size=node.shape[0])
        new_node = self.node_update(torch.cat([agg, node], dim=-1))
        if self.residual:
            if own_edge and not torch.is_grad_enabled():  # inference: update the edge latents in place
                return node + new_node, edge.add_(new_edge)
            return node + new_node, edge + new_edge
        return new_node, new_edge


def graph_pool(node: torch.Tensor, batch: torch.Tensor | None, num_graphs: int) -> torch.Tensor:
    """(num_graphs, 2 d): the mean and the max of each graph's node rows (``batch``: graph id per node; None: one
    graph). Both are invariant to the node order and continuous in the rows."""
    if batch is None:
        return torch.cat([node.mean(0), node.amax(0)])[None]
    return torch.cat([scatter(node, batch, 0, num_graphs, reduce=r) for r in ("mean", "max")], dim=1)


class GlobalContext(nn.Module):
    """``GarSimConfig.global_context``: an MLP of the graph's pooled node latents, added to every node's latent.
    Its last layer starts at zero, so a model widened by it (``GraphModel.widened``) starts as it was."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.mlp = MLP(2 * cfg.latent, cfg.mlp_hidden, cfg.latent, cfg.mlp_layers, cfg.activation, norm=False)
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, node: torch.Tensor, batch: torch.Tensor | None, num_graphs: int) -> torch.Tensor:
        g = self.mlp(graph_pool(node, batch, num_graphs))
        return node + (g if batch is None else g.index_select(0, batch))


class Processor(nn.Module):
    """L message-passing steps (unshared weights unless ``share_weights``), each after a global-context update when
    ``global_context``."""

    def __init__(self, cfg: GarSimConfig):
        super().__init__()
        self.num_steps = cfg.num_steps
        n_blocks = 1 if (cfg.share_weights and cfg.num_steps > 0) else cfg.num_steps
        self.steps = nn.ModuleList([MessagePassingStep(cfg) for _ in range(n_blocks)])
        self.mean = cfg.aggregation == "mean"
        # FiLM from the fabric's physical values: zero-initialised, so training starts from the plain processor
        self.film = (
            nn.ModuleList([nn.Linear(FABRIC_FEATURES, 2 * cfg.edge_latent) for _ in range(n_blocks)])
            if cfg.fabric_film
            else None
        )
        if self.film is not None:
            for lin in self.film:
                nn.init.zeros_(lin.weight)
                nn.init.zeros_(lin.bias)
        self.glob = nn.ModuleList([GlobalContext(cfg) for _ in range(n_blocks)]) if cfg.global_context else None

    def forward(
        self,
        node: torch.Tensor,
        edge: torch.Tensor,
        edge_index: torch.Tensor,
        fabric: torch.Tensor | None = None,
        batch: torch.Tensor | None = None,
        num_graphs: int = 1,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """L steps on node and edge latents; ``batch`` (graph id per node, None: one graph) and ``num_graphs`` scope
        the global context."""
        mean = MeanAggregator(edge_index[1], node.shape[0]) if (self.mean and self.num_steps > 0) else None
        for l in range(self.num_steps):
            block = l % len(self.steps)
            if self.glob is not None:
                node = self.glob[block](node, batch, num_graphs)
            film = self.film[block](fabric) if (self.film is not None and fabric is not None) else None
            node, edge = self.steps[block](node, edge, edge_index, mean, own_edge=l > 0, film=film)
        return node, edge
