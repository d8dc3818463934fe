"""Garment templates: manifold, oriented, non-degenerate, outside the body, pinned where expected."""

from __future__ import annotations

import time

import numpy as np
import pytest

from garsim.bodies.anny import AnnyBody
from garsim.garments.templates import (
    PARAMS,
    TemplateBody,
    garment_params,
    make_garment,
    make_garment_from_arrays,
    sample_garment_params,
)
from garsim.geometry.inside import InsideTester
from garsim.geometry.mesh import border_loops, face_normals
from garsim.geometry.proximity import nearest_vertices, signed_offset_to_nearest

KINDS = ("skirt", "top", "tshirt", "trousers", "dress")
PHENOTYPES = (
    {},
    {"gender": 0.0},
    {"gender": 1.0},
    {"weight": 0.9, "gender": 0.7},
    {"height": 0.1, "muscle": 0.8},
)
EXPECTED_BORDERS = {"skirt": 2, "top": 4, "tshirt": 4, "trousers": 3, "dress": 4}


@pytest.fixture(scope="module")
def bodies() -> dict[int, tuple[AnnyBody, TemplateBody, InsideTester]]:
    out = {}
    for i, ph in enumerate(PHENOTYPES):
        b = AnnyBody(ph)
        tb = TemplateBody.from_anny(b)
        out[i] = (b, tb, InsideTester(tb.vertices.astype(np.float32), tb.faces))
    return out


def edge_face_counts(faces: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)[1]


def consistently_oriented(faces: np.ndarray) -> bool:
    """Every interior edge is traversed once in each direction by its two faces."""
    d = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = faces.max() + 1
    keys = d[:, 0] * n + d[:, 1]
    return len(np.unique(keys)) == len(keys)  # a repeated directed edge means two faces disagree


def triangle_quality(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    a, b, c = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 1]]
    area = 0.5 * np.linalg.norm(np.cross(a, b), axis=1)
    return 4 * np.sqrt(3) * area / ((a**2).sum(1) + (b**2).sum(1) + (c**2).sum(1))


def check_garment(g, tb: TemplateBody, tester: InsideTester, kind: str, target: int) -> None:
    v = g.vertices.astype(np.float64)
    f = g.faces
    assert g.kind == kind
    assert np.isfinite(v).all()
    assert len(np.unique(f)) == len(v), "every vertex is used by a face"
    counts = edge_face_counts(f)
    assert counts.max() == 2, "edge-manifold: no edge shared by more than two faces"
    assert consistently_oriented(f)
    assert len(border_loops(f)) == EXPECTED_BORDERS[kind]
    q = triangle_quality(v, f)
    assert q.min() > 0.01, f"degenerate triangle (quality {q.min():.4f})"
    assert 0.75 * target <= len(v) <= 1.25 * target, f"{len(v)} vertices for a target of {target}"
    assert tester.inside(v.astype(np.float32)).sum() == 0, "garment vertices inside the body"
    off = signed_offset_to_nearest(v, tb.vertices, tb.normals)
    assert off.min() > 0.0, f"nearest-body-vertex normal offset {off.min():.4f} <= 0"
    # normals point away from the body: vertex -> nearest body vertex direction agrees with face normals
    fn = face_normals(v, f)
    c = v[f].mean(axis=1)
    idx, _ = nearest_vertices(c, tb.vertices)
    outward = np.einsum("ij,ij->i", fn, c - tb.vertices[idx])
    assert np.mean(outward > 0) > 0.9, f"only {np.mean(outward > 0):.2f} of faces point away from the body"
    # pinned mask: non-empty and where expected
    pz = v[g.pinned, 2]
    assert g.pinned.any()
    if kind in ("skirt", "trousers"):
        assert abs(pz.mean() - (tb.z_waist + g.params["waist_height"])) < 0.01, "waistband pinned"
        assert np.ptp(pz) < 0.01
    elif kind == "tshirt":
        assert pz.min() > tb.z_armpit - 0.02, "shoulders pinned above the armpits"
    else:  # top, dress: the bodice's top ring, one band below the armpits
        assert np.ptp(pz) < 0.01, "the bodice's top ring is pinned as one band"
        assert abs(pz.mean() - (tb.z_armpit - g.params["armpit_clearance"])) < 0.01


@pytest.mark.parametrize("kind", KINDS)
def test_templates_all_phenotypes_low_resolution(bodies, kind):
    for i in range(len(PHENOTYPES)):
        _, tb, tester = bodies[i]
        check_garment(make_garment(kind, tb, target_vertices=600), tb, tester, kind, 600)


@pytest.mark.parametrize("kind", KINDS)
def test_templates_three_resolutions(bodies, kind):
    _, tb, tester = bodies[0]
    for target in (600, 2500, 10000):
        check_garment(make_garment(kind, tb, target_vertices=target), tb, tester, kind, target)


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_templates_full_sweep(bodies, kind):
    for i in range(len(PHENOTYPES)):
        _, tb, tester = bodies[i]
        for target in (300, 2500, 10000, 20000):
            check_garment(make_garment(kind, tb, target_vertices=target), tb, tester, kind, target)


