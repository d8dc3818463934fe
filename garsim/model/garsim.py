"""The GarSim network: encode (Sec. 3.2) -> process (Alg. 1) -> decode (Sec. 3.4); safetensors I/O."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Self

import numpy as np
import torch
from safetensors import SafetensorError
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
CHECKSUM_KEY = "weights_sha256"
"""Top-level key of ``config.json`` holding the sha256 of ``model.safetensors`` (not a GarSimConfig field)."""
MODEL_KEY = "model"
"""Top-level key of ``config.json`` naming the model (``GraphModel.kind``) when it is not GarSim; absent: GarSim."""

log = logging.getLogger(__name__)


class WeightsError(ValueError):
    """A saved model that cannot be trusted: one line naming the file and what is wrong with it."""


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _safetensors_problem(path: Path) -> str | None:
    """What is wrong with the layout of a safetensors file (truncated, bad header), or None; never raises."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(8)
            if len(head) < 8:
                return f"truncated: {size} bytes, too short for a safetensors header"
            (n,) = struct.unpack("<Q", head)
            if n > size - 8:
                return f"truncated: {size} bytes, but its header alone claims {n + 8}"
            header = json.loads(fh.read(n))
        if not isinstance(header, dict):
            return "corrupt safetensors header (not a JSON object)"
        end = 0
        for key, info in header.items():
            if key == "__metadata__":
                continue
            end = max(end, int(info["data_offsets"][1]))
        if size < 8 + n + end:
            return f"truncated: {size} bytes, its header expects {8 + n + end}"
    except (OSError, ValueError, TypeError, KeyError, IndexError) as exc:
        return f"corrupt safetensors header ({type(exc).__name__}: {exc})".replace("\n", " ")
    return None


_SIMPLE_TYPES: dict[str, tuple[type, ...]] = {"int": (int,), "float": (int, float), "bool": (bool,), "str": (str,)}


def _check_config_types(d: dict[str, Any]) -> None:
    """Refuse values whose JSON type does not fit the GarSimConfig field (``"latent": "64"``, ``"residual": 1``)."""
    for f in dataclasses.fields(GarSimConfig):
        if f.name not in d:
            continue
        v, t = d[f.name], str(f.type).replace(" ", "")
        optional = t.endswith("|None")
        base = t[: -len("|None")] if optional else t
        if v is None and optional:
            continue
        if base in _SIMPLE_TYPES:
            ok = isinstance(v, _SIMPLE_TYPES[base]) and (base == "bool" or not isinstance(v, bool))
        elif base.startswith("tuple[int"):
            ok = isinstance(v, list | tuple) and all(isinstance(x, int) and not isinstance(x, bool) for x in v)
        else:
            continue
        if not ok:
            raise ValueError(f"{f.name} must be {t.replace('|', ' | ')}, got {v!r}")


def _read_config(path: Path) -> tuple[GarSimConfig, str | None, str]:
    """config.json -> (GarSimConfig, recorded weights sha256 or None, model kind); WeightsError when malformed."""
    try:
        d = json.loads(path.read_text())
        if not isinstance(d, dict):
            raise TypeError(f"expected a JSON object, got {type(d).__name__}")
        checksum = d.pop(CHECKSUM_KEY, None)
        if checksum is not None and not (isinstance(checksum, str) and len(checksum) == 64):
            raise ValueError(f"{CHECKSUM_KEY} must be a 64-digit hex string, got {checksum!r}")
        kind = d.pop(MODEL_KEY, GraphModel.kind)
        _check_config_types(d)
        return GarSimConfig.from_dict(d), checksum, kind
    except (OSError, UnicodeDecodeError, ValueError, TypeError) as exc:
        msg = str(exc).replace("\n", " ")
        raise WeightsError(f"{path}: malformed config ({type(exc).__name__}: {msg})") from None


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

    kind = "garsim"
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
        config = {**self.config.to_dict(), CHECKSUM_KEY: _sha256(d / WEIGHTS_FILE)}
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
        d = Path(directory)
        wpath, cpath = d / WEIGHTS_FILE, d / CONFIG_FILE
        if not wpath.exists() or not cpath.exists():
            raise FileNotFoundError(
                f"{d} must contain {WEIGHTS_FILE} and {CONFIG_FILE} (written by {cls.__name__}.save)"
            )
        config, expected, kind = _read_config(cpath)
        if kind != cls.kind:
            raise WeightsError(f"{cpath}: holds a {kind!r} model, not {cls.kind!r}; load it with that model's class")
        problem = _safetensors_problem(wpath)
        if expected is None:
            log.warning("%s has no %s (saved before checksums): %s is loaded unverified", cpath, CHECKSUM_KEY, wpath)
        else:
            actual = _sha256(wpath)
            if actual != expected.lower():
                detail = f"; {problem}" if problem else ""
                raise WeightsError(
                    f"{wpath}: checksum mismatch (sha256 {actual[:12]}..., "
                    f"{CONFIG_FILE} records {expected[:12]}...){detail}"
                )
        if problem:
            raise WeightsError(f"{wpath}: {problem}")
        try:
            state = load_file(str(wpath), device=map_location)
        except (SafetensorError, OSError, ValueError, RuntimeError) as exc:
            msg = str(exc).replace("\n", " ")
            raise WeightsError(f"{wpath}: unreadable safetensors ({type(exc).__name__}: {msg})") from None
        model = cls(config)
        own = model.state_dict()
        missing = sorted(set(own) - set(state))
        unexpected = sorted(set(state) - set(own))
        if missing or unexpected:
            raise WeightsError(
                f"{wpath}: weights do not match {cpath.name}: missing {missing[:5]}, unexpected {unexpected[:5]}"
            )
        wrong = [
            f"{k} {tuple(state[k].shape)} vs {tuple(v.shape)}" for k, v in own.items() if state[k].shape != v.shape
        ]
        if wrong:
            raise WeightsError(
                f"{wpath}: weights do not match {cpath.name}: {len(wrong)} tensor shapes differ "
                f"(file vs config), e.g. {'; '.join(wrong[:3])}"
            )
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
            0, rows, enc.index_select(0, slots) * data.anchor_weight[:, None]
        )
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
