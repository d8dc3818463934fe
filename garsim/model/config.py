"""GarSimConfig: every hyperparameter of the model (inputs, encoders, processor, decoder), JSON round-trip."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

HEADS: tuple[str, ...] = ("direction_magnitude", "displacement", "position")
SEMANTIC_MODES: tuple[str, ...] = ("grid", "vertex")


def check_known_keys(cls: type, d: dict[str, Any]) -> None:
    """Refuse keys that are not fields of the dataclass ``cls`` (a config saved by another version)."""
    known = {f.name for f in fields(cls)}
    unknown = set(d) - known
    if unknown:
        raise ValueError(f"unknown {cls.__name__} keys {sorted(unknown)}; known keys: {sorted(known)}")


FABRIC_FEATURES = 3
"""Fabric input per vertex: log bending rigidity, areal density, stretch (silk = 0, leather = 1)."""
SURFACE_FEATURES = 7
"""Target-surface input per vertex (``target_surface``): offset (3) from the prior's soft anchor on the target body,
that body's blended unit normal there (3), the signed distance along it (1); lengths in metres, in the body frame."""


@dataclass
class GarSimConfig:
    """Hyperparameters of GarSim; saved next to the weights as JSON.

    Inputs: ``knn_garment`` / ``knn_body``: slots of the geometry encoder's neighbourhoods (a vertex
    and its mesh 1-ring, nearest first, padded with itself) on the garment and on the body;
    ``canonicalize_yaw`` expresses every vector in a frame fixed to the canonical body's
    heading (exact equivariance to rotations about the vertical axis); ``semantic`` picks
    the body-semantic input: ``"grid"`` (the binary mask over body vertices splatted onto a
    fixed body-normalised grid of ``semantic_grid`` cells, any body topology) or
    ``"vertex"`` (the paper's binary vector over ``num_body_vertices`` body vertices).
    """

    # inputs (Eq. 2)
    knn_garment: int = 10  # garment mesh-ring slots: the vertex and up to 9 neighbours (irregular meshes)
    knn_body: int = 9  # body neighbourhood slots: q and its mesh 1-ring (Anny's valence <= 8)
    canonicalize_yaw: bool = True
    semantic: str = "grid"
    semantic_grid: tuple[int, int, int] = (8, 4, 16)
    num_body_vertices: int | None = None
    pos_scale: float = 10.0  # metres -> network units (decimetres) for every geometric input
    # encoders
    geo_hidden: int = 32
    geo_out: int = 32
    semantic_dim: int = 32
    latent: int = 64  # node latent size (η, χ, μ)
    edge_latent: int = 32  # edge latent size (π); edges outnumber nodes ~6:1, so they are kept narrower
    mlp_hidden: int = 64
    mlp_layers: int = 1  # hidden layers per MLP
    activation: str = "relu"  # as MeshGraphNets; ~1.6x cheaper than SiLU on CPU per element
    # processor (Algorithm 1)
    num_steps: int = 5
    aggregation: str = "mean"
    share_weights: bool = False
    residual: bool = True
    layer_norm: bool = True  # LayerNorm after the node-update and encoder MLPs (MeshGraphNets)
    edge_layer_norm: bool = False  # LayerNorm after the edge encoder/update MLPs: on (E, 32) rows it costs
    # ~2.5x the MLP's own matmul on CPU (~20% of inference), so edges rely on the node LayerNorms
    # decoder
    head: str = "direction_magnitude"
    magnitude_bias_init: float = -3.0
    # fabric conditioning (a deviation: the paper concatenates a one-hot f to the node input only)
    fabric_film: bool = True  # the fabric's physical values also scale/shift every edge update (FiLM) and the magnitude
    # ... and the processed node latents before the decoder (FiLM that no LayerNorm follows; off in the shipped model)
    fabric_decoder_film: bool = False
    # global context (a deviation: the paper's processor passes messages along mesh edges only, so after L steps a
    # vertex knows the garment within L edges; a top's hem cannot see the shoulders that lift it). Before each step
    # every node gets an MLP of its graph's mean- and max-pooled latents (zero-initialised: off at the start)
    global_context: bool = False
    # target surface (a deviation: the paper's body inputs are taken at q_i on the canonical body and its motion δ,
    # so a vertex cannot see another body part that the target pose brings near it, e.g. an arm lowered against a
    # top's side). Per vertex, the prior's soft anchor on the *target* body: the offset from that surface point, the
    # surface's blended normal and the signed distance along it, encoded by an MLP added to the node latents
    # (zero-initialised: off at the start)
    target_surface: bool = False
    # local rotation (a deviation: the paper adds the decoded vector to G^prior as it is, in one frame for the whole
    # garment). The decoded correction is taken as one in the template's rest frame and turned, per vertex, by the
    # rotation that carries the template's mesh neighbourhood onto the prior's (``bodies.prior.rotations_between``), as
    # DeePSD skins its pose-space displacements: a sleeve's learned correction turns with the arm. No weights of its own
    local_rotation: bool = False

    def __post_init__(self) -> None:
        self.semantic_grid = tuple(int(v) for v in self.semantic_grid)  # type: ignore[assignment]
        if self.head not in HEADS:
            raise ValueError(f"unknown head {self.head!r}; choose one of {HEADS}")
        if self.semantic not in SEMANTIC_MODES:
            raise ValueError(f"unknown semantic mode {self.semantic!r}; choose one of {SEMANTIC_MODES}")
        if self.semantic == "vertex" and not self.num_body_vertices:
            raise ValueError("semantic='vertex' needs num_body_vertices (the body topology's vertex count)")
        if len(self.semantic_grid) != 3 or min(self.semantic_grid) < 2:
            raise ValueError(f"semantic_grid must be 3 sizes >= 2, got {self.semantic_grid}")
        for name in (
            "knn_garment",
            "knn_body",
            "latent",
            "edge_latent",
            "mlp_hidden",
            "geo_hidden",
            "geo_out",
            "semantic_dim",
        ):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.num_steps < 0:
            raise ValueError(f"num_steps must be >= 0, got {self.num_steps}")

    @property
    def semantic_input_dim(self) -> int:
        """Length of the body-semantic input vector."""
        if self.semantic == "vertex":
            return int(self.num_body_vertices)  # type: ignore[arg-type]
        gx, gy, gz = self.semantic_grid
        return gx * gy * gz

    @property
    def surface_scale(self) -> tuple[float, ...]:
        """Per target-surface feature, its factor into network units (lengths by ``pos_scale``, the normal as is)."""
        return (self.pos_scale,) * 3 + (1.0,) * 3 + (self.pos_scale,)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON dict (tuples become lists)."""
        d = asdict(self)
        d["semantic_grid"] = list(self.semantic_grid)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GarSimConfig:
        """Inverse of ``to_dict``; unknown keys are an error."""
        check_known_keys(cls, d)
        return cls(**d)

    def to_json(self, path: str | Path | None = None) -> str:
        """Serialise to JSON text, also writing ``path`` when given."""
        text = json.dumps(self.to_dict(), indent=2, sort_keys=True)
        if path is not None:
            Path(path).write_text(text)
        return text

    @classmethod
    def from_json(cls, text_or_path: str | Path) -> GarSimConfig:
        """Read from JSON text or a path to a JSON file."""
        p = Path(text_or_path) if not str(text_or_path).lstrip().startswith("{") else None
        text = p.read_text() if p is not None else str(text_or_path)
        return cls.from_dict(json.loads(text))
