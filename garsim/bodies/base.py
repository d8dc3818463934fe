"""The body interface every body model implements (Anny, a bare mesh pair, ...)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PosedBody:
    """A posed body: vertices and, for rigged bodies, per-bone skinning transforms.

    ``transforms[j]`` maps the model's rest vertices to posed space for bone ``j``
    (so linear blend skinning of ``BodyModel.rest_vertices`` gives ``vertices``).
    """

    vertices: np.ndarray  # (V, 3) float32
    transforms: np.ndarray | None = None  # (J, 4, 4) float64


class BodyModel(ABC):
    """Rest mesh, faces, skinning weights, and posing."""

    @property
    @abstractmethod
    def faces(self) -> np.ndarray:
        """(F, 3) int64 triangles."""

    @property
    @abstractmethod
    def rest_vertices(self) -> np.ndarray:
        """(V, 3) vertices that ``PosedBody.transforms`` act on."""

    @property
    @abstractmethod
    def skin_weights(self) -> np.ndarray | None:
        """(V, K) skinning weights (rows sum to 1), or None for an unrigged body."""

    @property
    @abstractmethod
    def skin_indices(self) -> np.ndarray | None:
        """(V, K) bone index per weight, or None for an unrigged body."""

    @abstractmethod
    def canonical(self) -> PosedBody:
        """The body in its canonical pose (the T-pose for Anny)."""

    @abstractmethod
    def pose(self, pose: object) -> PosedBody:
        """The body in a target pose."""

    @property
    def num_vertices(self) -> int:
        return len(self.rest_vertices)
