"""garsim: a particle-based neural garment simulator (drape any garment onto any body pose).

The names below are imported on first use, so that ``import garsim.cli`` (and ``garsim --help``) loads
neither numpy nor torch.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from garsim.api import GarSim
    from garsim.data.sample import FABRICS, GARMENT_TYPES, Sample
    from garsim.geometry.io import MeshError, load_mesh, save_mesh

_LAZY: dict[str, str] = {
    "GarSim": "garsim.api",
    "Sample": "garsim.data.sample",
    "FABRICS": "garsim.data.sample",
    "GARMENT_TYPES": "garsim.data.sample",
    "MeshError": "garsim.geometry.io",
    "load_mesh": "garsim.geometry.io",
    "save_mesh": "garsim.geometry.io",
}

__all__ = ["GarSim", "Sample", "FABRICS", "GARMENT_TYPES", "MeshError", "load_mesh", "save_mesh"]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'garsim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
