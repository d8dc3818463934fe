"""The sample record: one garment on one body, canonical -> target, as the model sees it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

FABRICS: tuple[str, ...] = ("silk", "cotton", "denim", "leather")
"""Preset fabric names, lightest to stiffest (their physical values: ``garsim.garments.fabrics``)."""
CUSTOM_FABRIC = "custom"
"""The fabric name of a sample given by physical values (``Sample.fabric_values``) rather than a preset."""

GARMENT_TYPES: tuple[str, ...] = ("skirt", "top", "tshirt", "longsleeve", "trousers", "dress")


@dataclass
class Sample:
    """A garment template on a canonical body and the same body in a target pose.

    Arrays are float32 (positions, metres, Z up) or int64 (faces); ``target`` is the
    ground-truth garment on the target body (``None`` at inference time).
    """

    body_canonical: np.ndarray  # (Vb, 3)
    body_target: np.ndarray  # (Vb, 3)
    body_faces: np.ndarray  # (Fb, 3)
    garment: np.ndarray  # (N, 3) template draped on the canonical body (G)
    garment_faces: np.ndarray  # (Fg, 3)
    pinned: np.ndarray  # (N,) bool: the paper's index vector I
    prior: np.ndarray  # (N, 3) LBS deformation prior G^prior
    fabric: str
    garment_type: str
    target: np.ndarray | None = None  # (N, 3) ground truth G-bar
    meta: dict[str, Any] = field(default_factory=dict)
    fabric_values: dict[str, float] | None = (
        None  # physical values (bending N·m, density kg/m², ...), else the preset's
    )

    def __post_init__(self) -> None:
        n = len(self.garment)
        if self.fabric not in FABRICS and not (self.fabric == CUSTOM_FABRIC and self.fabric_values):
            raise ValueError(f"unknown fabric {self.fabric!r}; choose one of {FABRICS} (or physical values)")
        if self.body_canonical.shape != self.body_target.shape:
            raise ValueError(
                f"canonical body {self.body_canonical.shape} and target body "
                f"{self.body_target.shape} must share one topology"
            )
        for name in ("prior", "target"):
            arr = getattr(self, name)
            if arr is not None and arr.shape != (n, 3):
                raise ValueError(f"{name} has shape {arr.shape}, expected ({n}, 3) like the garment")
        if self.pinned.shape != (n,):
            raise ValueError(f"pinned mask has shape {self.pinned.shape}, expected ({n},)")
