"""The GarSim network: encode (Sec. 3.2) -> process (Alg. 1) -> decode (Sec. 3.4); safetensors I/O."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Self

import numpy as np
import torch
from safetensors.torch import load_file, save_file
from torch import nn
from torch_geometric.data import Data

from garsim.atomic import atomic_write
from garsim.data.sample import Sample
from garsim.model.config import FABRIC_FEATURES, GarSimConfig
from garsim.model.decoder import Decoder
from garsim.model.encoders import (
    BodyAwareEncoder,
    BodySemanticEncoder,
    EdgeEncoder,
    GarmentAwareEncoder,
    GeometryEncoder,
    NodeEncoder,
    TargetSurfaceEncoder,
)
from garsim.model.graph import build_graph, collate
from garsim.model.processor import Processor
from garsim.model.weights import (
    CHECKSUM_KEY,
    CONFIG_FILE,
    DEFAULT_KIND,
    MODEL_KEY,
    WEIGHTS_FILE,
    WeightsError,
    check_state,
    file_sha256,
    load_verified,
)


def node_batch(data: Data) -> torch.Tensor:
    """Graph id of every node (zeros for an unbatched graph)."""
    b = getattr(data, "batch", None)
    if b is None:
        return torch.zeros(data.num_nodes, dtype=torch.long, device=data.pos.device)
    return b


class GraphModel(nn.Module):
    """Base of the models ``garsim.train`` trains: a GarSimConfig, graphs built from Samples by ``make_graph``
    (``build_graph``'s signature), ``forward(data, return_parts)``, predict and safetensors save/load.
    ``kind`` names the model in ``config.json`` (GarSim writes none)."""

    kind = DEFAULT_KIND
    make_graph = staticmethod(build_graph)

    def __init__(self, config: GarSimConfig | None = None):
        super().__init__()
        self.config = config or GarSimConfig()

    def predict(self, sample: Sample | Sequence[Sample]) -> np.ndarray | list[np.ndarray]:
        """Sample(s) in memory -> predicted garment vertices (float32 numpy), graph built here."""
        was_training = self.training
        if was_training:  # .train()/.eval() walk every module: skip when already in eval mode
            self.eval()
        try:
            with torch.inference_mode():
                if isinstance(sample, Sample):
                    return self(self.make_graph(sample, self.config, loss_inputs=False)).numpy()
                graphs = [self.make_graph(s, self.config, loss_inputs=False) for s in sample]
                batch = collate(graphs)
                pred = self(batch)
                return [t.numpy() for t in torch.split(pred, [g.num_nodes for g in graphs])]
        finally:
            if was_training:
                self.train()

    def widened(self, config: GarSimConfig) -> Self:
        """A model of ``config`` holding this model's weights, the layers this one lacks (e.g. turned on by
        ``fabric_decoder_film``) at their initial values; raises ValueError when one of this model's weights has
        no place of the same shape in it (``config`` changes more than it adds)."""
        model = type(self)(config)
        mine, theirs = self.state_dict(), model.state_dict()
        misfit = sorted(k for k, v in mine.items() if k not in theirs or theirs[k].shape != v.shape)
        if misfit:
            raise ValueError(f"the model's weights {misfit[:5]} have no place in the widened config")
        model.load_state_dict(mine, strict=False)
        return model

    def num_parameters(self) -> int:
        """Number of trainable parameters."""
        return sum(p.numel() for p in self.parameters())

    def save(self, directory: str | Path) -> Path:
        """Write ``model.safetensors`` + ``config.json`` (the config plus the weights' sha256) into
        ``directory`` (atomically); returns it."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        state = {k: v.detach().contiguous().cpu() for k, v in self.state_dict().items()}
        atomic_write(d / WEIGHTS_FILE, lambda p: save_file(state, str(p), metadata={"format": "garsim"}))
        config = {**self.config.to_dict(), CHECKSUM_KEY: file_sha256(d / WEIGHTS_FILE)}
        if self.kind != GraphModel.kind:
            config[MODEL_KEY] = self.kind
        text = json.dumps(config, indent=2, sort_keys=True)
        atomic_write(d / CONFIG_FILE, lambda p: Path(p).write_text(text))
        return d

    @classmethod
    def load(cls, directory: str | Path, map_location: str = "cpu") -> Self:
        """Load a model of this class saved by ``save`` (safetensors + JSON; nothing is unpickled).

        Raises ``WeightsError`` (one line naming the file) when the weights fail their checksum, are
        truncated or corrupt, the config is malformed, or the weights do not fit the config. A config
        without a checksum (written before checksums) loads with a warning."""
        config, state = load_verified(directory, cls.kind, lambda p: load_file(p, device=map_location), cls.__name__)
        model = cls(config)
        check_state(state, {k: tuple(v.shape) for k, v in model.state_dict().items()}, Path(directory) / WEIGHTS_FILE)
        model.load_state_dict(state, strict=True)
        model.eval()
        return model


class GarSimModel(GraphModel):
    """GarSim: predicts the garment on the target body from a GarmentGraph (or Batch)."""

    def __init__(self, config: GarSimConfig | None = None):
        super().__init__(config)
        cfg = self.config
        self.geometry = GeometryEncoder(cfg)
        self.semantic = BodySemanticEncoder(cfg)
        self.garment_encoder = GarmentAwareEncoder(cfg, FABRIC_FEATURES)
        self.body_encoder = BodyAwareEncoder(cfg)
        self.node_encoder = NodeEncoder(cfg)
        self.edge_encoder = EdgeEncoder(cfg)
        self.surface_encoder = TargetSurfaceEncoder(cfg) if cfg.target_surface else None
        self.processor = Processor(cfg)
        self.decoder = Decoder(cfg)

    def deepened(self, num_steps: int) -> GarSimModel:
        """This model with message-passing steps appended up to ``num_steps``, each new step the identity at first
        (the last layers of its edge and node updates at zero, so it adds nothing to the residual stream until
        trained); raises ValueError for fewer steps or shared step weights."""
        cfg = self.config
        if num_steps < cfg.num_steps or cfg.share_weights:
            raise ValueError(
                f"can only append steps to a model with unshared steps: it has {cfg.num_steps}"
                f"{' shared' if cfg.share_weights else ''}, asked for {num_steps}"
            )
        model = self.widened(dataclasses.replace(cfg, num_steps=num_steps))
        with torch.no_grad():
            for step in model.processor.steps[cfg.num_steps :]:
                for layer in (step.edge_update.rest[-1], step.node_update[-1]):
                    layer.weight.zero_()
                    layer.bias.zero_()
        return model

    def forward(self, data: Data, return_parts: bool = False):
        """Predicted garment vertices (N, 3) in world coordinates; with ``return_parts`` also a dict of
        the body-frame displacement, direction and magnitude."""
        batch = node_batch(data)
        x_gar = self.geometry(data.gar_rel)
        # body geometry at each soft anchor: the anchor weights' blend of the anchoring vertices' features
        rows, slots = data.anchor_index[0], data.anchor_index[1]
        enc = self.geometry(data.body_rel)
        x_body = enc.new_zeros(data.num_nodes, enc.shape[1]).index_add_(
            0, rows, enc.index_select(0, slots) * data.anchor_weight[:, None]
        )
        single = data.rot.shape[0] == 1
        s = self.semantic(data.sem)
        s = s.expand(batch.shape[0], -1) if single else s[batch]
        chi = self.garment_encoder(x_gar, data.fabric, data.p, data.p_prior)
        mu = self.body_encoder(x_body, data.delta, s)
        eta = self.node_encoder(chi, mu)
        if self.surface_encoder is not None:
            eta = eta + self.surface_encoder(data.surface)
        pi = self.edge_encoder(data.edge_attr)
        eta, _ = self.processor(eta, pi, data.edge_index, data.fabric, None if single else batch, data.rot.shape[0])
        vec, direction, magnitude = self.decoder(eta, data.fabric)
        if single:  # R^T v for every row: body frame -> world
            world = vec @ data.rot[0].to(vec.dtype)
        else:
            world = torch.einsum("nij,ni->nj", data.rot[batch], vec)
        if self.config.local_rotation:  # a rest-frame correction, turned with its neighbourhood
            world = torch.einsum("nij,nj->ni", data.local_rot.to(world.dtype), world)
        base = data.anchor if self.config.head == "position" else data.prior
        pred = base + world
        if return_parts:
            return pred, {"displacement": vec, "direction": direction, "magnitude": magnitude}
        return pred


__all__ = [
    "CHECKSUM_KEY",
    "CONFIG_FILE",
    "MODEL_KEY",
    "WEIGHTS_FILE",
    "GarSimConfig",
    "GarSimModel",
    "GraphModel",
    "WeightsError",
    "node_batch",
]
