"""The garment record shared by templates, the simulator and the model."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Garment:
    """A triangle mesh garment with its pinned-vertex mask (the paper's index vector I)."""

    vertices: np.ndarray  # (N, 3) float32, metres, Z up
    faces: np.ndarray  # (F, 3) int64
    pinned: np.ndarray  # (N,) bool: waistband, straps/shoulders
    kind: str  # one of garsim.data.sample.GARMENT_TYPES
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float32)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int64)
        self.pinned = np.ascontiguousarray(self.pinned, dtype=bool)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"garment vertices must be (N, 3), got {self.vertices.shape}")
        if self.pinned.shape != (len(self.vertices),):
            raise ValueError(f"pinned mask {self.pinned.shape} does not match {len(self.vertices)} vertices")

    @property
    def num_vertices(self) -> int:
        return len(self.vertices)
