"""Fabrics in physical units, the same at every mesh resolution.

A fabric is a point in a small physical space: bending rigidity ``bending`` (N·m, the continuum
plate's B), areal density ``density`` (kg/m²), membrane stiffness ``stretch`` (N/m), a bending
damping time constant, Coulomb friction against the body and a collision thickness. The four
named presets are points in that space; :func:`interpolate_fabric` gives any fabric between them.

Conversion to a simulator (:func:`edge_bending_stiffness`): Newton's VBD hinge energy per interior
edge is 0.5 * ``edge_ke`` * L * (theta - theta_rest)² (``particle_vbd_kernels.py``: the stiffness is
multiplied by the rest edge length L). The discrete-shells bending energy (Grinspun et al. 2003) of
a plate with rigidity B is B * 3 L² / (A1 + A2) * theta² / 2 per edge (A1, A2 the two adjacent
triangles' areas), so ``edge_ke = 3 * B * L / (A1 + A2)``, per edge: a fine mesh gets proportionally
stiffer hinges and a fabric drapes alike at every resolution.

Preset values (bending rigidity converted with 1 gf·cm²/cm = 9.81e-5 N·m):
- Kawabata KES-FB2 pure-bending measurements of apparel fabrics (Kawabata & Niwa, "Fabric
  performance in clothing and clothing manufacture", J. Textile Inst. 80(1), 1989; Kawabata, "The
  standardization and analysis of hand evaluation", 1980) put silks and light shirtings at about
  0.005-0.05 gf·cm²/cm, cottons at 0.05-0.2, and heavy denims at 0.5-3 gf·cm²/cm.
- Wang, O'Brien & Ramamoorthi, "Data-driven elastic models for cloth" (SIGGRAPH 2011) measured ten
  fabrics with bending stiffnesses spanning about two orders of magnitude, denim at the top.
- Garment leather of 0.6-1.2 mm is one to two orders stiffer than denim (1e-3 to 1e-2 N·m; cantilever
  tests after Peirce 1930, "The handle of cloth as a measurable quantity"); the preset takes 5e-3 N·m.
Areal densities are typical weights: silk habotai ~60-80 g/m², cotton poplin/jersey 120-180 g/m²,
denim 12-14 oz/yd² (400-480 g/m²), garment leather 0.8-1.0 kg/m².
Membrane stiffness barely changes a drape under self-weight (strain ~1e-4 for any value in 1e3..3e4
N/m, measured): it is kept high enough that VBD holds the stretch check (edges <= 1.5x rest).

Measured (tests/test_physics_newton_sim.py, a 400-vertex flared skirt settled once in cotton, then held
in each preset until its mean speed fell below ``SimConfig.settle_speed`` = 2 cm/s): mean distance to the
body 44.3 / 44.3 / 44.4 / 46.3 mm, silk to leather, and the mean fold angle strictly decreasing. With real
bending values the light fabrics differ in their folds (on a fine mesh), the stiff ones a little in their silhouette.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

PRESET_NAMES: tuple[str, ...] = ("silk", "cotton", "denim", "leather")
"""Preset names, lightest to stiffest (the model's one-hot order)."""

GF_CM2_PER_CM = 9.80665e-5
"""One gram-force square centimetre per centimetre (Kawabata's bending unit) in N·m."""


@dataclass(frozen=True)
class Fabric:
    """Physical parameters of one fabric (SI units)."""

    name: str
    bending: float  # bending rigidity B, N·m
    density: float  # areal density, kg/m²
    stretch: float  # membrane stiffness (Neo-Hookean Lamé mu = lambda), N/m
    friction: float = 0.5  # Coulomb friction against the body
    bending_damping: float = 5.0e-5  # s: bending damping = this x bending stiffness
    stretch_damping: float = 1.0e-3  # N s/m: membrane strain-rate damping
    thickness: float = 0.002  # m: collision radius of each cloth particle

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "name":
                continue
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"fabric {self.name!r}: {f.name}={value!r} must be a finite number >= 0")
        for key in ("bending", "density", "stretch"):
            if getattr(self, key) <= 0:
                raise ValueError(f"fabric {self.name!r}: {key} must be > 0")

    def values(self) -> dict[str, float]:
        """The physical values (no name), e.g. to store beside a sample."""
        d = asdict(self)
        d.pop("name")
        return d

    @property
    def bending_length(self) -> float:
        """Peirce's bending length (B / (rho g))^(1/3) in metres: the scale below which the fabric stays flat."""
        return (self.bending / (self.density * 9.81)) ** (1.0 / 3.0)


PRESETS: dict[str, Fabric] = {
    "silk": Fabric("silk", bending=0.02 * GF_CM2_PER_CM, density=0.07, stretch=3.0e3, friction=0.3),
    "cotton": Fabric("cotton", bending=0.12 * GF_CM2_PER_CM, density=0.15, stretch=5.0e3, friction=0.5),
    "denim": Fabric("denim", bending=3.0 * GF_CM2_PER_CM, density=0.42, stretch=1.0e4, friction=0.6),
    "leather": Fabric("leather", bending=50.0 * GF_CM2_PER_CM, density=0.9, stretch=2.0e4, friction=0.7),
}
"""The presets (see the module docstring for their sources), in ``PRESET_NAMES`` order."""

