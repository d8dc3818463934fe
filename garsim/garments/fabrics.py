"""Fabric presets: physical parameters for Newton's VBD cloth solver, one table for all fabrics.

Units follow Newton's ``particle_vbd_kernels.py``: ``tri_ke``/``tri_ka`` are the Neo-Hookean
membrane's Lamé parameters mu/lambda in N/m; the bending energy per interior edge is
0.5 * ``edge_ke`` * (rest edge length) * (theta - theta_rest)^2 with ``edge_ke`` in N (rest
angles are zeroed by the simulator: fabric is cut flat); ``tri_kd`` (N s/m) damps strain rate and
``edge_kd`` (N s) bending rate. Stretch stiffness barely changes a drape under self-weight
(strain ~1e-4 for any value 1e3..3e4 N/m), so bending stiffness and areal density carry the
difference between fabrics (values chosen by measurement; see ``tests/test_garments_fabrics.py``
and the fabric-ordering test in ``tests/test_physics_newton_sim.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields


@dataclass(frozen=True)
class Fabric:
    """Physical parameters of one fabric for VBD cloth (SI units)."""

    name: str
    density: float  # areal density, kg/m^2
    tri_ke: float  # membrane Lamé mu, N/m
    tri_ka: float  # membrane Lamé lambda, N/m
    tri_kd: float  # membrane strain-rate damping, N s/m
    edge_ke: float  # bending stiffness, N (energy 0.5 * ke * L_rest * dtheta^2)
    edge_kd: float  # bending damping, N s
    friction: float  # Coulomb friction against the body
    thickness: float = 0.002  # collision radius of each cloth particle, m

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "name":
                continue
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"fabric {self.name!r}: {f.name}={value!r} must be a finite number >= 0")
        if self.density <= 0 or self.tri_ke <= 0:
            raise ValueError(f"fabric {self.name!r}: density and tri_ke must be > 0")


FABRICS: dict[str, Fabric] = {
    "silk": Fabric("silk", density=0.08, tri_ke=3.0e3, tri_ka=3.0e3, tri_kd=1.0e-3,
                   edge_ke=5.0e-5, edge_kd=1.0e-6, friction=0.3),
    "cotton": Fabric("cotton", density=0.15, tri_ke=5.0e3, tri_ka=5.0e3, tri_kd=1.0e-3,
                     edge_ke=0.8, edge_kd=1.0e-5, friction=0.5),
    "denim": Fabric("denim", density=0.35, tri_ke=1.0e4, tri_ka=1.0e4, tri_kd=1.0e-3,
                    edge_ke=5.0, edge_kd=1.0e-4, friction=0.6),
    "leather": Fabric("leather", density=0.8, tri_ke=2.0e4, tri_ka=2.0e4, tri_kd=1.0e-3,
                      edge_ke=30.0, edge_kd=1.0e-3, friction=0.7),
}
"""Presets in ``garsim.data.sample.FABRICS`` order (silk, cotton, denim, leather).

Measured on the template skirt (length 0.45, flare 0.5, 800 v) settled on the default T-pose body:
mean garment-to-body distance 36.4 / 40.4 / 45.5 / 54.3 mm and mean fold angle 18.3 / 11.9 / 7.8 /
5.8 degrees for silk / cotton / denim / leather (``edge_ke`` ladders below 1 N gave gaps under 3 mm).
The bending term scales with edge length, so these values are tuned for ~2-3 cm edges."""


def get_fabric(fabric: "str | Fabric") -> Fabric:
    """A preset by name (case-insensitive), or a given ``Fabric`` unchanged."""
    if isinstance(fabric, Fabric):
        return fabric
    if isinstance(fabric, str) and fabric.strip().lower() in FABRICS:
        return FABRICS[fabric.strip().lower()]
    raise ValueError(f"unknown fabric {fabric!r}; choose one of {list(FABRICS)} or pass a Fabric")
