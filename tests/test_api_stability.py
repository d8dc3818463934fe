"""The shipped model through the public API is stable, equivariant and leaves a resting garment in place.

Every check goes through ``GarSim.pretrained().drape(...)`` with default settings on mesh pairs, as a
user would call it: tiny input changes, a file round trip, reordered faces or vertices, and the whole
scene turned about the vertical or moved by 10 m change no output vertex by more than 0.5 mm.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from garsim import GarSim
from garsim.geometry.io import save_mesh

BOUND_MM = 0.5


@lru_cache(maxsize=1)
def scene():
    """A settled-looking template (skirt) on an Anny T-pose body, and the body in a walking pose."""
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.poses import walk_pose
    from garsim.garments.templates import make_garment

    body = AnnyBody()
    can = body.canonical()
    tgt = body.pose({b: v[0] for b, v in walk_pose(0.8, stride=0.5).items()})
    g = make_garment("skirt", body, {"length": 0.5, "flare": 0.4}, target_vertices=600)
    return (can.vertices.astype(np.float64), body.faces), (tgt.vertices.astype(np.float64), body.faces), g


@lru_cache(maxsize=1)
def sim() -> GarSim:
    return GarSim.pretrained()


def drape(canonical, target, garment, **kw) -> np.ndarray:
    return np.asarray(sim().drape(canonical, target, garment, fabric=kw.pop("fabric", "denim"), **kw), dtype=np.float64)


@lru_cache(maxsize=1)
def reference() -> np.ndarray:
    can, tgt, g = scene()
    return drape(can, tgt, (g.vertices, g.faces))


def _max_mm(a: np.ndarray, b: np.ndarray) -> float:
    return 1000.0 * float(np.abs(a - b).max())


def test_noise_on_every_input_vertex_moves_no_output_vertex():
    can, tgt, g = scene()
    rng = np.random.default_rng(0)
    noisy = [(v + rng.normal(0, 1e-6, v.shape), f) for v, f in (can, tgt, (g.vertices, g.faces))]
    assert _max_mm(drape(*noisy), reference()) < BOUND_MM


def test_obj_round_trip_of_the_garment(tmp_path):
    can, tgt, g = scene()
    path = tmp_path / "garment.obj"
    save_mesh(path, g.vertices, g.faces)
    assert _max_mm(drape(can, tgt, str(path)), reference()) < BOUND_MM


def test_face_and_vertex_permutations():
    can, tgt, g = scene()
    rng = np.random.default_rng(1)
    faces = g.faces[rng.permutation(len(g.faces))]
    assert _max_mm(drape(can, tgt, (g.vertices, faces)), reference()) < BOUND_MM
    perm = rng.permutation(len(g.vertices))
    inverse = np.argsort(perm)
    out = drape(can, tgt, (g.vertices[perm], inverse[g.faces]))
    assert _max_mm(out, reference()[perm]) < BOUND_MM  # a vertex permutation permutes the output


@pytest.mark.parametrize(
    "degrees, shift", [(37.0, (0.0, 0.0, 0.0)), (180.0, (0.0, 0.0, 0.0)), (0.0, (10.0, -10.0, 0.0))]
)
def test_scene_turned_about_the_vertical_or_moved(degrees, shift):
    can, tgt, g = scene()
    a = np.radians(degrees)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    t = np.asarray(shift)

    def move(mesh):
        return mesh[0] @ rot.T + t, mesh[1]

    out = drape(move(can), move(tgt), move((g.vertices.astype(np.float64), g.faces)))
    back = (out - t) @ rot
    assert _max_mm(back, reference()) < BOUND_MM


def test_fabric_changes_the_drape_and_physical_values_interpolate():
    from garsim.garments.fabrics import interpolate_fabric

    can, tgt, g = scene()
    silk = drape(can, tgt, (g.vertices, g.faces), fabric="silk")
    leather = drape(can, tgt, (g.vertices, g.faces), fabric="leather")
    assert _max_mm(silk, leather) > 0.5  # the fabric input reaches the output
    mid = drape(can, tgt, (g.vertices, g.faces), fabric=interpolate_fabric("denim", "denim", 0.5))
    assert _max_mm(mid, reference()) < 1e-3  # a Fabric equal to the preset is the preset
    values = {"bending": 1e-4, "density": 0.3, "stretch": 8e3}
    out = drape(can, tgt, (g.vertices, g.faces), fabric=values)
    assert np.isfinite(out).all() and out.shape == g.vertices.shape


def test_a_settled_template_on_a_body_that_does_not_move_stays():
    """Target body = canonical body, on the settled templates of the committed fixture (every family): the
    drape moves at most 3 mm on average."""
    from pathlib import Path

    from garsim.data.store import DatasetStore

    store = DatasetStore(Path(__file__).parent / "fixtures" / "dataset_v2")
    moved = {}
    for rec in store.sequences():
        lv = rec.levels["low"]
        body = (rec.body_canonical, rec.body_faces)
        out = sim().drape(body, body, (lv.template, lv.faces), fabric=rec.fabric)
        moved[f"{rec.garment_type}/{rec.seq_id}"] = 1000.0 * float(np.linalg.norm(out - lv.template, axis=1).mean())
    assert max(moved.values()) < 3.0, moved
