"""The GarSim forward pass in numpy: the inference path's runtime, without torch.

``garsim.model.garsim.GarSimModel`` (torch) is the model that trains; this module runs the same saved weights
on the arrays of ``garsim.model.inputs.graph_arrays`` with numpy and scipy only, so a cold ``garsim drape``
does not import torch (~1.3 s) or torch_geometric (~2 s more). It is a second implementation of one network, so
``tests/test_model_runtime.py`` holds it to the torch model's output (to float32 rounding) for every head,
activation, normalisation and fabric option; configurations it does not cover (aggregations other than the
paper's mean) are refused with a message, and ``GarSim.load`` then uses torch.

Speed: what depends on the template garment and the canonical body alone (the geometry encoders' features of
the garment and at the soft anchors, the body-semantic vector) is cached by content, so a pose sequence computes
it once; the fabric is one vector per garment, so its FiLM scale/shift is folded into each edge update's last
linear layer, and its magnitude gain is computed once, not per node; the mean aggregation is one CSR product over
the receiver-sorted edges; every node-side projection of the edge MLP's first layer is done per node and gathered
(as the torch processor does).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from garsim.data.sample import Sample
from garsim.geometry.cache import ContentCache, content_key
from garsim.model.config import GarSimConfig
from garsim.model.inputs import graph_arrays, pose_arrays, static_graph
from garsim.model.weights import CONFIG_FILE, DEFAULT_KIND, WEIGHTS_FILE, WeightsError, load_verified, read_model_config

if TYPE_CHECKING:  # torch: only for the annotation
    from garsim.model.garsim import GraphModel


EDGE_CHUNK = 2048
"""Edges per chunk of the message-passing loop (a chunk's (rows, edge_latent) intermediates stay in the cache)."""
_STATIC = ContentCache(8, scope="garment")  # per (model, template garment, canonical body): pose-free features
_TOKENS = itertools.count()


def _gelu(x: np.ndarray) -> np.ndarray:
    from scipy.special import erf  # only GELU models need it

    return (0.5 * x * (1.0 + erf(x / np.float32(np.sqrt(2.0))))).astype(np.float32)


_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "relu": lambda x: np.maximum(x, np.float32(0.0), out=x),
    "silu": lambda x: x / (np.float32(1.0) + np.exp(-x)),
    "gelu": _gelu,
}


def _linear(x: np.ndarray, w: np.ndarray, b: np.ndarray | None, out: np.ndarray | None = None) -> np.ndarray:
    """x @ w.T + b, into ``out`` when given (a reused buffer: fresh multi-MB arrays cost page faults, ~2x the GEMM)."""
    if x.ndim != 2:  # one GEMM, not one per leading index (numpy's stacked matmul is ~10x slower here)
        return _linear(x.reshape(-1, x.shape[-1]), w, b).reshape(*x.shape[:-1], w.shape[0])
    y = np.matmul(x, w.T, out=out)
    if b is not None:
        y += b
    return y


def _layer_norm(x: np.ndarray, w: np.ndarray, b: np.ndarray, eps: float = 1e-5) -> np.ndarray:
    d = x.shape[-1]
    xc = x - (x @ np.full(d, np.float32(1.0 / d)))[:, None]  # the row means as one GEMV (~8x x.mean(axis=-1))
    inv = np.float32(1.0) / np.sqrt(np.einsum("ij,ij->i", xc, xc)[:, None] / np.float32(d) + np.float32(eps))
    xc *= inv
    xc *= w
    xc += b
    return xc


def _mean_matrix(a: Mapping[str, np.ndarray], n: int) -> sp.csr_matrix:
    """(N, E) the mean over each node's incoming edges (any edge order; ``graph_arrays`` sorts them by receiver)."""
    rcv = a["edge_index"][1]
    counts = np.bincount(rcv, minlength=n)
    order = np.argsort(rcv, kind="stable")
    inv = (1.0 / np.maximum(counts, 1)).astype(np.float32)
    indptr = np.concatenate([[0], np.cumsum(counts)])
    return sp.csr_matrix((inv[rcv[order]], order, indptr), shape=(n, len(rcv)))


