"""The paper's training losses (Sec. 3.5, Eq. 3-7), each averaged per graph, then over the graphs of a batch.

Notes on the paper's equations:
- Eq. 3 (L2): an empty group (no pinned, or only pinned vertices) contributes 0 for that graph.
- Eq. 4 (smoothing): the uniform Laplacian of the prediction, Δ(Ḡ)_i = Ḡ_i − mean_{j∈N(i)} Ḡ_j,
  averaged as the Euclidean norm per vertex.
- Eq. 6 (collision) is printed as max(−N·(B̄ − Ḡ), ε), which would penalise every garment
  vertex outside the body; we implement the intended hinge of the works it cites (DeePSD,
  TailorNet): max(ε − N·(Ḡ − B̄), 0) with B̄, N the nearest target-body vertex and its normal.

Three terms the paper does not have (``LossWeights.dir``, used only with the direction + magnitude head),
which supervise the two factors of d = d̂ m separately against the simulated displacement r = Ḡ − G^prior:
a magnitude-weighted cosine loss on the direction, Σ_i |r_i| (1 − d̂_i·r̂_i) / Σ_i |r_i|, and the mean
|m_i − |r_i|| (metres) on the magnitude. Through Ḡ = G^prior + d̂ m alone, the direction's gradient is
scaled by m, so while the directions are still random the L2 and smoothing terms shrink m, the softplus
saturates, and the head stays at the prior (measured: 40 epochs at the prior's error with or without the
cosine term alone). The prediction is still d̂ m, as in the paper. And ``LossWeights.pair``: in a batch holding
a paired-fabric group (``garsim.train.pairs``: one template, body and pose in several fabrics), the part of each
member's error that differs from the group's mean error, ``fabric_pair_loss``: the L2 term sees the few-mm
differences between fabrics only beside errors ten times larger, this term sees nothing else. And
``LossWeights.fold``: how much the prediction is folded against the simulation, ``fold_loss``: where the folds lie
is not predictable from the inputs (so the L2 term averages them away), how deep they are is, and light fabrics
fold more than stiff ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch_geometric.data import Data
from torch_geometric.utils import scatter

from garsim.geometry.cache import ContentCache
from garsim.geometry.proximity import cached_tree
from garsim.model.garsim import node_batch

_BODY_TREES = ContentCache(1024, scope="train")
"""KD-trees of the training bodies: each is reused every epoch instead of rebuilt every step (~4 ms per body)."""


@dataclass
class LossWeights:
    """α's of Eq. 7, β of Eq. 3 and the collision margin ε (metres)."""

    l2: float = 1.0
    sm: float = 0.01
    nc: float = 1e-4
    col: float = 1.0
    beta: float = 0.4
    eps: float = 0.004
    dir: float = 1.0  # weight of the direction + magnitude terms (ours, see the module docstring); that head only
    pair: float = 0.0  # weight of the paired-fabric term (ours, ``fabric_pair_loss``); 0: off, as in the paper
    pair_smooth: int = 0  # smoothing rounds of that term's residual over the mesh (``fabric_pair_loss``); 0: none
    fold: float = 0.0  # weight of the fold-depth term (ours, ``fold_loss``); 0: off, as in the paper
    relative: float = 0.0  # m; > 0: each graph's L2 term weighs this over its prior's mean error (floored at a
    # quarter of it) in the total, so garments the prior already fits well weigh as much as loose ones (ours); 0: off


def _graph_ids(data: Data) -> tuple[torch.Tensor, int]:
    """(graph id of every node, number of graphs) of a graph or a batch."""
    b = node_batch(data)
    return b, int(data.num_graphs) if getattr(data, "batch", None) is not None else 1


def l2_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    pinned: torch.Tensor,
    batch: torch.Tensor,
    num_graphs: int,
    beta: float = 0.4,
) -> torch.Tensor:
    """Eq. 3 per graph: (1−β)·mean ‖·‖ over non-pinned + β·mean ‖·‖ over pinned vertices, (B,)."""
    err = torch.linalg.vector_norm(pred - target, dim=-1)
    pin = pinned.to(err.dtype)
    free = 1.0 - pin
    n_pin = scatter(pin, batch, dim=0, dim_size=num_graphs, reduce="sum")
    n_free = scatter(free, batch, dim=0, dim_size=num_graphs, reduce="sum")
    s_pin = scatter(err * pin, batch, dim=0, dim_size=num_graphs, reduce="sum")
    s_free = scatter(err * free, batch, dim=0, dim_size=num_graphs, reduce="sum")
    return (1.0 - beta) * s_free / n_free.clamp_min(1.0) + beta * s_pin / n_pin.clamp_min(1.0)


