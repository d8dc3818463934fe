"""Fabrics in physical units: the presets, interpolation, sampling, and the per-hinge conversion."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from garsim.data.sample import FABRICS as FABRIC_NAMES
from garsim.garments.fabrics import (
    GF_CM2_PER_CM,
    PRESET_NAMES,
    PRESETS,
    Fabric,
    edge_bending_stiffness,
    fabric_from_values,
    get_fabric,
    interpolate_fabric,
    nearest_preset,
    sample_fabric,
    stiffness_coordinate,
)


def test_table_matches_the_one_hot_order():
    assert tuple(PRESETS) == FABRIC_NAMES == PRESET_NAMES
    for name, fabric in PRESETS.items():
        assert fabric.name == name


def test_presets_lie_in_published_ranges_and_are_ordered():
    # Kawabata bending rigidity in gf cm^2/cm: silk ~0.005-0.05, cotton 0.05-0.2, denim 0.5-3, leather 10-100
    kes = {n: f.bending / GF_CM2_PER_CM for n, f in PRESETS.items()}
    assert 0.005 <= kes["silk"] <= 0.05 and 0.05 <= kes["cotton"] <= 0.2
    assert 0.5 <= kes["denim"] <= 3.0 and 10.0 <= kes["leather"] <= 100.0
    ladder = [PRESETS[n] for n in PRESET_NAMES]
    for a, b in zip(ladder, ladder[1:]):
        assert b.bending >= 3 * a.bending and b.density > a.density
    # Peirce's bending length: ~1 cm silk ... ~5+ cm leather
    assert 0.005 < PRESETS["silk"].bending_length < 0.015 < PRESETS["leather"].bending_length


def test_hinge_stiffness_of_an_equilateral_pair_by_hand():
    # two equilateral triangles of side a sharing an edge: A1 + A2 = sqrt(3)/2 a^2, so ke = 3 B a / (sqrt(3)/2 a^2)
    a, b = 0.02, 1e-5
    v = np.array([[0, 0, 0], [a, 0, 0], [a / 2, a * math.sqrt(3) / 2, 0], [a / 2, -a * math.sqrt(3) / 2, 0]])
    hinges = np.array([[2, 3, 0, 1], [-1, 3, 0, 3]])  # an interior hinge and a border edge
    ke = edge_bending_stiffness(b, v, hinges)
    assert ke[0] == pytest.approx(2 * math.sqrt(3) * b / a) and ke[1] == 0.0
    # halving the mesh spacing doubles the hinge stiffness (same fabric, same drape)
    assert edge_bending_stiffness(b, v / 2, hinges)[0] == pytest.approx(2 * ke[0])
    # a sliver triangle does not give an unbounded hinge
    sliver = v.copy()
    sliver[2, 1] = 1e-9
    sliver[3, 1] = -1e-9
    assert edge_bending_stiffness(b, sliver, hinges)[0] <= 3 * b * a / (0.1 * a * a) * 1.0001


def test_interpolation_between_presets_is_monotone_and_exact_at_the_ends():
    a = interpolate_fabric("silk", "leather", 0.0)
    assert a.values() == pytest.approx(PRESETS["silk"].values())
    assert interpolate_fabric("silk", "leather", 1.0).bending == pytest.approx(PRESETS["leather"].bending)
    mids = [interpolate_fabric("cotton", "denim", t) for t in (0.25, 0.5, 0.75)]
    assert PRESETS["cotton"].bending < mids[0].bending < mids[1].bending < mids[2].bending < PRESETS["denim"].bending
    assert stiffness_coordinate("silk") == pytest.approx(0.0) and stiffness_coordinate("leather") == pytest.approx(1.0)
    assert nearest_preset(mids[0]) == "cotton" and nearest_preset(mids[2]) == "denim"
    with pytest.raises(ValueError, match="t must be in"):
        interpolate_fabric("silk", "denim", 1.5)


def test_sampled_fabrics_stay_between_silk_and_leather_and_round_trip():
    rng = np.random.default_rng(0)
    samples = [sample_fabric(rng) for _ in range(200)]
    coords = np.array([stiffness_coordinate(f) for f in samples])
    assert coords.min() >= -1e-9 and coords.max() <= 1 + 1e-9 and coords.std() > 0.2  # log-uniform spread
    for f in samples[:5]:
        assert fabric_from_values(f.values()).values() == f.values()


def test_get_fabric_by_name_or_instance():
    assert get_fabric("silk") is PRESETS["silk"]
    assert get_fabric(" Denim ") is PRESETS["denim"]
    custom = dataclasses.replace(PRESETS["cotton"], name="stiff-cotton", bending=1e-4)
    assert get_fabric(custom) is custom


def test_unknown_fabric_lists_valid_names():
    with pytest.raises(ValueError, match="silk.*cotton.*denim.*leather"):
        get_fabric("wool")
    with pytest.raises(ValueError, match="choose one of"):
        get_fabric(3)  # type: ignore[arg-type]


def test_presets_are_frozen_and_validated():
    with pytest.raises(dataclasses.FrozenInstanceError):
        PRESETS["silk"].density = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError, match="density"):
        Fabric("bad", bending=1e-5, density=-0.1, stretch=1e3)
    with pytest.raises(ValueError, match="bending"):
        Fabric("bad", bending=float("nan"), density=0.1, stretch=1e3)
    with pytest.raises(ValueError, match="bending must be > 0"):
        Fabric("bad", bending=0.0, density=0.1, stretch=1e3)


def test_fabric_values_name_the_missing_and_unknown_keys():
    with pytest.raises(ValueError, match=r"missing stretch; give bending"):
        fabric_from_values({"bending": 1e-5, "density": 0.2})
    with pytest.raises(ValueError, match=r"missing bending, stretch; unknown colour"):
        fabric_from_values({"density": 0.2, "colour": 1.0})
    f = fabric_from_values({"bending": 1e-5, "density": 0.2, "stretch": 3000.0, "friction": 0.3})
    assert f.friction == 0.3 and f.thickness == Fabric.thickness  # optional keys default