def test_skirt_geometry_follows_parameters(bodies):
    _, tb, _ = bodies[0]
    short = make_garment("skirt", tb, {"length": 0.3, "flare": 0.0}, target_vertices=1500)
    long = make_garment("skirt", tb, {"length": 0.6, "flare": 0.6}, target_vertices=1500)
    z_top = tb.z_waist
    assert short.vertices[:, 2].max() == pytest.approx(z_top, abs=1e-4)
    assert short.vertices[:, 2].min() == pytest.approx(z_top - 0.3, abs=1e-4)
    assert long.vertices[:, 2].min() == pytest.approx(z_top - 0.6, abs=1e-4)

    # flare: the hem radius grows by ~flare * (hip - hem height) compared with the unflared skirt
    def hem_radius(g):
        hem = g.vertices[g.vertices[:, 2] < g.vertices[:, 2].min() + 1e-4]
        return np.linalg.norm(hem[:, :2] - hem[:, :2].mean(0), axis=1).mean()

    flat = make_garment("skirt", tb, {"length": 0.6, "flare": 0.0}, target_vertices=1500)
    expected = 0.6 * (tb.z_hip - (z_top - 0.6))
    assert hem_radius(long) - hem_radius(flat) == pytest.approx(expected, rel=0.15)
    low = make_garment("skirt", tb, {"waist_height": -0.08}, target_vertices=1500)
    assert low.vertices[:, 2].max() == pytest.approx(z_top - 0.08, abs=1e-4)


def test_tshirt_has_sleeves_along_arms(bodies):
    _, tb, _ = bodies[0]
    g = make_garment("tshirt", tb, {"sleeve_length": 0.15}, target_vertices=2500)
    top = make_garment("top", tb, target_vertices=2500)
    assert g.vertices[:, 0].max() > tb.shoulder_x + 0.1  # sleeves reach along the arm
    assert top.vertices[:, 0].max() < tb.shoulder_x + 0.03  # a tank top has none
    assert g.vertices[:, 2].max() > tb.z_shoulder  # covers the shoulders


def test_trousers_have_two_separate_legs(bodies):
    _, tb, _ = bodies[0]
    g = make_garment("trousers", tb, target_vertices=2500)
    low = g.vertices[g.vertices[:, 2] < tb.z_crotch - 0.15]
    assert (low[:, 0] > tb.x_mid).any() and (low[:, 0] < tb.x_mid).any()
    assert not (np.abs(low[:, 0] - tb.x_mid) < 0.005).any(), "a gap between the legs below the crotch"


def test_make_garment_from_arrays_matches_anny(bodies):
    b, tb, _ = bodies[0]
    g1 = make_garment("skirt", b, target_vertices=800)
    g2 = make_garment_from_arrays(
        "skirt", b.canonical().vertices, b.faces, b.skin_indices, b.skin_weights, b.bone_labels, target_vertices=800
    )
    np.testing.assert_allclose(g1.vertices, g2.vertices)


def test_parameter_validation():
    with pytest.raises(ValueError, match="length=-0.2 is out of range"):
        garment_params("skirt", {"length": -0.2})
    with pytest.raises(ValueError, match="unknown garment kind"):
        garment_params("cape")
    with pytest.raises(ValueError, match="unknown skirt parameters"):
        garment_params("skirt", {"sleeves": 1.0})
    with pytest.raises(ValueError, match="finite"):
        garment_params("top", {"length": float("nan")})


def test_target_vertices_validation(bodies):
    _, tb, _ = bodies[0]
    with pytest.raises(ValueError, match="target_vertices"):
        make_garment("skirt", tb, target_vertices=10)


def test_sample_params_in_range_and_reproducible():
    for kind in KINDS:
        a = sample_garment_params(kind, np.random.default_rng(3))
        b = sample_garment_params(kind, np.random.default_rng(3))
        assert a == b
        p = garment_params(kind, a)  # validates
        for name, (lo, hi, slo, shi) in PARAMS[kind].RANGES.items():
            assert slo <= getattr(p, name) <= shi and lo <= slo <= shi <= hi
    draws = [sample_garment_params("skirt", np.random.default_rng(s))["length"] for s in range(20)]
    assert len(set(draws)) == 20


def test_random_parameters_build_valid_garments(bodies):
    rng = np.random.default_rng(0)
    _, tb, tester = bodies[3]
    for kind in KINDS:
        params = sample_garment_params(kind, rng)
        g = make_garment(kind, tb, params, target_vertices=1200)
        assert tester.inside(g.vertices).sum() == 0
        assert edge_face_counts(g.faces).max() == 2


def test_build_time_2500(bodies):
    _, tb, _ = bodies[0]
    for kind in KINDS:
        t0 = time.perf_counter()
        g = make_garment(kind, tb, target_vertices=2500)
        dt = time.perf_counter() - t0
        print(f"template build {kind:9s} {g.num_vertices:5d} v: {dt * 1000:.0f} ms")
        assert dt < 20.0
