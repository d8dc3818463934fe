"""Implicit-surface garments (garsim.garments.implicit): topology, orientation, clearance, pins, determinism."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from garsim.garments.implicit import (
    IMPLICIT_KINDS,
    SHORT_EDGE,
    _collapse_short_edges,
    make_implicit_garment,
    sample_implicit_params,
)
from garsim.geometry.inside import InsideTester
from garsim.geometry.mesh import border_loops, edge_lengths, face_normals, vertex_normals

pytest.importorskip("skimage", reason="the implicit construction needs garsim[sim] (scikit-image, pymeshlab)")
pytest.importorskip("pymeshlab", reason="the implicit construction needs garsim[sim] (scikit-image, pymeshlab)")

LOOPS = {"skirt": 2, "trousers": 3, "tshirt": 4, "longsleeve": 4, "top": 4, "dress": 4}


@functools.lru_cache(maxsize=2)
def _body(phenotype: tuple = ()):
    from garsim.bodies.anny import AnnyBody

    body = AnnyBody(dict(phenotype))
    can = body.canonical()
    return (
        np.asarray(can.vertices),
        body.faces,
        body.skin_indices,
        body.skin_weights,
        list(body.bone_labels),
        InsideTester(can.vertices, body.faces),
    )


HEAVY = (("weight", 0.95), ("height", 0.1), ("muscle", 0.3))


def _make(kind, params=None, n=1000, phenotype=()):
    v, f, si, sw, bl, _ = _body(phenotype)
    return make_implicit_garment(kind, v, f, si, sw, bl, params=params, target_vertices=n)


def _check(g, kind: str, n: int, phenotype=()) -> None:
    bv, _bf, _, _, _, tester = _body(phenotype)
    v, f = g.vertices.astype(np.float64), g.faces
    assert g.kind == kind and g.params["construction"] == "implicit"
    assert abs(g.num_vertices - n) <= 0.2 * n, (kind, n, g.num_vertices)
    assert f.min() >= 0 and f.max() < len(v) and len(np.unique(f)) == len(v)
    # edge-manifold and consistently oriented: each directed edge at most once, each undirected at most twice
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    _, dcount = np.unique(d, axis=0, return_counts=True)
    assert dcount.max() == 1, f"{kind}: an edge is used twice in one direction (inconsistent orientation)"
    _, ucount = np.unique(np.sort(d, axis=1), axis=0, return_counts=True)
    assert ucount.max() <= 2, f"{kind}: non-manifold edge"
    # open with the expected border loops
    loops = border_loops(f)
    assert len(loops) == LOOPS[kind], (kind, [len(lp) for lp in loops])
    # outward normals
    from scipy.spatial import cKDTree

    _, idx = cKDTree(bv).query(v)
    assert np.mean(np.einsum("ij,ij->i", v - bv[idx], vertex_normals(v, f))) > 0
    # clear of the body
    assert not tester.inside(g.vertices).any(), f"{kind}: vertices inside the body"
    assert tester.signed_distance(g.vertices).min() > 0.003
    # pins
    frac = g.pinned.mean()
    assert 0 < frac < 0.3, (kind, frac)
    if kind in ("skirt", "trousers"):
        top = max(loops, key=lambda lv: v[lv, 2].mean())
        assert g.pinned[top].all()
        for lp in loops:
            if lp is not top:
                assert not g.pinned[lp].any(), "a hem is pinned"
    else:
        hem = min(loops, key=lambda lv: v[lv, 2].mean())
        assert not g.pinned[hem].any(), "the hem is pinned"
        assert np.ptp(v[hem, 2]) < 0.05, f"{kind}: the hem is not level (cut by another region)"


@pytest.mark.parametrize(
    "kind,params,n",
    [
        ("skirt", None, 400),
        ("trousers", {"length": 1.0, "width": 0.0}, 1200),
        ("tshirt", None, 800),
        ("longsleeve", {"sleeve": 1.0}, 500),
        ("top", {"variant": 0}, 600),
        ("dress", {"variant": 1, "length": 0.3}, 700),
    ],
)
def test_implicit_garment_valid(kind, params, n):
    _check(_make(kind, params, n), kind, n)


def test_no_sliver_edges_left_by_the_cuts():
    """The plane cuts leave ~0.01-1 mm border edges beside 6 cm ones (a dress of the v2 dataset: 0.02 mm),
    which the 1.5x stretch test rejected in every fabric; after the collapse none is near that short."""
    ph = (("age", 0.8373), ("gender", 0.4416), ("height", 0.3095), ("muscle", 0.5318))
    ph += (("proportions", 0.2087), ("weight", 0.0866))
    params = {"variant": 0, "length": 0.0793, "flare": 0.9516, "neck": 0.4151, "sleeve": 0.4367}
    params |= {"strap_width": 0.0398, "ease": 0.0236}
    for kind, prm, n, phen in (("dress", params, 316, ph), ("longsleeve", {"sleeve": 1.0}, 2000, ())):
        g = _make(kind, prm, n, phen)
        length = edge_lengths(g.vertices, g.faces)
        assert length.min() >= 0.85 * SHORT_EDGE * np.median(length), (kind, length.min(), np.median(length))
        _check(g, kind, n, phen)


def test_collapse_short_edges_keeps_a_manifold_oriented_sheet():
    n = 6
    u = np.linspace(0.0, 1.0, n)
    x, y = np.meshgrid(u, u, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    f = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    v[1, 1] = 0.003  # a border sliver: edge (0, 1) is 3 mm, the others 20 cm
    v[n + 2, 1], v[n + 3, 1] = 0.498, 0.502  # an interior one: 4 mm
    nv, nf = _collapse_short_edges(v, f, 0.05)
    assert len(nv) == len(v) - 2 and len(nf) == len(f) - 3
    assert edge_lengths(nv, nf).min() > 0.05
    assert (face_normals(v, f)[:, 2] > 0).all() and (face_normals(nv, nf)[:, 2] > 0).all()  # none flipped
    d = np.concatenate([nf[:, [0, 1]], nf[:, [1, 2]], nf[:, [2, 0]]])
    assert len(np.unique(d, axis=0)) == len(d)  # consistently oriented, edge-manifold
    assert len(border_loops(nf)) == 1
    same_v, same_f = _collapse_short_edges(v, f, 0.001)  # nothing that short: unchanged
    assert np.array_equal(same_v, v) and np.array_equal(same_f, f)


def test_deterministic():
    a = _make("top", {"variant": 1}, 500)
    b = _make("top", {"variant": 1}, 500)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert np.array_equal(a.pinned, b.pinned)


def test_trousers_two_legs():
    g = _make("trousers", {"length": 0.0, "width": 1.0}, 600)  # wide shorts
    loops = border_loops(g.faces)
    assert len(loops) == 3
    hems = sorted(loops, key=lambda lv: g.vertices[lv, 2].mean())[:2]
    xs = [g.vertices[lv, 0].mean() for lv in hems]
    assert min(xs) < -0.05 and max(xs) > 0.05  # one hem loop per leg


def test_sleeve_lengths():
    v = _body()[0]
    short = _make("tshirt", {"sleeve": 0.0}, 600)
    long_ = _make("longsleeve", {"sleeve": 1.0}, 600)
    assert long_.vertices[:, 0].max() > short.vertices[:, 0].max() + 0.15
    assert long_.vertices[:, 0].max() < v[:, 0].max()  # the hands stay bare


def test_params_sampling_and_errors():
    rng = np.random.default_rng(0)
    for kind in IMPLICIT_KINDS:
        p = sample_implicit_params(kind, rng)
        assert all(isinstance(x, (int, float, str)) for x in p.values())
    v, f, si, sw, bl, _ = _body()
    with pytest.raises(ValueError, match="use one of"):
        make_implicit_garment("cape", v, f, si, sw, bl)
    with pytest.raises(ValueError, match="out of range"):
        make_implicit_garment("skirt", v, f, si, sw, bl, params={"flare": 2.0})
    with pytest.raises(ValueError, match="unknown"):
        make_implicit_garment("skirt", v, f, si, sw, bl, params={"sleeve": 0.5})
    with pytest.raises(ValueError, match="integer code"):
        make_implicit_garment("top", v, f, si, sw, bl, params={"variant": 3})
    with pytest.raises(ValueError, match="target_vertices"):
        make_implicit_garment("skirt", v, f, si, sw, bl, target_vertices=5)
    with pytest.raises(ValueError, match="use one of"):
        sample_implicit_params("cape", rng)


@pytest.mark.slow
@pytest.mark.parametrize("kind", IMPLICIT_KINDS)
@pytest.mark.parametrize("phenotype", [(), HEAVY], ids=["default", "heavy"])
def test_matrix(kind, phenotype):
    rng = np.random.default_rng(abs(hash(kind)) % 1000)
    for n in (400, 1200, 2500):
        params = sample_implicit_params(kind, rng)
        g = _make(kind, params, n, phenotype)
        _check(g, kind, n, phenotype)
    # extremes of every float parameter
    for lo_hi in (0.0, 1.0):
        params = sample_implicit_params(kind, rng)
        for key in ("length", "flare", "width", "sleeve", "neck", "waist"):
            if key in params:
                params[key] = lo_hi
        _check(_make(kind, params, 800, phenotype), kind, 800, phenotype)
    if "variant" in params:
        for var in (0, 1):
            params["variant"] = var
            _check(_make(kind, params, 800, phenotype), kind, 800, phenotype)