def _neighbour_mean(x: torch.Tensor, edge_index: torch.Tensor) -> torch.Tensor:
    """Each vertex's mesh neighbours' mean of ``x`` (its own value where it has no neighbour)."""
    nbr_mean = scatter(x[edge_index[0]], edge_index[1], dim=0, dim_size=x.shape[0], reduce="mean")
    count = scatter(torch.ones_like(edge_index[1], dtype=x.dtype), edge_index[1], dim=0, dim_size=x.shape[0])
    return torch.where(count[:, None] > 0, nbr_mean, x)


def laplacian_loss(pred: torch.Tensor, edge_index: torch.Tensor, batch: torch.Tensor, num_graphs: int) -> torch.Tensor:
    """Eq. 4 per graph: mean over vertices of ‖Ḡ_i − mean of its mesh neighbours‖, (B,).

    ``edge_index`` holds both directions of every mesh edge (senders row 0, receivers row 1).
    """
    lap = pred - _neighbour_mean(pred, edge_index)
    return scatter(torch.linalg.vector_norm(lap, dim=-1), batch, dim=0, dim_size=num_graphs, reduce="mean")


def face_normals_t(pred: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(F, 3) unit face normals of a torch mesh (differentiable)."""
    v0, v1, v2 = pred[faces[:, 0]], pred[faces[:, 1]], pred[faces[:, 2]]
    return torch.nn.functional.normalize(torch.linalg.cross(v1 - v0, v2 - v0), dim=-1, eps=1e-12)


def normal_consistency_loss(
    pred: torch.Tensor, faces: torch.Tensor, face_pairs: torch.Tensor, batch: torch.Tensor, num_graphs: int
) -> torch.Tensor:
    """Eq. 5 per graph: mean over adjacent face pairs of 1 − cos(angle between their normals), (B,)."""
    n = face_normals_t(pred, faces)
    nc = 1.0 - (n[face_pairs[:, 0]] * n[face_pairs[:, 1]]).sum(-1)
    pair_graph = batch[faces[face_pairs[:, 0], 0]]
    return scatter(nc, pair_graph, dim=0, dim_size=num_graphs, reduce="mean")


def mean_fold(
    x: torch.Tensor, faces: torch.Tensor, face_pairs: torch.Tensor, batch: torch.Tensor, num_graphs: int
) -> torch.Tensor:
    """Per graph, the mean over adjacent face pairs of the chord between their unit normals, 2 sin(θ/2) for the
    dihedral fold angle θ (≈ θ in radians for the usual folds; smooth where θ = 0), (B,)."""
    n = face_normals_t(x, faces)
    # |n1 - n2| from the difference, not sqrt(2 - 2 cos): cos loses the small angles to float32 cancellation
    # (the chord from cos changed the study's fitted folds by up to 0.7 deg and its errors by 5 mm)
    chord = torch.sqrt(((n[face_pairs[:, 0]] - n[face_pairs[:, 1]]) ** 2).sum(-1) + 1e-12)
    return scatter(chord, batch[faces[face_pairs[:, 0], 0]], dim=0, dim_size=num_graphs, reduce="mean")


def fold_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    faces: torch.Tensor,
    face_pairs: torch.Tensor,
    batch: torch.Tensor,
    num_graphs: int,
    pair: torch.Tensor | None = None,
) -> torch.Tensor:
    """Per graph: |e| for e = mean fold of the prediction − mean fold of the simulation (``mean_fold``, ≈ radians),
    plus, for a graph of a paired-fabric group (``pair`` >= 0, as ``fabric_pair_loss``), |e − the group's mean e|:
    the fold differences between the fabrics of one template, which a uniformly deeper fold does not mend, (B,).
    Zero when every prediction is as folded as its simulation on average, wherever its folds lie."""
    with torch.no_grad():
        simulated = mean_fold(target, faces, face_pairs, batch, num_graphs)
    err = mean_fold(pred, faces, face_pairs, batch, num_graphs) - simulated
    loss = err.abs()
    if pair is not None:
        group = pair.to(err.device)
        grouped = torch.nonzero(group >= 0).ravel()
        if grouped.numel():
            _, slot = torch.unique(group[grouped], return_inverse=True)
            rel = err[grouped] - scatter(err[grouped], slot, dim=0, reduce="mean")[slot]
            loss = loss.index_add(0, grouped, rel.abs())
    return loss


def nearest_in_graph(
    points: np.ndarray, point_graph: np.ndarray, refs: np.ndarray, ref_graph: np.ndarray, num_graphs: int
) -> np.ndarray:
    """Index into ``refs`` of the nearest reference point of the same graph, for each point."""
    out = np.zeros(len(points), dtype=np.int64)
    for g in range(num_graphs):  # a loop over graphs, not vertices
        pm, rm = np.flatnonzero(point_graph == g), np.flatnonzero(ref_graph == g)
        if len(pm) == 0:
            continue
        if len(rm) == 0:
            raise ValueError(f"graph {g} has no collision body vertices: build graphs with with_collision=True")
        _, idx = cached_tree(refs[rm], _BODY_TREES).query(points[pm])
        out[pm] = rm[idx]
    return out


def collision_loss(
    pred: torch.Tensor,
    body: torch.Tensor,
    normals: torch.Tensor,
    batch: torch.Tensor,
    body_batch: torch.Tensor,
    num_graphs: int,
    eps: float = 0.004,
) -> torch.Tensor:
    """Eq. 6 per graph: mean over vertices of max(ε − N·(Ḡ − B̄), 0) for the nearest target-body vertex, (B,)."""
    idx = nearest_in_graph(
        pred.detach().cpu().numpy(), batch.cpu().numpy(), body.cpu().numpy(), body_batch.cpu().numpy(), num_graphs
    )
    idx_t = torch.from_numpy(idx).to(pred.device)
    signed = ((pred - body[idx_t]) * normals[idx_t]).sum(-1)
    return scatter(torch.relu(eps - signed), batch, dim=0, dim_size=num_graphs, reduce="mean")


def collision_fraction(pred: torch.Tensor, data: Data) -> torch.Tensor:
    """Per graph, the fraction of predicted vertices behind their nearest target-body vertex's normal (DeePSD), (B,)."""
    batch, num_graphs = _graph_ids(data)
    idx = nearest_in_graph(
        pred.detach().cpu().numpy(),
        batch.cpu().numpy(),
        data.col_body.cpu().numpy(),
        data.col_batch.cpu().numpy(),
        num_graphs,
    )
    idx_t = torch.from_numpy(idx).to(pred.device)
    inside = (((pred - data.col_body[idx_t]) * data.col_normal[idx_t]).sum(-1) < 0).to(pred.dtype)
    return scatter(inside, batch, dim=0, dim_size=num_graphs, reduce="mean")


def direction_loss(
    direction: torch.Tensor, magnitude: torch.Tensor, data: Data, batch: torch.Tensor, num_graphs: int
) -> torch.Tensor:
    """Per graph: Σ |r| (1 − d̂·r̂) / Σ |r| + mean |m − |r|| for the body-frame unit directions d̂ and the
    magnitudes m (metres) against the simulated displacement r = target − prior in the frame the decoder predicts
    in: each graph's body frame, and with ``local_rot`` (``GarSimConfig.local_rotation``, which turns the decoded
    vector by it) that rotation undone first, (B,)."""
    rot = data.rot[0].expand(batch.shape[0], 3, 3) if data.rot.shape[0] == 1 else data.rot[batch]
    d = data.target - data.prior
    local = getattr(data, "local_rot", None)
    if local is not None:  # pred = prior + L R^T v, so v = R L^T (target - prior)
        d = torch.einsum("nji,nj->ni", local.to(d.dtype), d)
    r = torch.einsum("nij,nj->ni", rot.to(direction.dtype), d)
    length = torch.linalg.vector_norm(r, dim=-1)
    cos = (direction * r).sum(-1) / length.clamp_min(1e-9)
    num = scatter(length * (1.0 - cos), batch, dim=0, dim_size=num_graphs, reduce="sum")
    den = scatter(length, batch, dim=0, dim_size=num_graphs, reduce="sum")
    mag = scatter((magnitude - length).abs(), batch, dim=0, dim_size=num_graphs, reduce="mean")
    return num / den.clamp_min(1e-9) + mag


def fabric_pair_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    pair: torch.Tensor,
    batch: torch.Tensor,
    num_graphs: int,
    edge_index: torch.Tensor | None = None,
    smooth: int = 0,
) -> torch.Tensor:
    """Per graph: mean over its vertices of ‖r_i − mean of r_i over its group‖, r = Ḡ − G the error and the group
    the batch's graphs of one paired-fabric group (same mesh, vertex i matched to vertex i), (B,); 0 for a graph in
    no group (``pair`` = -1) or alone in the batch. Zero exactly when every member is off by the same vector field,
    i.e. when the predicted differences between the fabrics are the simulated ones. ``smooth`` > 0: that deviation
    is first smoothed ``smooth`` times over the mesh (``edge_index``, both directions; x <- (x + neighbours' mean)
    / 2), so that only its large-scale part counts, not the wrinkles."""
    if smooth < 0 or (smooth > 0 and edge_index is None):
        raise ValueError(f"pair smoothing needs rounds >= 0 and the mesh's edge_index, got {smooth} rounds")
    counts = torch.bincount(batch, minlength=num_graphs)
    pos = torch.arange(batch.shape[0], device=batch.device) - (torch.cumsum(counts, 0) - counts)[batch]
    group = pair.to(batch.device)[batch]
    dev = torch.zeros(batch.shape[0], dtype=pred.dtype, device=pred.device)
    sel = torch.nonzero(group >= 0).ravel()  # vertices of grouped graphs only
    r = pred[sel] - target[sel]
    _, slot = torch.unique(torch.stack([group[sel], pos[sel]]), dim=1, return_inverse=True)
    d = pred.new_zeros(pred.shape).index_put((sel,), r - scatter(r, slot, dim=0, reduce="mean")[slot])
    for _ in range(smooth):
        d = 0.5 * (d + _neighbour_mean(d, edge_index))
    dev = dev.index_put((sel,), torch.linalg.vector_norm(d[sel], dim=-1))
    return scatter(dev, batch, dim=0, dim_size=num_graphs, reduce="mean")


