"""The GarSim network: encode (Sec. 3.2) -> process (Alg. 1) -> decode (Sec. 3.4); safetensors I/O."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

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
)
from garsim.model.inputs import build_graph, collate
from garsim.model.processor import Processor

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"


def node_batch(data: Data) -> torch.Tensor:
    """Graph id of every node (zeros for an unbatched graph)."""
    b = getattr(data, "batch", None)
    if b is None:
        return torch.zeros(data.num_nodes, dtype=torch.long, device=data.pos.device)
    return b


class GarSimModel(nn.Module):
    """GarSim: predicts the garment on the target body from a GarmentGraph (or Batch)."""

    def __init__(self, config: GarSimConfig | None = None):
        super().__init__()
        self.config = cfg = config or GarSimConfig()
        self.geometry = GeometryEncoder(cfg)
        self.semantic = BodySemanticEncoder(cfg)
        self.garment_encoder = GarmentAwareEncoder(cfg, FABRIC_FEATURES)
        self.body_encoder = BodyAwareEncoder(cfg)
        self.node_encoder = NodeEncoder(cfg)
        self.edge_encoder = EdgeEncoder(cfg)
        self.processor = Processor(cfg)
        self.decoder = Decoder(cfg)

    def forward(self, data: Data, return_parts: bool = False):
        """Predicted garment vertices (N, 3) in world coordinates; with ``return_parts`` also a dict of
        the body-frame displacement, direction and magnitude."""
        batch = node_batch(data)
        x_gar = self.geometry(data.gar_rel)
        # body geometry at each soft anchor: the anchor weights' blend of the anchoring vertices' features
        rows, slots = data.anchor_index[0], data.anchor_index[1]
        enc = self.geometry(data.body_rel)
        x_body = enc.new_zeros(data.num_nodes, enc.shape[1]).index_add_(
            0, rows, enc.index_select(0, slots) * data.anchor_weight[:, None])
        single = data.rot.shape[0] == 1
        s = self.semantic(data.sem)
        s = s.expand(batch.shape[0], -1) if single else s[batch]
        chi = self.garment_encoder(x_gar, data.fabric, data.p, data.p_prior)
        mu = self.body_encoder(x_body, data.delta, s)
        eta = self.node_encoder(chi, mu)
        pi = self.edge_encoder(data.edge_attr)
        eta, _ = self.processor(eta, pi, data.edge_index, data.fabric)
        vec, direction, magnitude = self.decoder(eta, data.fabric)
        if single:  # R^T v for every row: body frame -> world
            world = vec @ data.rot[0].to(vec.dtype)
        else:
            world = torch.einsum("nij,ni->nj", data.rot[batch], vec)
        base = data.anchor if self.config.head == "position" else data.prior
        pred = base + world
        if return_parts:
            return pred, {"displacement": vec, "direction": direction, "magnitude": magnitude}
        return pred

    # -- convenience ------------------------------------------------------------------------
    def predict(self, sample: Sample | Sequence[Sample]) -> np.ndarray | list[np.ndarray]:
        """Sample(s) in memory -> predicted garment vertices (float32 numpy), graph built here."""
        was_training = self.training
        if was_training:  # .train()/.eval() walk every module: skip when already in eval mode
            self.eval()
        try:
            with torch.inference_mode():
                if isinstance(sample, Sample):
                    return self(build_graph(sample, self.config, loss_inputs=False)).numpy()
                graphs = [build_graph(s, self.config, loss_inputs=False) for s in sample]
                batch = collate(graphs)
                pred = self(batch)
                return [t.numpy() for t in torch.split(pred, [g.num_nodes for g in graphs])]
        finally:
            if was_training:
                self.train()

    def num_parameters(self) -> int:
        """Number of trainable parameters."""
        return sum(p.numel() for p in self.parameters())

    def save(self, directory: str | Path) -> Path:
        """Write ``model.safetensors`` + ``config.json`` into ``directory`` (atomically); returns it."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        state = {k: v.detach().contiguous().cpu() for k, v in self.state_dict().items()}
        atomic_write(d / WEIGHTS_FILE, lambda p: save_file(state, str(p), metadata={"format": "garsim"}))
        atomic_write(d / CONFIG_FILE, lambda p: Path(p).write_text(self.config.to_json()))
        return d

    @classmethod
    def load(cls, directory: str | Path, map_location: str = "cpu") -> "GarSimModel":
        """Load a model saved by ``save`` (safetensors + JSON; nothing is unpickled)."""
        d = Path(directory)
        if not (d / WEIGHTS_FILE).exists() or not (d / CONFIG_FILE).exists():
            raise FileNotFoundError(f"{d} must contain {WEIGHTS_FILE} and {CONFIG_FILE} (written by GarSimModel.save)")
        model = cls(GarSimConfig.from_json(d / CONFIG_FILE))
        state = load_file(str(d / WEIGHTS_FILE), device=map_location)
        missing, unexpected = model.load_state_dict(state, strict=False)
        if missing or unexpected:
            raise ValueError(f"weights in {d} do not match the config: missing {missing[:5]}, unexpected {unexpected[:5]}")
        model.eval()
        return model


__all__ = ["GarSimModel", "GarSimConfig", "node_batch", "WEIGHTS_FILE", "CONFIG_FILE"]
