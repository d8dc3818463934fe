"""garsim: a particle-based neural garment simulator (drape any garment onto any body pose)."""

from garsim.api import GarSim
from garsim.data.sample import FABRICS, GARMENT_TYPES, Sample
from garsim.geometry.io import MeshError, load_mesh, save_mesh

__all__ = ["GarSim", "Sample", "FABRICS", "GARMENT_TYPES", "MeshError", "load_mesh", "save_mesh"]
__version__ = "0.1.0"