def garsim_loss(
    pred: torch.Tensor,
    data: Data,
    weights: LossWeights | None = None,
    use_collision: bool = False,
    direction: torch.Tensor | None = None,
    magnitude: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Eq. 7: total loss (scalar, mean over graphs) and the per-graph terms {l2, sm, nc, col, dir, pair, fold,
    total} (B,).

    ``direction``, ``magnitude``: the direction + magnitude head's body-frame unit directions and magnitudes
    (``return_parts``), which add the direction term when ``weights.dir`` > 0."""
    w = weights or LossWeights()
    batch, num_graphs = _graph_ids(data)
    terms = {
        "l2": l2_loss(pred, data.target, data.pinned, batch, num_graphs, w.beta),
        "sm": laplacian_loss(pred, data.edge_index, batch, num_graphs),
        "nc": normal_consistency_loss(pred, data.faces, data.face_pairs, batch, num_graphs),
    }
    l2 = terms["l2"]  # reported as it is (mean error), weighed in the total
    if w.relative > 0:
        prior_err = per_graph_error_mm(data.prior, data.target, data) / 1000.0
        l2 = l2 * (w.relative / prior_err.clamp_min(0.25 * w.relative))
    total = w.l2 * l2 + w.sm * terms["sm"] + w.nc * terms["nc"]
    if direction is not None and magnitude is not None and w.dir > 0:
        terms["dir"] = direction_loss(direction, magnitude, data, batch, num_graphs)
        total = total + w.dir * terms["dir"]
    if w.pair > 0 and getattr(data, "pair", None) is not None:
        terms["pair"] = fabric_pair_loss(
            pred, data.target, data.pair, batch, num_graphs, data.edge_index, w.pair_smooth
        )
        total = total + w.pair * terms["pair"]
    if w.fold > 0:
        pair = getattr(data, "pair", None) if w.pair > 0 else None  # the groups travel together only then
        terms["fold"] = fold_loss(pred, data.target, data.faces, data.face_pairs, batch, num_graphs, pair)
        total = total + w.fold * terms["fold"]
    if use_collision:
        if getattr(data, "col_body", None) is None:
            raise ValueError("the collision loss needs graphs built with with_collision=True")
        terms["col"] = collision_loss(pred, data.col_body, data.col_normal, batch, data.col_batch, num_graphs, w.eps)
        total = total + w.col * terms["col"]
    terms["total"] = total
    return total.mean(), terms


def per_graph_error_mm(pred: torch.Tensor, target: torch.Tensor, data: Data) -> torch.Tensor:
    """Per-graph mean Euclidean vertex error in millimetres, (B,)."""
    batch, num_graphs = _graph_ids(data)
    err = torch.linalg.vector_norm(pred - target, dim=-1) * 1000.0
    return scatter(err, batch, dim=0, dim_size=num_graphs, reduce="mean")
