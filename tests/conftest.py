"""Shared fixtures: one Anny body per test session and a tiny synthetic closed mesh."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def anny_body():
    """The default-phenotype AnnyBody (built once per session, ~1-3 s; model data cached in ~/.cache/garsim)."""
    from garsim.bodies.anny import AnnyBody

    return AnnyBody({})


@pytest.fixture(scope="session")
def icosphere() -> tuple[np.ndarray, np.ndarray]:
    """A closed, outward-oriented unit icosphere (642 vertices, 1280 faces): float32 vertices, int64 faces."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    return np.asarray(m.vertices, dtype=np.float32), np.asarray(m.faces, dtype=np.int64)
