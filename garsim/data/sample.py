"""The sample record: one garment on one body, canonical -> target, as the model sees it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

FABRICS: tuple[str, ...] = ("silk", "cotton", "denim", "leather")
"""Fabric names in one-hot order (the paper's f)."""

GARMENT_TYPES: tuple[str, ...] = ("skirt", "top", "tshirt", "trousers", "dress")


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

    def __post_init__(self) -> None:
        n = len(self.garment)
        if self.fabric not in FABRICS:
            raise ValueError(f"unknown fabric {self.fabric!r}; choose one of {FABRICS}")
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

    @property
    def fabric_index(self) -> int:
        return FABRICS.index(self.fabric)
