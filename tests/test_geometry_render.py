"""Renderer: PNGs are written, views are oriented (Z up, front looks at -Y), colours show up."""

from __future__ import annotations

import time

import numpy as np
import pytest
import trimesh
from matplotlib.image import imread

from garsim.geometry.render import render_grid, render_image, render_views

WHITE = 0.98


def _box(extents, centre=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.box(extents=extents)
    return np.asarray(m.vertices) + np.asarray(centre), np.asarray(m.faces)


def _silhouette(img: np.ndarray) -> np.ndarray:
    return (img < WHITE).any(axis=2)


def _extent(mask: np.ndarray) -> tuple[int, int]:
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return cols[-1] - cols[0] + 1, rows[-1] - rows[0] + 1  # width, height in pixels


def test_front_and_side_silhouettes_of_a_box():
    box = _box((1.0, 0.2, 2.0))  # wide in X, thin in Y, tall in Z
    front = render_image([box], views=("front",), size=200)
    side = render_image([box], views=("side",), size=200)
    wf, hf = _extent(_silhouette(front))
    ws, hs = _extent(_silhouette(side))
    assert hf == pytest.approx(hs, abs=1)  # shared scale, Z up in both
    assert wf / hf == pytest.approx(0.5, abs=0.02)  # front sees X (1.0) by Z (2.0)
    assert ws / hs == pytest.approx(0.1, abs=0.02)  # side sees Y (0.2) by Z (2.0)
    assert not np.array_equal(front.shape, side.shape) or not np.allclose(front, side)


def test_orientation_markers():
    body = _box((0.4, 0.4, 1.6))
    top = _box((0.1, 0.1, 0.1), (0.0, 0.0, 0.9))  # above the body (+Z)
    left = _box((0.1, 0.1, 0.1), (0.35, 0.0, 0.0))  # the body's left (+X)
    nose = _box((0.1, 0.1, 0.1), (0.0, -0.35, 0.0))  # in front of the body (-Y)
    meshes = [body, top, left, nose]
    colors = ["#808080", "red", "lime", "blue"]
    front = render_image(meshes, views=("front",), colors=colors, size=240)
    side = render_image(meshes, views=("side",), colors=colors, size=240)

    def centroid(img, channel):
        others = [c for c in range(3) if c != channel]
        mask = (img[..., channel] > 0.3) & (img[..., others] < 0.1).all(axis=2)
        assert mask.sum() > 20, f"marker of channel {channel} not visible"
        rows, cols = np.nonzero(mask)
        return rows.mean() / img.shape[0], cols.mean() / img.shape[1]

    r, _ = centroid(front, 0)
    assert r < 0.15  # +Z is at the top of the image
    _, c = centroid(front, 1)
    assert c > 0.75  # front view: the body's left (+X) on the image's right (we face the body)
    _, c = centroid(side, 2)
    assert c < 0.3  # side view from the body's left: its front (-Y) points to the image's left
    r, c = centroid(front, 2)
    assert 0.4 < r < 0.6 and 0.35 < c < 0.65  # the nose marker is seen head-on


def test_per_vertex_scalars_use_the_colormap(tmp_path):
    v, f = trimesh.creation.icosphere(subdivisions=3).vertices, trimesh.creation.icosphere(subdivisions=3).faces
    img = render_image([(v, f)], views=("front",), colors=np.asarray(v[:, 0]), size=160, cmap="viridis")
    mask = _silhouette(img)
    cols = np.flatnonzero(mask.any(axis=0))
    left, right = (
        img[:, cols[0] : cols[0] + 15][mask[:, cols[0] : cols[0] + 15]],
        img[:, cols[-1] - 15 : cols[-1]][mask[:, cols[-1] - 15 : cols[-1]]],
    )
    # viridis: low = purple (blue > green), high = yellow (red and green > blue)
    assert left[:, 2].mean() > left[:, 1].mean()
    assert right[:, 0].mean() > right[:, 2].mean() and right[:, 1].mean() > right[:, 2].mean()
    flat = render_image([(v, f)], views=("front",), colors="red", size=160)
    inner = _silhouette(flat)
    for _ in range(2):  # erode: anti-aliased border pixels blend with the white background
        inner = inner & np.roll(inner, 1, 0) & np.roll(inner, -1, 0) & np.roll(inner, 1, 1) & np.roll(inner, -1, 1)
    assert inner.sum() > 1000
    assert flat[inner][:, 1:].max() < 1e-6 and flat[inner][:, 0].min() > 0.3  # shaded pure red


def test_render_views_writes_a_png_with_colorbar_and_title(tmp_path):
    box = _box((0.5, 0.3, 1.0))
    path = render_views(tmp_path / "out.png", [box], title="a box", size=200)
    img = imread(path)
    assert img.ndim == 3 and img.shape[0] >= 200
    assert (img[..., :3] < WHITE).any(axis=2).mean() > 0.05  # non-blank
    plain = imread(render_views(tmp_path / "plain.png", [box], size=200))
    scal = imread(
        render_views(tmp_path / "err.png", [box], colors=np.linspace(0, 5, len(box[0])), colorbar_label="mm", size=200)
    )
    assert scal.shape[1] > plain.shape[1]  # the colour bar widens the figure
    assert sorted(p.name for p in tmp_path.iterdir()) == ["err.png", "out.png", "plain.png"]  # no temp files


def test_render_grid_layout(tmp_path):
    box = _box((0.5, 0.3, 1.0))
    img = render_image([box], size=100)
    path = render_grid(
        tmp_path / "grid.png",
        [img, [box], [box, _box((0.2, 0.2, 0.2), (0, 0, 0.7))]],
        ncols=2,
        titles=["a", "b", "c"],
        size=100,
    )
    grid = imread(path)
    assert grid.shape[1] == pytest.approx(2 * img.shape[1], abs=2)
    assert grid.shape[0] == pytest.approx(2 * (100 + 24), abs=2)


def test_render_grid_shares_one_colour_range_and_draws_its_bar(tmp_path):
    """Two panels whose scalars span 0-10 and 0-100: on the shared 0-100 range the first is all dark (viridis'
    low end), on its own range it is not; the bar adds a strip under the grid; a bar without a range is refused."""
    box = _box((0.5, 0.3, 1.0))
    n = len(box[0])
    low, high = np.linspace(0.0, 10.0, n), np.linspace(0.0, 100.0, n)
    own = imread(render_grid(tmp_path / "own.png", [[box], [box]], ncols=2, size=100, colors=[[low], [high]]))
    shared = render_grid(
        tmp_path / "shared.png",
        [[box], [box]],
        ncols=2,
        size=100,
        colors=[[low], [high]],
        vmin=0.0,
        vmax=100.0,
        colorbar_label="error (mm)",
    )
    shared = imread(shared)
    assert shared.shape[0] == pytest.approx(own.shape[0] + 70, abs=2)
    first = np.s_[: own.shape[0], : own.shape[1] // 2]

    def green(im: np.ndarray) -> float:  # mean green of the first panel's box: viridis' high end is green-yellow
        panel = im[first][..., :3]
        return float(panel[_silhouette(panel)][:, 1].mean())

    assert green(shared) < green(own) - 0.2
    with pytest.raises(ValueError, match="vmin and vmax"):
        render_grid(tmp_path / "x.png", [[box]], colors=[[low]], colorbar_label="error (mm)")


def test_bad_arguments(tmp_path):
    box = _box((1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="PNG"):
        render_views(tmp_path / "x.jpg", [box])
    with pytest.raises(ValueError, match="unknown view"):
        render_image([box], views=("top-down",))
    with pytest.raises(ValueError, match="one per mesh"):
        render_image([box, box], colors=["red", "blue", "green", "black", "white"])
    with pytest.raises(ValueError, match="at least one mesh"):
        render_image([])


def test_body_and_20k_garment_render_fast(anny_body, tmp_path):
    body = anny_body.canonical()
    cyl = trimesh.creation.cylinder(radius=0.22, height=0.5, sections=160).subdivide().subdivide().subdivide()
    garment = np.asarray(cyl.vertices) + np.array([0.0, -0.1, -0.2])
    assert len(garment) > 19000
    t0 = time.perf_counter()
    path = render_views(tmp_path / "body.png", [(body.vertices, anny_body.faces), (garment, cyl.faces)], size=512)
    dt = time.perf_counter() - t0
    print(f"\nrender: {len(body.vertices)}-v body + {len(garment)}-v garment, front+side at 512 px: {dt:.2f} s")
    assert dt < 15.0
    img = imread(path)[..., :3]
    h, w = img.shape[:2]
    front = img[:, : w // 2]
    # the head is near the top centre of the front view, the feet at the bottom
    rows = np.flatnonzero((front < WHITE).any(axis=2).any(axis=1))
    assert rows[0] < 0.08 * h and rows[-1] > 0.92 * h
