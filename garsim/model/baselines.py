"""Baselines and ablation variants: the LBS prior alone, the nearest-vertex client, a DeePSD-style per-vertex
skinning network, and GarSim with other heads / no message passing."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import torch
from torch import nn
from torch_geometric.data import Data

from garsim.bodies.anny import anny_rig, match_anny_rig
from garsim.bodies.recover import fit_bone_transforms
from garsim.data.sample import Sample
from garsim.geometry.proximity import nearest_vertices, soft_anchor
from garsim.model.config import FABRIC_FEATURES, GarSimConfig
from garsim.model.encoders import MLP
from garsim.model.garsim import CONFIG_FILE, MODEL_KEY, GarSimModel, GraphModel, WeightsError, node_batch
from garsim.model.graph import GarmentGraph, build_graph
from garsim.model.inputs import body_frame

ABLATIONS: tuple[str, ...] = ("full", "displacement", "position", "no_message_passing")


class PriorBaseline(nn.Module):
    """Predicts the LBS deformation prior G^prior itself (the paper's 'prior' row)."""

    def forward(self, data: Data) -> torch.Tensor:
        return data.prior


def nearest_vertex_drape(sample: Sample) -> np.ndarray:
    """The naive client: Ḡ_i = G_i + (B̄_q − B_q), each garment vertex moved rigidly (translation only) with its
    nearest canonical body vertex q; (N, 3) float32, available wherever the prior is."""
    q, _ = nearest_vertices(sample.garment, sample.body_canonical)
    moved = np.asarray(sample.body_target, np.float64)[q] - np.asarray(sample.body_canonical, np.float64)[q]
    return (np.asarray(sample.garment, np.float64) + moved).astype(np.float32)


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


DEEPSD_HIDDEN_LAYERS = 3
"""Hidden layers (of ``GarSimConfig.latent`` units) of each DeePSD-style MLP."""
SKIN_FLOOR = 1e-6
"""Blend-weight logits start at log(w + this), w the body's skinning at the anchor: bones the body does not
use there start at ~1e-6 weight (about 0.1 mm of leakage in all), and the network may raise them."""


def deepsd_graph(sample: Sample, config: GarSimConfig | None = None, **kwargs) -> GarmentGraph:
    """``build_graph`` plus what the DeePSD-style baseline skins with: Anny's bone transforms fitted from the
    body meshes (canonical -> target, about the canonical centroid ``centre``; ``bones`` (1, J, 3, 4)), the
    body's skinning weights at each template vertex's soft anchor (``skin`` (N, J)) and the template vertex
    relative to ``centre`` in the body frame (``rest`` (N, 3)). Needs a body of Anny's topology (its rig)."""
    cfg = config or GarSimConfig()
    canonical = np.asarray(sample.body_canonical, np.float64)
    rig = match_anny_rig(len(canonical), np.asarray(sample.body_faces))
    if rig is None:
        raise ValueError(
            f"the DeePSD-style baseline skins with Anny's skeleton; the body of {kwargs.get('name') or 'the sample'} "
            f"({len(canonical)} vertices) does not have Anny's topology"
        )
    graph = build_graph(sample, cfg, **kwargs)
    indices, weights, num_bones = rig
    centre = canonical.mean(axis=0)
    bones = fit_bone_transforms(
        canonical - centre, np.asarray(sample.body_target, np.float64) - centre, indices, weights, num_bones
    )
    rows = np.repeat(np.arange(len(canonical)), indices.shape[1])
    body_skin = sp.csr_matrix((np.ravel(weights), (rows, np.ravel(indices))), shape=(len(canonical), num_bones))
    skin = (soft_anchor(sample.garment, canonical) @ body_skin).toarray()
    rot = body_frame(sample.body_canonical, sample.body_faces, cfg.canonicalize_yaw).rot64
    rest = (np.asarray(sample.garment, np.float64) - centre) @ rot.T
    graph.bones = torch.from_numpy(bones[None, :, :3, :].astype(np.float32))
    graph.centre = torch.from_numpy(centre[None].astype(np.float32))
    graph.skin = torch.from_numpy(skin.astype(np.float32))
    graph.rest = torch.from_numpy(rest.astype(np.float32))
    return graph


class DeePSDBaseline(GraphModel):
    """A DeePSD-style baseline (Bertiche et al. 2021): per-vertex MLPs, no message passing, then skinning.

    Ω (blend weights) sees the template alone: its vertex in the canonical body frame (``rest``) and its offset
    from its soft anchor on the canonical body (``p``); its logits are added to log(w + ``SKIN_FLOOR``), w the
    body's skinning at the anchor, and a softmax gives the weights W_i over Anny's J bones. Φ (pose-space
    deformation) sees the template (``rest``, ``p``), the pose and the fabric: instead of Anny joint angles,
    the per-vertex body displacement δ_i = B̄_q − B_q at the template vertex's anchor and the prior's offset
    from the moved anchor (``p_prior``), the features GarSim's inputs already provide, plus the fabric values
    GarSim gets (DeePSD has no fabric input; given here so the comparison isolates the architecture). It
    predicts ΔD_i in the rest space, which is then skinned with Anny's bone transforms X_j fitted from the two
    body meshes: Ḡ_i = c + Σ_j W_ij X_j (G_i − c + ΔD_i), c the canonical body's centroid. Both heads start at
    zero, so the untrained baseline is the LBS prior (bones fitted from the meshes, within ~1 mm of the stored
    prior). Config fields used: ``pos_scale``, ``latent`` (MLP width), ``activation``, and the graph inputs.
    Bodies must have Anny's topology. Trained by ``garsim.train`` with ``TrainConfig.model = "deepsd"``.
    """

    kind = "deepsd"
    make_graph = staticmethod(deepsd_graph)

    def __init__(self, config: GarSimConfig | None = None):
        super().__init__(config)
        cfg = self.config
        num_bones = anny_rig("anny")[3]
        self.blend = MLP(6, cfg.latent, num_bones, DEEPSD_HIDDEN_LAYERS, cfg.activation, norm=False)
        self.psd = MLP(12 + FABRIC_FEATURES, cfg.latent, 3, DEEPSD_HIDDEN_LAYERS, cfg.activation, norm=False)
        for head in (self.blend[-1], self.psd[-1]):
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)

    def forward(self, data: Data, return_parts: bool = False):
        """Predicted garment vertices (N, 3) in world coordinates; with ``return_parts`` also a dict of the
        body-frame pose-space displacement and the blend weights (no direction: the trainer's direction term
        is GarSim's)."""
        batch = node_batch(data)
        s = self.config.pos_scale
        rest, p = data.rest * s, data.p * s
        weights = torch.softmax(torch.log(data.skin + SKIN_FLOOR) + self.blend(torch.cat([rest, p], 1)), dim=1)
        psd = self.psd(torch.cat([rest, p, data.p_prior * s, data.delta * s, data.fabric], 1)) / s
        rot = data.rot[batch]
        sizes = torch.bincount(batch, minlength=data.bones.shape[0]).tolist()  # a batch's graphs are contiguous
        bones = data.bones.flatten(2)  # (B, J, 12)
        skinned = torch.cat([w @ x for w, x in zip(torch.split(weights, sizes), bones)]).view(-1, 3, 4)
        centre = data.centre[batch]
        local = data.pos - centre + torch.einsum("nij,ni->nj", rot, psd)  # R^T ΔD: body frame -> world
        pred = centre + torch.einsum("nij,nj->ni", skinned[:, :, :3], local) + skinned[:, :, 3]
        if return_parts:
            return pred, {"displacement": psd, "direction": None, "magnitude": None, "weights": weights}
        return pred


MODELS: dict[str, type[GraphModel]] = {GarSimModel.kind: GarSimModel, DeePSDBaseline.kind: DeePSDBaseline}
"""The trainable models by ``GraphModel.kind`` (``TrainConfig.model``); both take a GarSimConfig."""


def load_model(directory: str | Path) -> GraphModel:
    """A saved GarSim or DeePSD-style model, loaded by the class its ``config.json`` names (absent: GarSim)."""
    try:
        kind = json.loads((Path(directory) / CONFIG_FILE).read_text()).get(MODEL_KEY, GarSimModel.kind)
    except (OSError, ValueError, AttributeError):  # unreadable: GarSimModel.load names the problem
        kind = GarSimModel.kind
    if kind not in MODELS:
        raise WeightsError(f"{Path(directory) / CONFIG_FILE}: unknown model {kind!r}; known: {sorted(MODELS)}")
    return MODELS[kind].load(directory)
