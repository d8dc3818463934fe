"""The public drape API: meshes in, the garment on the target body out."""

from __future__ import annotations

import dataclasses
import functools
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from garsim.bodies.anny_rig import anny_root_region
from garsim.bodies.prior import MeshPairPrior
from garsim.data.sample import CUSTOM_FABRIC, FABRICS, Sample
from garsim.garments.fabrics import Fabric, fabric_from_values, get_fabric
from garsim.garments.garment import Garment
from garsim.garments.remesh import BarycentricMap, barycentric_map, decimate, transfer_barycentric
from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.io import UNITS, MeshError, as_mesh, from_internal, to_internal, y_up_to_z_up, z_up_to_y_up
from garsim.geometry.mesh import cached_vertex_normals, piece_count, top_border_loops, weld, weld_index
from garsim.geometry.proximity import push_outside
from garsim.geometry.rigid import yaw_alignment

WEIGHTS_DIR = Path(__file__).parent / "weights"
log = logging.getLogger(__name__)


def _pinned_mask(pinned: Any, n: int) -> np.ndarray:
    if pinned is None:
        return np.zeros(n, dtype=bool)
    p = np.asarray(pinned)
    if p.dtype == bool:
        if p.shape != (n,):
            raise ValueError(f"pinned mask has shape {p.shape}; expected ({n},) booleans, one per garment vertex")
        return p
    if p.size and not (np.issubdtype(p.dtype, np.number) and np.all(p == np.round(p))):
        raise ValueError(f"pinned indices must be whole vertex numbers (or a boolean mask), got {p.ravel()[:4]!r}")
    idx = p.astype(np.int64).ravel()
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise ValueError(f"pinned indices must be in [0, {n}), got range [{idx.min()}, {idx.max()}]")
    mask = np.zeros(n, dtype=bool)
    mask[idx] = True
    return mask


_AUTO_PINS = ContentCache(8, scope="garment")


def auto_pinned(garment: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``pinned="auto"``: the (N,) mask of the garment's top border loops (waistband; neckline and straps of
    garments hung from the shoulders; ``garsim.geometry.mesh.top_border_loops``), for a garment in garsim's frame
    (metres, Z up) on the canonical body. A garment without a border (a closed surface) is refused."""

    def compute() -> np.ndarray:
        loops = top_border_loops(garment, faces)
        if not loops:
            raise MeshError(
                "pinned='auto' found no border loop on the garment (a closed surface): give the pinned vertex "
                "indices instead (CLI: --pinned FILE)"
            )
        mask = np.zeros(len(garment), dtype=bool)
        mask[np.concatenate(loops)] = True
        mask.setflags(write=False)
        log.info("pinned='auto': %d vertices on %d top border loop(s)", int(mask.sum()), len(loops))
        return mask

    return _AUTO_PINS.get(content_key(np.asarray(garment), np.asarray(faces)), compute)


def fabric_fields(fabric: Any) -> tuple[str, dict[str, float] | None]:
    """(name, physical values or None) of a fabric given as a preset name, a ``Fabric`` or a dict of
    physical values (``bending`` N·m, ``density`` kg/m², ``stretch`` N/m, ...)."""
    if isinstance(fabric, str):
        if fabric.strip().lower() not in FABRICS:
            raise ValueError(f"unknown fabric {fabric!r}; choose one of {', '.join(FABRICS)} or give physical values")
        return fabric.strip().lower(), None
    if isinstance(fabric, dict):
        fabric = fabric_from_values(dict(fabric))
    if isinstance(fabric, Fabric):
        if fabric.name in FABRICS and fabric == get_fabric(fabric.name):
            return fabric.name, None
        _warn_outside_presets(fabric)
        return CUSTOM_FABRIC, fabric.values()
    raise ValueError(
        f"fabric must be a preset name ({', '.join(FABRICS)}), a Fabric or a dict of physical values, "
        f"got {type(fabric).__name__}"
    )


def _warn_outside_presets(fabric: Fabric) -> None:
    """Log a warning for physical values the network did not see: beyond silk .. leather (10% of that log range)."""
    for key in ("bending", "density", "stretch"):
        lo, hi = (float(np.log(getattr(get_fabric(p), key))) for p in ("silk", "leather"))
        t = (float(np.log(getattr(fabric, key))) - lo) / (hi - lo)
        if not -0.1 <= t <= 1.1:
            log.warning(
                "fabric %s=%.3g lies outside silk .. leather (%.3g .. %.3g), the range the model was trained on: "
                "its drape extrapolates",
                key,
                getattr(fabric, key),
                getattr(get_fabric("silk"), key),
                getattr(get_fabric("leather"), key),
            )


BODY_HEIGHT_RANGE = (0.4, 2.6)
"""Plausible standing body heights in metres: outside it the input is in other units (or not a body)."""
FAR_FROM_BODY = 0.4
"""m: a garment whose median vertex is farther than this from the canonical body does not surround it (lenient:
skirts flared to a 0.6-0.7 m hem lie 26-28 cm from the body at the median)."""
INSIDE_LIMIT = 0.10
"""Share of a garment's vertices inside the canonical body (winding number) above which it is not draped on that body
and is refused; over ``INSIDE_WARN`` a warning says so. Garments draped on their body have none (217 here: 0.6% at
most even by DeePSD's looser nearest-normal test); one moved 10 cm sideways, shrunk to 70% or made on another pose
has 5-100% (docs/studies/input_checks.md)."""
INSIDE_WARN = 0.02
INSIDE_DEPTH = 0.005
"""m: a garment vertex counts as inside the canonical body for ``INSIDE_LIMIT`` only this deep in it: a tight garment
that grazes the skin by a millimetre is draped on that body (the network and the refinement handle it), one made on
another pose or body is centimetres inside."""
CHECK_POINTS = 2000
"""The input checks read about this many of a garment's vertices, taken in the order of their coordinates (so a
reordered mesh gets the same verdict)."""
BETTER_FIT = 0.7
"""A garment turned between Y-up and Z-up, or scaled by a power of ten, that lies this much nearer the canonical
body (median distance), within 10 cm of it (a garment over ``INSIDE_WARN`` inside the body as read: nearer at all,
within ``FAR_FROM_BODY``), with at most 1% inside it and a garment's size (its bounding box's
diagonal 0.1-1.5x the body's height) is in another axis or unit than the body: refused. A scaled reading is tried
only for a garment whose own size is not a garment's (scaled about the origin, a large garment may land nearer a body
that is not centred there). On the fixture's and the external set's garments the best such reading is 1.15-4.9x
farther than the garment as given."""
_READINGS: tuple[tuple[str, Any], ...] = (
    ("turned from Y-up to Z-up", y_up_to_z_up),
    ("turned from Z-up to Y-up", z_up_to_y_up),
    *((f"scaled by {10.0**k:g}", lambda v, k=k: v * 10.0**k) for k in (-3, -2, -1, 1, 2, 3)),
)


def _size(points: np.ndarray) -> float:
    """The diagonal of the points' bounding box."""
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _fit(tree: Any, body: np.ndarray, normals: np.ndarray, garment: np.ndarray) -> tuple[float, float]:
    """(median distance (m) of the garment's vertices to the body's, share of them inside the body by DeePSD's test:
    behind their nearest body vertex's normal), from one query of the body's KD-tree."""
    dist, idx = tree.query(garment)
    inside = np.einsum("ij,ij->i", garment - body[idx], normals[idx]) < 0.0
    return float(np.median(dist)), float(inside.mean())