class _MLP:
    """An ``encoders.MLP`` (or any nn.Sequential of Linear/activation/LayerNorm) from its state-dict entries."""

    def __init__(self, state: Mapping[str, np.ndarray], prefix: str, act: Callable[[np.ndarray], np.ndarray]):
        idx = sorted({int(k[len(prefix) :].split(".")[0]) for k in state if k.startswith(prefix)})
        self.layers: list[tuple[str, np.ndarray, np.ndarray | None]] = []
        for i in idx:
            w, b = state[f"{prefix}{i}.weight"], state.get(f"{prefix}{i}.bias")
            self.layers.append(("linear" if w.ndim == 2 else "norm", w, b))
        self.act = act

    def scaled(self, out_scale: np.ndarray, out_shift: np.ndarray) -> _MLP:
        """This MLP with its output scaled by ``out_scale`` and shifted by ``out_shift`` (per channel), folded into
        the last layer's weights when that layer is linear."""
        mlp = _MLP.__new__(_MLP)
        mlp.act, mlp.layers = self.act, list(self.layers)
        kind, w, b = self.layers[-1]
        if kind == "linear":
            mlp.layers[-1] = (kind, w * out_scale[:, None], (b if b is not None else 0.0) * out_scale + out_shift)
        else:
            mlp.post = (out_scale, out_shift)
        return mlp

    post: tuple[np.ndarray, np.ndarray] | None = None
    """A scale and shift applied after the last layer (``scaled`` of an MLP that ends in a norm)."""

    def __call__(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The MLP on ``x``; the result is written into ``out`` when given (a reused buffer)."""
        n_linear = sum(kind == "linear" for kind, _, _ in self.layers)
        last = len(self.layers) - 1
        seen = 0
        for i, (kind, w, b) in enumerate(self.layers):
            if kind == "norm":
                x = _layer_norm(x, w, b)  # type: ignore[arg-type]
                continue
            x = _linear(x, w, b, out if i == last else None)
            seen += 1
            if seen < n_linear:  # an activation between linear layers, none after the last
                x = self.act(x)
        if self.post is not None:
            x = x * self.post[0] + self.post[1]
        if out is not None and x is not out:
            out[...] = x
            return out
        return x


class GarSimRuntime:
    """A saved GarSim model run with numpy: ``predict(sample)`` as ``GarSimModel.predict``, without torch."""

    kind = DEFAULT_KIND
    make_graph = staticmethod(graph_arrays)
    """Sample -> this model's input (``GraphModel.make_graph``'s counterpart)."""

    def __init__(self, config: GarSimConfig, state: Mapping[str, np.ndarray]):
        if config.aggregation != "mean":
            raise ValueError(
                f"the numpy runtime implements the paper's mean aggregation, not {config.aggregation!r}; "
                "load this model with garsim.model.garsim.GarSimModel (torch)"
            )
        self.config = config
        self._token = next(_TOKENS)  # this instance's part of the feature cache's keys
        s = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in state.items()}
        self._act = _ACTIVATIONS[config.activation]
        act = self._act
        self.scale = np.float32(config.pos_scale)
        g1w, g1b, g2w, g2b = (
            s[f"geometry.mlp.{i}.{p}"] for i, p in ((0, "weight"), (0, "bias"), (2, "weight"), (2, "bias"))
        )
        self.geo = (g1w * self.scale, g1b, g2w, g2b)
        self.semantic = _MLP(s, "semantic.mlp.", act)
        self.garment = _MLP(s, "garment_encoder.mlp.", act)
        self.body = _MLP(s, "body_encoder.mlp.", act)
        self.node = _MLP(s, "node_encoder.mlp.", act)
        self.edge = _MLP(s, "edge_encoder.mlp.", act)
        self.surface = _MLP(s, "surface_encoder.mlp.", act) if config.target_surface else None
        self.surface_scale = np.array(config.surface_scale, dtype=np.float32)
        n_blocks = 1 if (config.share_weights and config.num_steps > 0) else config.num_steps
        self.steps = [
            (
                s[f"processor.steps.{i}.edge_update.lin_recv.weight"],
                s[f"processor.steps.{i}.edge_update.lin_recv.bias"],
                s[f"processor.steps.{i}.edge_update.lin_send.weight"],
                s[f"processor.steps.{i}.edge_update.lin_edge.weight"],
                _MLP(s, f"processor.steps.{i}.edge_update.rest.", act),
                _MLP(s, f"processor.steps.{i}.node_update.", act),
                (s[f"processor.film.{i}.weight"], s[f"processor.film.{i}.bias"]) if config.fabric_film else None,
                _MLP(s, f"processor.glob.{i}.mlp.", act) if config.global_context else None,
            )
            for i in range(n_blocks)
        ]
        self.decoder = _MLP(s, "decoder.mlp.", act)
        gain = ("decoder.fabric_gain.weight", "decoder.fabric_gain.bias")
        self.fabric_gain = (s[gain[0]], s[gain[1]]) if gain[0] in s else None
        film = ("decoder.fabric_film.weight", "decoder.fabric_film.bias")
        self.decoder_film = (s[film[0]], s[film[1]]) if config.fabric_decoder_film else None

    @classmethod
    def load(cls, directory: str | Path) -> GarSimRuntime:
        """A model directory saved by ``GarSimModel.save``, with the same checks as ``GarSimModel.load``."""
        from safetensors.numpy import load_file

        config, state = load_verified(directory, cls.kind, load_file)
        try:
            return cls(config, state)
        except KeyError as exc:
            raise WeightsError(
                f"{Path(directory) / WEIGHTS_FILE}: weights do not match config.json: missing {exc.args[0]!r}"
            ) from None

    def _geometry(self, rel: np.ndarray) -> np.ndarray:
        """PointNet++ set abstraction: (M, k, 3) relative positions -> (M, geo_out), max-pooled."""
        w1, b1, w2, b2 = self.geo
        h = _linear(self._act(_linear(rel, w1, b1)), w2, b2)
        if self.config.activation == "relu":  # monotonic: pool first (as the torch encoder)
            return self._act(h.max(axis=1))
        return self._act(h).max(axis=1)

    def forward(self, a: Mapping[str, np.ndarray], static_key: int | None = None) -> np.ndarray:
        """Predicted garment vertices (N, 3), world coordinates, from one graph's ``graph_arrays``. ``static_key``
        names the pose-free arrays (a ``StaticGraph.token``); None: they are keyed by their content."""
        sc = self.scale
        x_gar, x_body, s, mean = self._static(a, static_key)
        fabric = a["fabric"]
        chi = self.garment(np.concatenate([x_gar, fabric, a["p"] * sc, a["p_prior"] * sc], axis=1))
        mu = self.body(np.concatenate([x_body, a["delta"] * sc, s], axis=1))
        node = self.node(np.concatenate([chi, mu], axis=1))
        if self.surface is not None:
            node += self.surface(a["surface"] * self.surface_scale)
        edge = self.edge(a["edge_attr"] * sc)
        node = self._process(node, edge, a["edge_index"], mean, fabric)
        vec = self._decode(node, fabric)
        world = vec @ a["rot"][0]  # R^T v for every row: body frame -> world
        if self.config.local_rotation:  # a rest-frame correction, turned with its neighbourhood
            world = np.einsum("nij,nj->ni", a["local_rot"], world)
        base = a["anchor"] if self.config.head == "position" else a["prior"]
        return (base + world).astype(np.float32)

    __call__ = forward

    def _static(
        self, a: Mapping[str, np.ndarray], static_key: int | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, sp.csr_matrix]:
        """(garment geometry features, body geometry features at the soft anchors, body-semantic rows, the mean
        aggregation's (N, E) matrix): functions of the template garment and the canonical body only, cached by
        ``static_key`` or else by the content of their inputs."""
        names = ("gar_rel", "body_rel", "anchor_index", "anchor_weight", "sem", "edge_index")

        def compute() -> tuple[np.ndarray, np.ndarray, np.ndarray, sp.csr_matrix]:
            n = len(a["gar_rel"])
            rows, slots = a["anchor_index"]
            enc = self._geometry(a["body_rel"])
            blend = sp.csr_matrix((a["anchor_weight"], (rows, slots)), shape=(n, len(enc)))
            s = np.broadcast_to(self.semantic(a["sem"]), (n, self.config.semantic_dim))
            return self._geometry(a["gar_rel"]), np.asarray(blend @ enc, dtype=np.float32), s, _mean_matrix(a, n)

        key = ("token", static_key) if static_key is not None else content_key(*(a[k] for k in names))
        return _STATIC.get((self._token, key), compute)

    def _process(
        self, node: np.ndarray, edge: np.ndarray, edge_index: np.ndarray, mean: sp.csr_matrix, fabric: np.ndarray
    ) -> np.ndarray:
        if self.config.num_steps == 0:
            return node
        snd, rcv = edge_index
        n_edges = len(rcv)
        uniform = bool((fabric == fabric[:1]).all())  # one fabric per garment: FiLM once, broadcast
        # per-chunk work buffers, reused by every chunk and step: the edge rows outnumber the nodes ~6:1, and a
        # chunk's intermediates stay in the core's cache (whole-array passes were ~20% slower at 2,400 vertices)
        rows = max(1, min(n_edges, EDGE_CHUNK))
        hid_buf = np.empty((rows, self.steps[0][3].shape[0]), dtype=np.float32)
        gathered = np.empty_like(hid_buf)
        new_edge = np.empty_like(edge)
        for l in range(self.config.num_steps):
            w_recv, b_recv, w_send, w_edge, rest, node_mlp, film, glob = self.steps[l % len(self.steps)]
            if glob is not None:  # the graph's mean- and max-pooled latents, through an MLP, added to every node
                node = node + glob(np.concatenate([node.mean(axis=0), node.max(axis=0)])[None])
            recv = _linear(node, w_recv, b_recv)  # node terms of the edge MLP's first layer, projected per node
            send = node @ w_send.T
            per_edge = None
            if film is not None and uniform:  # one scale/shift for every edge: folded into the last layer
                scale, shift = np.split(_linear(fabric[:1], *film)[0], 2)
                rest = rest.scaled(np.float32(1.0) + scale, shift)
            elif film is not None:
                per_edge = np.split(_linear(fabric, *film), 2, axis=1)  # per node, taken at each edge's sender
            for lo in range(0, n_edges, rows):
                hi = min(n_edges, lo + rows)
                k = hi - lo
                hid = np.matmul(edge[lo:hi], w_edge.T, out=hid_buf[:k])
                hid += np.take(recv, rcv[lo:hi], axis=0, out=gathered[:k])
                hid += np.take(send, snd[lo:hi], axis=0, out=gathered[:k])
                rest(self._act(hid), out=new_edge[lo:hi])
                if per_edge is not None:
                    chunk = new_edge[lo:hi]
                    chunk *= np.float32(1.0) + per_edge[0][snd[lo:hi]]
                    chunk += per_edge[1][snd[lo:hi]]
            agg = np.asarray(mean @ new_edge, dtype=np.float32)
            new_node = node_mlp(np.concatenate([agg, node], axis=1))
            if self.config.residual:
                node = node + new_node
                edge += new_edge  # edge is this forward's own array (the edge encoder's output)
            else:
                node = new_node
                edge, new_edge = new_edge, edge
        return node

    def _decode(self, node: np.ndarray, fabric: np.ndarray) -> np.ndarray:
        if self.decoder_film is not None:
            scale, shift = np.split(_linear(fabric, *self.decoder_film), 2, axis=1)
            node = node * (np.float32(1.0) + scale) + shift
        out = self.decoder(node)
        if self.config.head != "direction_magnitude":
            return out / self.scale
        direction = out[:, :3] / np.maximum(np.linalg.norm(out[:, :3], axis=1, keepdims=True), np.float32(1e-8))
        magnitude = np.logaddexp(np.float32(0.0), out[:, 3:4]) / self.scale
        if self.fabric_gain is not None:
            magnitude = magnitude * np.exp(_linear(fabric, *self.fabric_gain))
        return direction * magnitude

    def predict(self, sample: Sample | Sequence[Sample]) -> np.ndarray | list[np.ndarray]:
        """Sample(s) -> predicted garment vertices (float32), as ``GarSimModel.predict``."""
        if isinstance(sample, Sample):
            static = static_graph(sample, self.config)
            return self.forward({**static.arrays, **pose_arrays(static, sample)}, static.token)
        return [self.predict(s) for s in sample]  # type: ignore[misc]


def load_for_inference(directory: str | Path) -> GarSimRuntime | GraphModel:
    """The model saved in ``directory`` for draping: the numpy runtime when it implements the model (GarSim with
    the mean aggregation), else the torch model (``garsim.model.baselines.load_model``: the DeePSD-style
    baseline, other aggregations). Both have ``predict(sample)`` and ``config``."""
    config_path = Path(directory) / CONFIG_FILE
    if config_path.exists():
        config, kind = read_model_config(config_path)
        if kind == GarSimRuntime.kind and config.aggregation == "mean":
            return GarSimRuntime.load(directory)
    from garsim.model.baselines import load_model  # torch

    return load_model(directory)
