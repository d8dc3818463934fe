"""The parameter schema of each template family: valid and sampling ranges, validation, sampling."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import ClassVar

import numpy as np


# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------
@dataclass
class _Params:
    """Base: every field is a float with a valid and a sampling range in ``RANGES`` (valid lo, hi, sampling lo, hi)."""

    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {}

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            lo, hi = type(self).RANGES[f.name][:2]
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{type(self).__name__}.{f.name} must be a finite number, got {value!r}")
            if not lo <= value <= hi:
                raise ValueError(
                    f"{type(self).__name__}.{f.name}={value} is out of range; use a value in [{lo}, {hi}] (metres)"
                )
            setattr(self, f.name, float(value))

    def as_dict(self) -> dict[str, float]:
        return {k: v for k, v in asdict(self).items() if not k.startswith("_")}


@dataclass
class SkirtParams(_Params):
    """Skirt: ``length`` from the waistband down, ``flare`` = radius gained per metre below the hip."""

    length: float = 0.45
    flare: float = 0.3
    waist_height: float = 0.0  # waistband offset from the natural waist (negative = low rise)
    looseness: float = 0.015
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.15, 1.1, 0.22, 0.8),
        "flare": (0.0, 1.2, 0.05, 0.7),
        "waist_height": (-0.15, 0.08, -0.08, 0.04),
        "looseness": (0.008, 0.08, 0.01, 0.03),
    }


@dataclass
class TopParams(_Params):
    """Tank top: tube from below the armpits down by ``length``, two straps over the shoulders."""

    length: float = 0.35
    looseness: float = 0.02
    strap_width: float = 0.035
    armpit_clearance: float = 0.045
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.15, 0.8, 0.22, 0.42),  # sampled: hem between the waist and the hips
        "looseness": (0.01, 0.08, 0.015, 0.04),
        "strap_width": (0.015, 0.06, 0.025, 0.05),
        "armpit_clearance": (0.03, 0.1, 0.04, 0.06),
    }


@dataclass
class TShirtParams(_Params):
    """T-shirt: torso tube of ``length`` below the armpits, shoulder panels, short sleeves along the arms."""

    length: float = 0.45
    looseness: float = 0.025
    sleeve_length: float = 0.16
    sleeve_looseness: float = 0.03
    neck_width: float = 0.09  # half-width of the neck opening
    armpit_clearance: float = 0.045
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.15, 0.8, 0.32, 0.55),
        "looseness": (0.012, 0.08, 0.018, 0.04),
        "sleeve_length": (0.06, 0.3, 0.1, 0.22),
        "sleeve_looseness": (0.015, 0.08, 0.02, 0.045),
        "neck_width": (0.06, 0.13, 0.08, 0.11),
        "armpit_clearance": (0.03, 0.1, 0.04, 0.06),
    }


@dataclass
class TrousersParams(_Params):
    """Trousers: waist tube from the waistband to the crotch, two leg tubes of total ``length``."""

    length: float = 0.9
    waist_height: float = 0.0
    looseness: float = 0.02
    leg_opening: float = 0.07  # minimum radius of the leg tubes (straight vs. slim legs)
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.25, 1.2, 0.32, 0.95),  # shorts (mid-thigh) to ankle
        "waist_height": (-0.12, 0.08, -0.06, 0.04),
        "looseness": (0.01, 0.06, 0.015, 0.035),
        "leg_opening": (0.0, 0.15, 0.05, 0.1),
    }


@dataclass
class DressParams(_Params):
    """Strap dress: bodice from below the armpits, skirt flaring below the hip; ``length`` from the armpits."""

    length: float = 0.85
    flare: float = 0.3
    looseness: float = 0.02
    strap_width: float = 0.035
    armpit_clearance: float = 0.045
    RANGES: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "length": (0.45, 1.5, 0.65, 1.1),
        "flare": (0.0, 1.2, 0.05, 0.6),
        "looseness": (0.01, 0.08, 0.015, 0.035),
        "strap_width": (0.015, 0.06, 0.025, 0.05),
        "armpit_clearance": (0.03, 0.1, 0.04, 0.06),
    }


PARAMS: dict[str, type[_Params]] = {
    "skirt": SkirtParams,
    "top": TopParams,
    "tshirt": TShirtParams,
    "trousers": TrousersParams,
    "dress": DressParams,
}


def garment_params(kind: str, params: dict[str, float] | None = None) -> _Params:
    """The validated parameter dataclass of ``kind`` (defaults for missing keys)."""
    if kind not in PARAMS:
        raise ValueError(f"unknown garment kind {kind!r}; choose one of {tuple(PARAMS)}")
    cls = PARAMS[kind]
    params = dict(params or {})
    valid = {f.name for f in fields(cls) if not f.name.startswith("_")}
    unknown = set(params) - valid
    if unknown:
        raise ValueError(f"unknown {kind} parameters {sorted(unknown)}; valid: {sorted(valid)}")
    return cls(**params)


OOD_REACH = 0.6
"""The out-of-distribution region of a parameter reaches this fraction of the way from its sampling
range to its valid limit, on both sides."""


def sample_garment_params(kind: str, rng: np.random.Generator, region: str = "train") -> dict[str, float]:
    """Random parameters of ``kind``: uniform in each field's sampling range (``region="train"``), or
    (``"ood"``) every field just outside it, between the sampling range and the valid limits, on a random side."""
    if kind not in PARAMS:
        raise ValueError(f"unknown garment kind {kind!r}; choose one of {tuple(PARAMS)}")
    if region not in ("train", "ood"):
        raise ValueError(f"region must be 'train' or 'ood', got {region!r}")
    ranges = PARAMS[kind].RANGES
    if region == "train":
        return {name: float(rng.uniform(r[2], r[3])) for name, r in ranges.items()}
    out = {}
    for name, (v_lo, v_hi, s_lo, s_hi) in ranges.items():
        below, above = s_lo - v_lo, v_hi - s_hi
        if above > 0 and (below <= 0 or rng.uniform() < 0.5):
            out[name] = float(s_hi + rng.uniform(0.05, OOD_REACH) * above)
        elif below > 0:
            out[name] = float(s_lo - rng.uniform(0.05, OOD_REACH) * below)
        else:
            out[name] = float(rng.uniform(s_lo, s_hi))
    return out