def check_scene(body: np.ndarray, body_faces: np.ndarray, garment: np.ndarray, up: str = "z", units: str = "m") -> None:
    """Refuse a body that is plainly in another axis or unit, or a garment that is not draped on it: in another
    axis or unit than the body, far from it, or partly inside it.

    ``body`` and ``garment`` are in garsim's frame (metres, Z up), converted from the input's ``up`` and
    ``units``; the message names the flag that fixes the input."""
    extent = body.max(axis=0) - body.min(axis=0)
    # read in the wrong axis the vertical is the body's depth, its shortest extent; a T-pose's arm span may match
    # its height, an upper-body avatar's exceed it
    if extent[2] < 0.6 * extent.max() and extent[2] < min(extent[0], extent[1]):
        axis = "XYZ"[int(np.argmax(extent))]
        if up == "y":
            raise MeshError(
                f"read as Y-up, the canonical body's longest axis is {axis}, not the vertical: the file looks "
                "Z-up already; drop up='y' (CLI: --up z)"
            )
        raise MeshError(
            f"the canonical body's longest axis is {axis}, not Z (up): for a Y-up file (Blender, glTF) "
            "pass up='y' (CLI: --up y)"
        )
    height = float(extent[2])
    if not (BODY_HEIGHT_RANGE[0] <= height <= BODY_HEIGHT_RANGE[1]):
        raw = height / UNITS[units]  # in the file's own numbers
        fits = [u for u, scale in UNITS.items() if BODY_HEIGHT_RANGE[0] <= raw * scale <= BODY_HEIGHT_RANGE[1]]
        hint = fits[0] if fits else None
        fix = f"pass units='{hint}' (CLI: --units {hint})" if hint else "give the meshes in metres, cm or mm"
        raise MeshError(f"the canonical body is {raw:.3g} {units} tall (units='{units}'), not a person: {fix}")
    # coarse figures (a median, shares of 1-10%, ratios of 0.7): a few thousand spread vertices tell them
    garment = garment[np.lexsort(garment.T[::-1])][:: max(1, len(garment) // CHECK_POINTS)]
    from garsim.geometry.proximity import cached_tree

    tree, normals = cached_tree(body), cached_vertex_normals(body, body_faces)
    median, inside = _fit(tree, body, normals, garment)
    own_size = _size(garment) / height
    for reading, move in _READINGS:
        other = move(garment)
        if not 0.1 <= _size(other) / height <= 1.5 or (reading.startswith("scaled") and 0.1 <= own_size <= 1.5):
            continue
        other_median, other_inside = _fit(tree, body, normals, other)
        # much nearer the body, or a garment partly inside it (as given) that lies nearer and outside it so read
        nearer = min(BETTER_FIT * median, 0.1) if inside <= INSIDE_WARN else min(median, FAR_FROM_BODY)
        if other_median < nearer and other_inside <= 0.01:
            raise MeshError(
                f"the garment is in another axis or unit than the canonical body: {reading} it would lie "
                f"{100 * other_median:.1f} cm from the body instead of {100 * median:.1f} cm; give every mesh in one "
                "axis and unit (up= / units= apply to all; CLI: --up / --units)"
            )
    if median > FAR_FROM_BODY:
        raise MeshError(
            f"the garment's median vertex is {100 * median:.0f} cm from the canonical body: it must be draped on "
            "the canonical body (same position, axis and units; a Y-up or cm/mm file: pass up= / units=, CLI: "
            "--up / --units)"
        )
    if inside > INSIDE_WARN:  # by DeePSD's test, which flags some points near concave parts: the exact one decides
        from garsim.geometry.inside import inside_mask, obstacle

        deep = np.abs(obstacle(body, body_faces).query(garment)[0]) > INSIDE_DEPTH
        inside = float((inside_mask(garment, body, body_faces) & deep).mean())
        depth = f"over {1000 * INSIDE_DEPTH:.0f} mm"
        where = f"{100 * inside:.0f}% of the garment's vertices are {depth} inside the canonical body"
        if inside > INSIDE_LIMIT:
            raise MeshError(
                f"{where}: it must be draped on the canonical body (the pose and body it was made on, e.g. not the "
                "target)"
            )
        if inside > INSIDE_WARN:
            log.warning("%s: is it draped on the canonical body? The drape starts from there", where)


TARGET_SCALE_RANGE = (0.5, 2.0)
"""The target body's RMS distance from its centroid over the canonical body's: a posed copy of one mesh (0.73-1.04
over the sampler's whole pose range here), not one in other units (10x to 1000x)."""
MAX_TILT_DEG = 45.0
"""Largest angle between the vertical and the vertical turned by the rotation that best aligns the canonical body with
the target (Kabsch, about their centroids): up to 34 deg over the sampler's whole pose range here, 58-64 deg for a
Y-up target read as Z-up; sitting on the floor with straight legs or bending far forward turns it 47-55 deg, and is
refused too (the bound cannot tell them from a wrong axis)."""


def check_target(canonical: np.ndarray, target: np.ndarray) -> None:
    """Refuse a target body (garsim's frame, the canonical body's topology) in another unit or axis than the
    canonical body."""
    step = max(1, len(canonical) // 2000)  # every step-th vertex: plenty for a whole body's size and turn
    c = np.asarray(canonical[::step], dtype=np.float64)
    t = np.asarray(target[::step], dtype=np.float64)
    c, t = c - c.mean(axis=0), t - t.mean(axis=0)
    scale = float(np.sqrt((t**2).sum(1).mean() / (c**2).sum(1).mean()))
    if not TARGET_SCALE_RANGE[0] <= scale <= TARGET_SCALE_RANGE[1]:
        raise MeshError(
            f"the target body is {scale:.3g}x the size of the canonical body: give every body in the same units "
            "(a posed copy of the canonical body mesh)"
        )
    u, _, vt = np.linalg.svd(c.T @ t)
    rotation = (u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt).T  # canonical -> target
    tilt = float(np.degrees(np.arccos(np.clip(rotation[2, 2], -1.0, 1.0))))
    if tilt > MAX_TILT_DEG:
        raise MeshError(
            f"the target body is turned {tilt:.0f} deg away from the canonical body's vertical: give every mesh in "
            "one axis (up= applies to all; CLI: --up); a real pose turned that far (sitting on the floor, bending far "
            "forward, lying) is beyond what garsim drapes"
        )


_SCENES = ContentCache(4, scope="garment")  # Scene.make's scenes, by the content of their meshes and settings


@dataclasses.dataclass(frozen=True)
class Scene:
    """The per-sequence part of a drape: the validated canonical body and garment (garsim's frame), the garment's
    pin mask and fabric. ``sample(target)`` adds one target body. ``Scene.make`` keeps the last few scenes by
    content, so draping one garment on pose after pose validates it and sets up its prior once.

    The scene's garment is the user's with coincident vertices welded (within ``WELD_TOLERANCE``: a mesh split at
    UV seams or hard edges, as glTF files store them, would otherwise be draped as separate panels and its seams
    would open); ``welded`` maps each of the user's vertices to the scene's, and :meth:`unweld` maps results back."""

    body_canonical: np.ndarray
    body_faces: np.ndarray
    garment: np.ndarray
    garment_faces: np.ndarray
    pinned: np.ndarray
    fabric: str
    fabric_values: dict[str, float] | None
    garment_type: str = "unknown"
    up: str = "z"
    units: str = "m"
    welded: np.ndarray | None = None

    @classmethod
    def make(
        cls,
        body_canonical: Any,
        garment: Any,
        fabric: Any = "cotton",
        pinned: Any = None,
        garment_type: str = "unknown",
        up: str = "z",
        units: str = "m",
    ) -> Scene:
        """Validate the canonical body and the garment (in ``up`` axis and ``units``), their relation, the pins and
        the fabric."""
        fabric_name, fabric_values = fabric_fields(fabric)
        bc, bf = as_mesh(body_canonical, "canonical body")
        g, gf = as_mesh(garment, "garment")
        bc, g = (to_internal(v, up, units).astype(np.float32) for v in (bc, g))
        key = (
            content_key(bc, bf, g, gf),
            pinned.strip().lower() if isinstance(pinned, str) else None if pinned is None else content_key(pinned),
            fabric_name,
            None if fabric_values is None else tuple(sorted(fabric_values.items())),
            garment_type,
            up,
            units,
        )
        return _SCENES.get(
            key, lambda: cls._validated(bc, bf, g, gf, fabric_name, fabric_values, pinned, garment_type, up, units)
        )

    @classmethod
    def _validated(
        cls,
        bc: np.ndarray,
        bf: np.ndarray,
        g: np.ndarray,
        gf: np.ndarray,
        fabric_name: str,
        fabric_values: dict[str, float] | None,
        pinned: Any,
        garment_type: str,
        up: str,
        units: str,
    ) -> Scene:
        """A new Scene of meshes already in garsim's frame, once their relation and the pins are checked."""
        auto = isinstance(pinned, str)
        if auto and pinned.strip().lower() != "auto":
            raise ValueError(f"pinned must be 'auto', vertex indices or a boolean mask, got {pinned!r}")
        check_scene(bc, bf, g, up=up, units=units)
        mask = None if auto else _pinned_mask(pinned, len(g))  # on the user's vertices
        index = weld_index(g, gf)
        if index is not None:
            g, gf = weld(g, gf, index)
            if mask is not None:  # a welded vertex is pinned when any of its copies is
                mask = np.bincount(index[mask], minlength=len(g)) > 0
        pieces = piece_count(gf, len(g))
        if pieces > 1:
            log.warning(
                "the garment has %d separate pieces; they are draped as one garment (each piece's drape depends on "
                "the others): drape separate garments one at a time",
                pieces,
            )
        if auto:  # found on the welded garment: a seam is not a border
            mask = auto_pinned(g, gf)
        arrays = (bc, np.array(bf), g, np.array(gf), np.array(mask))  # the scene's own copies
        for a in (*arrays, index):
            if a is not None:
                a.flags.writeable = False  # per-scene set-up (Scene.prior) is computed once from them
        return cls(*arrays, fabric_name, fabric_values, garment_type, up, units, index)

    def unweld(self, garment: np.ndarray) -> np.ndarray:
        """Per-vertex values of the scene's garment (..., M, k) on the user's garment's vertices (..., N, k)."""
        return garment if self.welded is None else garment[..., self.welded, :]

    def target_vertices(self, body_target: Any) -> np.ndarray:
        """A target body (a mesh, or an array of vertices on the canonical body's faces) in garsim's frame; it must
        share the canonical body's topology."""
        verts = self._on_canonical_faces(body_target)
        if verts is not None:  # the canonical body's (validated) faces: only the vertices need checking
            if not np.isfinite(verts).all():
                raise MeshError("target body: vertices contain NaN or inf; fix the mesh")
            bt, bf_t = verts, self.body_faces
        else:
            bt, bf_t = as_mesh(body_target, "target body")
        bt = to_internal(bt, self.up, self.units).astype(np.float32)
        bc, bf = self.body_canonical, self.body_faces
        if bc.shape != bt.shape or bf.shape != bf_t.shape or not (bf_t is bf or np.array_equal(bf, bf_t)):
            raise MeshError(
                f"canonical body ({len(bc)} vertices, {len(bf)} faces) and target body ({len(bt)} vertices, "
                f"{len(bf_t)} faces) must share one topology: pose the same body mesh"
            )
        check_target(bc, bt)
        return bt

    def _on_canonical_faces(self, body_target: Any) -> np.ndarray | None:
        """The vertices of a target given as an array, or as a (vertices, faces) pair whose faces are the canonical
        body's, when they are numbers of the canonical body's shape; else None (validate it as a mesh)."""
        verts = body_target
        if isinstance(body_target, (tuple, list)) and len(body_target) == 2:
            faces = body_target[1]
            same = faces is self.body_faces or (
                isinstance(faces, np.ndarray)
                and faces.shape == self.body_faces.shape
                and np.array_equal(faces, self.body_faces)
            )
            verts = body_target[0] if same else None
        if not isinstance(verts, np.ndarray) or verts.shape != self.body_canonical.shape:
            return None
        return verts if np.issubdtype(verts.dtype, np.number) else None

    @functools.cached_property
    def prior(self) -> MeshPairPrior:
        """The skinning prior of this garment on this canonical body, set up once: ``prior(target)`` per pose."""
        return MeshPairPrior(self.garment, self.body_canonical, self.body_faces)

    def sample(self, body_target: Any) -> Sample:
        """The model's input record for one target body (validated here), with the prior."""
        bt = self.target_vertices(body_target)
        return Sample(
            body_canonical=self.body_canonical,
            body_target=bt,
            body_faces=self.body_faces,
            garment=self.garment,
            garment_faces=self.garment_faces,
            pinned=self.pinned,
            prior=self.prior(bt),
            fabric=self.fabric,
            fabric_values=self.fabric_values,
            garment_type=self.garment_type,
        )


def make_sample(
    body_canonical: Any,
    body_target: Any,
    garment: Any,
    fabric: Any = "cotton",
    pinned: Any = None,
    garment_type: str = "unknown",
    up: str = "z",
    units: str = "m",
) -> Sample:
    """Validate user meshes (in ``up`` axis and ``units``) and build the model's input record (with the prior).

    ``pinned``: garment vertex indices, an (N,) boolean mask, ``"auto"`` (the top border loops, found in the
    canonical body's frame: :func:`auto_pinned`) or None; pinned vertices follow the prior exactly. The record's
    garment is the scene's, coincident vertices welded (:class:`Scene`)."""
    return Scene.make(body_canonical, garment, fabric, pinned, garment_type, up, units).sample(body_target)


@dataclasses.dataclass(frozen=True)
class SequenceConfig:
    """Defaults of :meth:`GarSim.drape_sequence` (``garsim animate`` takes its defaults from here)."""

    smoothing: float = 3.0
    """Temporal smoothing of the network's correction, in frames (the standard deviation of a Gaussian; 0: off).
    On the 30-frame walk cycle it brings every family's jitter after refinement to or below the prior's (at 2 frames
    the t-shirt's stayed 3-5% above it); it damps a correction that changes once per 30-frame cycle by 18%
    (exp(-(2 pi 3 / 30)^2 / 2)), one that changes over the whole sequence not at all."""


def check_smoothing(smoothing: Any) -> float:
    """A temporal smoothing in frames: a finite number >= 0 (0: off), else a one-line ValueError."""
    try:
        sigma = float(smoothing)
    except (TypeError, ValueError):
        raise ValueError(f"smoothing is a number of frames >= 0, got {smoothing!r}") from None
    if not (np.isfinite(sigma) and 0.0 <= sigma <= 100.0):
        raise ValueError(f"smoothing is a number of frames in [0, 100] (0: off), got {smoothing!r}")
    return sigma


def smooth_corrections(
    frames: np.ndarray, priors: np.ndarray, sigma: float, rotations: np.ndarray | None = None
) -> np.ndarray:
    """(T, N, 3) frames whose correction to the prior is Gaussian-smoothed over time (std ``sigma`` frames,
    the ends extended by their nearest frame): ``priors + g_sigma * (frames - priors)``. ``rotations`` (T, 3, 3):
    each frame's root-frame turn (:func:`root_frame`); the corrections are smoothed in the root frame, so those of a
    body that turns round are not averaged across its turn."""
    from scipy.ndimage import gaussian_filter1d

    correction = np.asarray(frames, np.float64) - priors
    if rotations is not None:
        correction = np.einsum("tnj,tji->tni", correction, rotations)  # each row x R_t: into the root frame
    smoothed = gaussian_filter1d(correction, sigma, axis=0, mode="nearest", truncate=3.0)
    if rotations is not None:
        smoothed = np.einsum("tni,tji->tnj", smoothed, rotations)  # x R_t^T: back to the world
    return (priors + smoothed).astype(np.float32)


_COARSE = ContentCache(8, scope="garment")  # per garment: its decimated copy and the maps both ways


def is_mesh_pair(obj: Any) -> bool:
    """Whether ``obj`` is one (vertices (V, 3), faces (F, 3) integers) pair of arrays, not a list of meshes."""
    if not isinstance(obj, (tuple, list)) or len(obj) != 2:
        return False
    verts, faces = (np.asarray(a) if isinstance(a, np.ndarray) else None for a in obj)
    return (
        verts is not None
        and faces is not None
        and np.issubdtype(verts.dtype, np.floating)  # two integer target arrays are two targets, not a mesh
        and verts.ndim == 2
        and verts.shape[1:] == (3,)
        and faces.ndim == 2
        and faces.shape[1:] == (3,)
        and np.issubdtype(faces.dtype, np.integer)
    )


def root_frame(sample: Sample) -> tuple[np.ndarray, np.ndarray] | None:
    """(R, t): how the target body's root (Anny's pelvis region, ``bodies.anny_rig.anny_root_region``) is turned
    about the vertical and moved from the canonical body's (``geometry.rigid.yaw_alignment``), or None for a body
    in another topology. The network sees the target body and the prior moved back by it and its garment is moved
    on by it (ours, not the paper's): an avatar that walks off or turns round (root motion) is draped as if it had
    stayed, and the garment follows it exactly. The region is skin, not bone: over v5test's poses it moves 2 mm (median;
    10 mm at most) and turns under 3 degrees, in the motion library's deep sit 14.5 mm (the groin follows the thighs;
    stricter regions move more: ``docs/studies/root_frame.md``). v0.9 alone moved 14 mm at a vertex (median) for a 1
    cm move of the target."""
    region = anny_root_region(len(sample.body_canonical), np.asarray(sample.body_faces))
    if region is None:
        return None
    return yaw_alignment(np.asarray(sample.body_canonical)[region], np.asarray(sample.body_target)[region])


def _coarse_copy(sample: Sample, max_vertices: int) -> tuple[Garment, BarycentricMap, BarycentricMap]:
    """The garment decimated to ~``max_vertices``, the full -> coarse map and the coarse -> full map."""
    garment = Garment(sample.garment, sample.garment_faces, sample.pinned, sample.garment_type, {})
    low, to_low = decimate(garment, ratio=max_vertices / len(sample.garment))
    return low, to_low, barycentric_map(sample.garment, low.vertices, low.faces)


def postprocess(
    pred: np.ndarray,
    sample: Sample,
    collision_margin: float | None = 0.002,
    refine: bool = True,
    memo: Any = None,
    fallback: bool = True,
) -> np.ndarray:
    """The API's post-process of a raw prediction: physical refinement (``garsim.refine``) or, with
    ``refine=False``, the push-out along the soft anchor's normal, to ``collision_margin`` metres outside the
    target body (None: the raw prediction). The sample's pinned vertices follow the prior exactly, before the
    refinement (which never moves them, so their edges are refined against where they end) and after; the
    refinement also takes the prior as its ``fallback`` for vertices the network put deep inside the body, through
    the body or on torn edges. ``memo`` (a ``garsim.refine.RefineMemo``, optional): kept by the caller between two
    post-processes of one sample, it makes the second refinement cheaper (same result). ``fallback=False``: refine
    without the prior as fallback (``drape_sequence``'s second pass)."""
    pred = np.array(pred, dtype=np.float32)
    pred[sample.pinned] = sample.prior[sample.pinned]
    if collision_margin is not None and refine:
        from garsim.model.inputs import sample_fabric
        from garsim.refine import refine as refine_garment

        pred = refine_garment(
            pred,
            sample.garment,
            sample.garment_faces,
            sample.body_target,
            sample.body_faces,
            fabric=sample_fabric(sample),
            pinned=sample.pinned,
            margin=collision_margin,
            fallback=sample.prior if fallback else None,
            memo=memo,
        )
    elif collision_margin is not None:
        normals = cached_vertex_normals(sample.body_target, sample.body_faces)
        pred = push_outside(pred, sample.body_target, normals, collision_margin)
    pred[sample.pinned] = sample.prior[sample.pinned]  # a user's pins (waistbands, straps) follow the body
    return pred


class GarSim:
    """Drapes a garment from a canonical body onto a target body in one step.

    ``GarSim.pretrained()`` is the shipped model, ``GarSim.load(folder)`` a trained one, ``GarSim(model)`` any model
    object with ``predict(sample)`` and ``config``, and ``GarSim.prior_only()`` the garment deformation prior
    (LBS-like skinning; ``model=None``), the baseline every learned model must beat.
    """

    def __init__(
        self,
        model: Any,
        collision_margin: float | None = 0.002,
        max_vertices: int | None = None,
        refine: bool = True,
    ) -> None:
        """``refine`` (default on): after the network, a few iterations of physical constraint projection
        (``garsim.refine``: edges within the fabric's stretch limit, vertices and edges ``collision_margin``
        metres outside the body's triangles); on the test split and the external set it lowers the mean error
        as well as the collisions (docs/studies/fallback_side.md), at ~3-20 ms more per call (`garsim bench`; a new
        body pose refits its BVH in ~1 ms).
        ``refine=False``: vertices inside the body or nearer than ``collision_margin`` are only pushed out along
        the body's blended normal at their soft anchor. ``collision_margin=None`` keeps the raw network output.
        ``max_vertices``: a denser garment is draped
        by the network at about this many vertices (decimated) and its correction to the prior carried
        back barycentrically; None (the default) runs the network on the garment as given. Decimation
        depends on the vertex and face order and on tiny changes of the input, so it is off unless asked for."""
        if collision_margin is not None and not (0.0 <= collision_margin < 0.05):
            raise ValueError(f"collision_margin is in metres, in [0, 0.05), got {collision_margin}")
        if max_vertices is not None and max_vertices < 100:
            raise ValueError(f"max_vertices must be >= 100 (or None), got {max_vertices}")
        self.model = model
        self.collision_margin = collision_margin
        self.max_vertices = max_vertices
        self.refine = bool(refine)

    def _network(self, sample: Sample) -> np.ndarray:
        """The network's garment, at the garment's own resolution up to ``max_vertices``."""
        n = len(sample.garment)
        if self.max_vertices is None or n <= self.max_vertices:
            return self.model.predict(sample)
        try:
            low, to_low, to_full = _COARSE.get(
                (content_key(sample.garment, sample.garment_faces, sample.pinned), self.max_vertices),
                lambda: _coarse_copy(sample, self.max_vertices),
            )
        except Exception as exc:  # a mesh the simplifier cannot handle still gets a prediction
            log.warning("could not decimate the garment (%s); running the network on all %d vertices", exc, n)
            return self.model.predict(sample)
        low_prior = transfer_barycentric(sample.prior, to_low)
        low_sample = dataclasses.replace(
            sample,
            garment=low.vertices,
            garment_faces=low.faces,
            pinned=low.pinned,
            prior=low_prior.astype(np.float32),
            target=None,
        )
        correction = self.model.predict(low_sample) - low_prior
        return (sample.prior + transfer_barycentric(correction, to_full)).astype(np.float32)

    def raw(self, sample: Sample) -> np.ndarray:
        """The network's garment for a prepared sample before any post-process (the prior when there is no model),
        run in the target body's root frame (:func:`root_frame`)."""
        if self.model is None:
            return np.array(sample.prior, dtype=np.float32)
        frame = root_frame(sample)
        if frame is None:
            return self._network(sample)
        rot, shift = frame
        local = dataclasses.replace(
            sample,
            body_target=((np.asarray(sample.body_target, np.float64) - shift) @ rot).astype(np.float32),
            prior=((np.asarray(sample.prior, np.float64) - shift) @ rot).astype(np.float32),
        )
        return (self._network(local).astype(np.float64) @ rot.T + shift).astype(np.float32)

    def finish(self, pred: np.ndarray, sample: Sample, memo: Any = None, fallback: bool = True) -> np.ndarray:
        """This GarSim's post-process of a raw garment (:func:`postprocess`, with its optional refine ``memo`` and
        ``fallback``; none for the bare prior)."""
        if self.model is None and not self.refine:
            return np.array(pred, dtype=np.float32)
        return postprocess(pred, sample, self.collision_margin, self.refine, memo=memo, fallback=fallback)

    def predict(self, sample: Sample) -> np.ndarray:
        """The model's garment for a prepared sample (the prior when there is no model), post-processed."""
        return self.finish(self.raw(sample), sample)

    def sequence_metadata(self, fabric: Any, smoothing: float) -> dict[str, Any]:
        """What made a ``drape_sequence`` result, for an exported file's metadata (the bare prior is never smoothed)."""
        from garsim import __version__

        return {
            "generator": f"garsim {__version__}",
            "model": self.name,
            "fabric": fabric,
            "refine": self.refine,
            "temporal_smoothing_frames": float(smoothing) if self.model is not None else 0.0,
        }

    @property
    def name(self) -> str:
        base = "GarSim model" if self.model is not None else "skinning prior"
        return base + (" + refine" if self.refine else "")

    @classmethod
    def prior_only(cls, refine: bool = False) -> GarSim:
        """The skinning prior alone (``refine=True``: the prior + physical refinement, a baseline)."""
        return cls(model=None, refine=refine)

    @classmethod
    def pretrained(cls, **options: Any) -> GarSim:
        """The model shipped inside the package (``garsim/weights``); ``options`` as ``GarSim(...)``."""
        from garsim.model.runtime import load_for_inference
        from garsim.model.weights import WEIGHTS_FILE

        if not (WEIGHTS_DIR / WEIGHTS_FILE).exists():
            raise FileNotFoundError(
                f"no pretrained weights at {WEIGHTS_DIR / WEIGHTS_FILE}: this build ships no trained model; "
                "use GarSim.prior_only() (or `garsim drape --prior-only`)"
            )
        return cls(model=load_for_inference(WEIGHTS_DIR), **options)

    @classmethod
    def load(cls, directory: str | Path, **options: Any) -> GarSim:
        """A model saved by training (model.safetensors + config.json: GarSim or the DeePSD-style baseline);
        ``options`` as ``GarSim(...)``. GarSim runs on the numpy runtime (``garsim.model.runtime``, no torch)."""
        from garsim.model.runtime import load_for_inference

        return cls(model=load_for_inference(directory), **options)

    @classmethod
    def default(cls) -> GarSim:
        """The shipped model when present, else the prior."""
        try:
            return cls.pretrained()
        except FileNotFoundError:
            return cls.prior_only()

    def drape_on(self, body: Any, canonical: Any, target: Any, garment: Any, fabric: Any = "cotton") -> np.ndarray:
        """Drape a ``Garment`` using a rigged ``BodyModel`` and its posed bodies (exact LBS prior)."""
        from garsim.bodies.prior import garment_prior

        prior = garment_prior(body, canonical, target, garment.vertices)
        fabric_name, fabric_values = fabric_fields(fabric)
        sample = Sample(
            body_canonical=canonical.vertices,
            body_target=target.vertices,
            body_faces=body.faces,
            garment=garment.vertices,
            garment_faces=garment.faces,
            pinned=garment.pinned,
            prior=prior,
            fabric=fabric_name,
            fabric_values=fabric_values,
            garment_type=garment.kind,
        )
        return self.predict(sample)

    def drape(
        self,
        body_canonical: Any,
        body_target: Any,
        garment: Any,
        fabric: Any = "cotton",
        pinned: Any = None,
        up: str = "z",
        units: str = "m",
    ) -> np.ndarray:
        """Predicted garment vertices (N, 3) on ``body_target``, in the input's axis and units.

        Each mesh is a ``trimesh.Trimesh``, a ``(vertices, faces)`` pair of arrays or a file path;
        both bodies share one topology; ``garment`` is draped on ``body_canonical``. ``fabric`` is a
        preset name (silk, cotton, denim, leather), a ``Fabric`` or a dict of physical values. ``up``
        ('z' or 'y') and ``units`` ('m', 'cm', 'mm') describe the input meshes; the output uses the same.
        ``pinned`` (indices, a mask, or ``"auto"``: the garment's top border loops) vertices follow the prior
        exactly.
        """
        scene = Scene.make(body_canonical, garment, fabric, pinned, up=up, units=units)
        out = scene.unweld(self.predict(scene.sample(body_target)))
        return from_internal(out, up, units).astype(np.float32)

    def drape_sequence(
        self,
        body_canonical: Any,
        body_targets: Any,
        garment: Any,
        fabric: Any = "cotton",
        pinned: Any = None,
        progress: bool = False,
        up: str = "z",
        units: str = "m",
        smoothing: float = SequenceConfig.smoothing,
    ) -> np.ndarray:
        """The garment on every target body of a sequence: (T, N, 3).

        ``smoothing`` (frames, >= 0; 0 turns it off): the network's correction to the prior, G - G^prior, is
        smoothed over time with a Gaussian of this standard deviation before the post-process of each frame (the
        prior carries the motion, so only the network's frame-to-frame noise is removed; the whole sequence is
        known, so the filter is centred and adds no lag). With the refinement on, the refined frames' correction is
        smoothed once more and refined again (a near-valid drape, so the second pass is cheap and moves little): the
        refinement's own frame-to-frame changes would otherwise add the jitter the first filter removed. The bare
        prior is never smoothed.

        ``body_targets`` is a sequence of meshes (or vertex arrays sharing the canonical body's faces) or a
        (T, Vb, 3) array. Per-garment and per-body work is done once per sequence: validating the canonical body and
        the garment and their relation (``Scene``), and through content-keyed caches the soft anchors, the graph
        topology, the rig fit of the canonical body and the network's pose-free features; each frame pays for its
        target body's prior, the network and the refinement.
        """
        if isinstance(body_targets, (str, os.PathLike)) or is_mesh_pair(body_targets):
            raise ValueError(
                "body_targets is one mesh: give a list of target bodies (meshes, files or vertex arrays) or a "
                "(T, V, 3) array; one target: GarSim.drape"
            )
        targets = list(body_targets)
        if not targets:
            raise ValueError("body_targets is empty: give at least one target body")
        sigma = check_smoothing(smoothing)
        scene = Scene.make(body_canonical, garment, fabric, pinned, up=up, units=units)  # once per sequence
        from tqdm import tqdm

        with tqdm(total=2 * len(targets), disable=not progress, unit="step") as bar:
            samples, raw = [], []
            for t in targets:
                samples.append(scene.sample(t))
                raw.append(self.raw(samples[-1]))
                bar.update()
            priors = np.stack([s.prior for s in samples])
            turns = None  # each frame's root-frame turn: the corrections are smoothed in the body's root frame
            if sigma > 0 and len(raw) > 1:
                turns = np.stack([np.eye(3) if f is None else f[0] for f in map(root_frame, samples)])
                raw = list(smooth_corrections(np.stack(raw), priors, sigma, turns))
            refined = self.model is not None and self.refine and self.collision_margin is not None
            twice = refined and sigma > 0 and len(samples) > 1
            memos: list = [None] * len(samples)
            if twice:  # each frame's first refinement leaves its distance queries to its second (garsim.refine)
                from garsim.refine import RefineMemo

                memos = [RefineMemo() for _ in samples]
            done = []
            for sample, pred, memo in zip(samples, raw, memos):
                done.append(self.finish(pred, sample, memo))
                bar.update()
            if twice:  # the refinement's own frame-to-frame changes, smoothed
                again = smooth_corrections(np.stack(done), priors, sigma, turns)
                # without the fallback: the first pass handed what needed it to the prior, the smoothing spread that
                # over time; handing patches to it again here would bring back the jumps the smoothing removed
                done = [self.finish(p, s, m, fallback=False) for s, p, m in zip(samples, again, memos)]
        return np.stack([from_internal(scene.unweld(f), up, units).astype(np.float32) for f in done])
