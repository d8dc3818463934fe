"""Fabric presets: the table, lookup, validation, and the physical ladder silk < cotton < denim < leather."""

from __future__ import annotations

import dataclasses

import pytest

from garsim.data.sample import FABRICS as FABRIC_NAMES
from garsim.garments.fabrics import FABRICS, Fabric, get_fabric


def test_table_matches_the_one_hot_order():
    assert tuple(FABRICS) == FABRIC_NAMES
    for name, fabric in FABRICS.items():
        assert fabric.name == name


def test_bending_and_density_increase_from_silk_to_leather():
    # Bending stiffness is the lever that separates drapes (DESIGN.md); it grows >= 3x per step.
    ladder = [FABRICS[n] for n in ("silk", "cotton", "denim", "leather")]
    for a, b in zip(ladder, ladder[1:]):
        assert b.edge_ke >= 3 * a.edge_ke
        assert b.density > a.density
        assert b.tri_ke >= a.tri_ke


def test_bending_length_scale_orders_fabrics():
    # Discrete bending 0.5*ke*L*theta^2 ~ continuum modulus B = ke*h for edge length h; the gravity
    # bending length (B / (density * g))^(1/3) sets fold size: silk ~1 cm, leather >> 10 cm (h = 3 cm).
    h = 0.03
    lengths = {n: (f.edge_ke * h / (f.density * 9.81)) ** (1 / 3) for n, f in FABRICS.items()}
    assert lengths["silk"] < 0.02
    assert lengths["silk"] < lengths["cotton"] < lengths["denim"] < lengths["leather"]
    assert lengths["leather"] > 0.2


def test_get_fabric_by_name_or_instance():
    assert get_fabric("silk") is FABRICS["silk"]
    assert get_fabric(" Denim ") is FABRICS["denim"]
    custom = dataclasses.replace(FABRICS["cotton"], name="stiff-cotton", edge_ke=0.5)
    assert get_fabric(custom) is custom


def test_unknown_fabric_lists_valid_names():
    with pytest.raises(ValueError, match="silk.*cotton.*denim.*leather"):
        get_fabric("wool")
    with pytest.raises(ValueError, match="choose one of"):
        get_fabric(3)  # type: ignore[arg-type]


def test_presets_are_frozen_and_validated():
    with pytest.raises(dataclasses.FrozenInstanceError):
        FABRICS["silk"].density = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError, match="density"):
        Fabric("bad", density=-0.1, tri_ke=1e3, tri_ka=1e3, tri_kd=0, edge_ke=1e-3, edge_kd=0, friction=0.5)
    with pytest.raises(ValueError, match="edge_ke"):
        Fabric("bad", density=0.1, tri_ke=1e3, tri_ka=1e3, tri_kd=0, edge_ke=float("nan"), edge_kd=0, friction=0.5)