_LOG_KEYS = ("bending", "density", "stretch")
MIN_HINGE_AREA_RATIO = 0.1
"""Floor of (A1 + A2) / L² in :func:`edge_bending_stiffness` (an equilateral pair has 0.87)."""


def get_fabric(fabric: str | Fabric) -> Fabric:
    """A preset by name (case-insensitive), or a given ``Fabric`` unchanged."""
    if isinstance(fabric, Fabric):
        return fabric
    if isinstance(fabric, str) and fabric.strip().lower() in PRESETS:
        return PRESETS[fabric.strip().lower()]
    raise ValueError(f"unknown fabric {fabric!r}; choose one of {list(PRESETS)} or pass a Fabric")


def fabric_from_values(values: dict[str, float], name: str = "custom") -> Fabric:
    """A ``Fabric`` from stored physical values (``Fabric.values()``); missing optional keys take defaults.
    Raises ValueError naming the missing or unknown keys."""
    optional = [f.name for f in fields(Fabric) if f.name not in ("name", *_LOG_KEYS)]
    missing = [k for k in _LOG_KEYS if k not in values]
    unknown = sorted(set(values) - set(_LOG_KEYS) - set(optional))
    problems = [f"{what} {', '.join(keys)}" for what, keys in (("missing", missing), ("unknown", unknown)) if keys]
    if problems:
        raise ValueError(
            f"fabric values: {'; '.join(problems)}; give bending (N·m), density (kg/m²), stretch (N/m), optionally "
            + ", ".join(optional)
        )
    return Fabric(name=name, **values)


def interpolate_fabric(a: str | Fabric, b: str | Fabric, t: float, name: str = "custom") -> Fabric:
    """The fabric at ``t`` in [0, 1] between ``a`` and ``b``: log-linear in bending, density and stretch,
    linear in the rest."""
    if not (0.0 <= t <= 1.0):
        raise ValueError(f"interpolation parameter t must be in [0, 1], got {t}")
    fa, fb = get_fabric(a), get_fabric(b)
    va, vb = fa.values(), fb.values()
    out = {}
    for key in va:
        if key in _LOG_KEYS:
            out[key] = float(math.exp((1 - t) * math.log(va[key]) + t * math.log(vb[key])))
        else:
            out[key] = float((1 - t) * va[key] + t * vb[key])
    return Fabric(name=name, **out)


def stiffness_coordinate(fabric: str | Fabric) -> float:
    """Where a fabric's bending rigidity lies on the log scale from silk (0) to leather (1) (may be outside)."""
    b = get_fabric(fabric).bending
    lo, hi = math.log(PRESETS["silk"].bending), math.log(PRESETS["leather"].bending)
    return (math.log(b) - lo) / (hi - lo)


def nearest_preset(fabric: str | Fabric) -> str:
    """The preset name closest to ``fabric`` in log bending rigidity."""
    b = math.log(get_fabric(fabric).bending)
    return min(PRESET_NAMES, key=lambda n: abs(math.log(PRESETS[n].bending) - b))


def sample_fabric(rng: np.random.Generator, name: str = "custom") -> Fabric:
    """A random fabric between silk and leather: log-uniform bending, density and stretch loosely tied to it."""
    t = float(rng.uniform(0.0, 1.0))
    base = interpolate_fabric("silk", "leather", t)
    jitter = np.exp(rng.normal(0.0, 0.25, size=2))
    lo_d, hi_d = PRESETS["silk"].density, PRESETS["leather"].density
    lo_s, hi_s = PRESETS["silk"].stretch, PRESETS["leather"].stretch
    density = float(np.clip(base.density * jitter[0], lo_d, hi_d))
    stretch = float(np.clip(base.stretch * jitter[1], lo_s, hi_s))
    values = base.values() | {"density": density, "stretch": stretch}
    return Fabric(name=name, **values)


def edge_bending_stiffness(bending: float, vertices: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """Per-hinge stiffness ``3 B L / (A1 + A2)`` (N) for Newton's VBD hinges.

    ``hinges`` is (E, 4) in Newton's ``edge_indices`` order (opposite vertex 1, opposite vertex 2,
    edge vertex 1, edge vertex 2), -1 for a missing opposite vertex (a border edge: stiffness 0).
    """
    v = np.asarray(vertices, dtype=np.float64)
    h = np.asarray(hinges, dtype=np.int64)
    interior = (h[:, 0] >= 0) & (h[:, 1] >= 0)
    out = np.zeros(len(h), dtype=np.float64)
    if not interior.any():
        return out
    o1, o2, a, b = (h[interior, k] for k in range(4))
    e = v[b] - v[a]
    length = np.linalg.norm(e, axis=1)
    area1 = 0.5 * np.linalg.norm(np.cross(e, v[o1] - v[a]), axis=1)
    area2 = 0.5 * np.linalg.norm(np.cross(e, v[o2] - v[a]), axis=1)
    # a sliver triangle would give a near-infinite hinge: floor the area at that of a thin triangle
    out[interior] = 3.0 * bending * length / np.maximum(area1 + area2, MIN_HINGE_AREA_RATIO * length**2)
    return out
