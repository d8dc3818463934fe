"""Inside-the-body tests: an exact one (warp winding number, ms per call) and DeePSD's cheap proxy.

:class:`InsideTester` builds one ``wp.Mesh`` with winding-number support for a body, refits it
when the body moves (:meth:`InsideTester.update`), and classifies points on the CPU device.
The generalised winding number is robust to the small holes and self-touching regions a body
mesh has (eyes, mouth), unlike ray parity. ``trimesh``'s ``contains`` took ~30 s for the same job.
The same BVH answers closest-point queries (:meth:`InsideTester.closest`: closest surface point and its
face) and segment queries (:meth:`InsideTester.segment_hits`: does a segment meet the surface).
The one-shot functions (:func:`inside_mask`, :func:`closest_on_mesh`, :func:`segment_hits`) share one
tester per body, cached by content, so the metrics of several predictions on one body build it once.
Those answers are warp's float32 ones. :class:`Obstacle` (:func:`obstacle`) is garsim's one exact query: the
closest point on the triangles recomputed in float64 with its sign from the angle-weighted pseudo-normal of the
feature it lies on; :func:`surface_funcs` hands its warp functions to kernels elsewhere (``garsim.refine``).

:func:`collision_fraction` is the metric of DeePSD / the paper: each garment vertex is compared
with its nearest body vertex and that vertex's normal, and counts as colliding when
``(x - b) . n < 0``.
"""

# No ``from __future__ import annotations`` here: warp reads the kernels' annotations, and a string annotation
# cannot name the local warp struct (Surface) that they take.
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache
from types import SimpleNamespace
from typing import Any

import numpy as np

from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.proximity import signed_offset_to_nearest

_DEVICE = "cpu"
UNBOUNDED = 1.0e6
"""m: the search radius of a query that must find the closest point wherever it is."""
_SLACK = 1e-5  # m: added to every float32 search radius, far above its rounding (~1e-6 at 10 m from the origin)
_AGREE_FULL = float(np.cos(np.radians(25.0)))  # contact_plane: nearby face normals this much alike (two faces up to
_AGREE_NONE = float(np.cos(np.radians(45.0)))  # 50 degrees apart) are averaged, from 90 degrees apart on ignored
_AGREE_SPAN = _AGREE_FULL - _AGREE_NONE
_TESTERS = ContentCache(4)  # per body mesh: the one-shot functions' InsideTester (never handed out)


@lru_cache(maxsize=1)
def quiet_warp():
    """Import and initialise warp once, quietly: no banner on stdout, and on a Linux machine without a CUDA driver
    not warp's "Could not find or load the NVIDIA CUDA driver" on stderr either (garsim runs on the CPU; the kernel
    cache is ``~/.cache/warp``).

    Every garsim module that uses warp (directly, or through Anny or Newton) calls this first."""
    import warp as wp
    import warp._src.context as wp_context

    if wp_context.runtime is None:  # not initialised yet by another garsim module
        wp.config.quiet = True
        if hasattr(wp, "LOG_WARNING"):
            wp.config.log_level = wp.LOG_WARNING
        with _stderr_silenced(sys.platform.startswith("linux") and not _cuda_driver_present()):
            wp.init()
    return wp


def _cuda_driver_present() -> bool:
    """Whether the CUDA driver library loads (what warp's initialisation tries, warning on stderr when it cannot)."""
    import ctypes

    for name in ("libcuda.so", "libcuda.so.1"):
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


@contextmanager
def _stderr_silenced(silence: bool) -> Iterator[None]:
    """Send what native code writes to file descriptor 2 to /dev/null while in the block (when ``silence``)."""
    if not silence:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@lru_cache(maxsize=1)
def _kernels():
    wp = quiet_warp()

    @wp.kernel(module="unique")
    def inside_kernel(
        mesh: wp.uint64,
        points: wp.array(dtype=wp.vec3),
        accuracy: float,
        threshold: float,
        out: wp.array(dtype=wp.int32),
    ):
        tid = wp.tid()
        q = wp.mesh_query_point_sign_winding_number(mesh, points[tid], 1.0e6, accuracy, threshold)
        inside = 0
        if q.result:
            if q.sign < 0.0:
                inside = 1
        out[tid] = inside

    @wp.kernel(module="unique")
    def signed_distance_kernel(
        mesh: wp.uint64,
        points: wp.array(dtype=wp.vec3),
        accuracy: float,
        threshold: float,
        out: wp.array(dtype=float),
    ):
        tid = wp.tid()
        p = points[tid]
        q = wp.mesh_query_point_sign_winding_number(mesh, p, 1.0e6, accuracy, threshold)
        d = 1.0e6
        if q.result:
            c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
            d = wp.length(p - c) * q.sign
        out[tid] = d

    @wp.kernel(module="unique")
    def closest_kernel(
        mesh: wp.uint64,
        points: wp.array(dtype=wp.vec3),
        out_point: wp.array(dtype=wp.vec3),
        out_face: wp.array(dtype=wp.int32),
    ):
        tid = wp.tid()
        q = wp.mesh_query_point_no_sign(mesh, points[tid], 1.0e6)
        face = -1
        c = points[tid]
        if q.result:
            face = q.face
            c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        out_point[tid] = c
        out_face[tid] = face

    @wp.kernel(module="unique")
    def segment_kernel(
        mesh: wp.uint64,
        starts: wp.array(dtype=wp.vec3),
        ends: wp.array(dtype=wp.vec3),
        out: wp.array(dtype=wp.int32),
    ):
        tid = wp.tid()
        d = ends[tid] - starts[tid]
        hit = 0
        if wp.length(d) > 0.0:  # max_t = 1 in multiples of d: the segment itself
            hit = wp.where(wp.mesh_query_ray_anyhit(mesh, starts[tid], d, 1.0), 1, 0)
        out[tid] = hit

    return inside_kernel, signed_distance_kernel, closest_kernel, segment_kernel


# ----------------------------------------------------------------------------------------------------
# exact signed closest points on a triangle mesh (float64), the one implementation garsim uses: the obstacle
# of garsim.refine, and any other exact query (Obstacle.query)


@lru_cache(maxsize=1)
def surface_funcs() -> SimpleNamespace:
    """The warp functions of the exact signed closest-point query, for kernels elsewhere (garsim.refine) to call:
    ``signed_closest(surface, p, radius)`` -> (found, signed distance, closest point, outward unit normal) on a
    ``Surface`` (:attr:`Obstacle.surface`), its parts, and the ``query_points`` kernel behind :meth:`Obstacle.query`."""
    wp = quiet_warp()
    f64 = wp.float64

    @wp.struct
    class Surface:
        """A posed obstacle as the query reads it: its BVH, float64 vertices, faces, each face's neighbour across
        each edge (-1 on a boundary) and the faces around each vertex (CSR: vf_face[vf_start[v]:vf_start[v + 1]])."""

        mesh: wp.uint64
        verts: wp.array(dtype=wp.vec3d)
        faces: wp.array2d(dtype=wp.int32)
        face_adj: wp.array2d(dtype=wp.int32)
        vf_start: wp.array(dtype=wp.int32)
        vf_face: wp.array(dtype=wp.int32)

    @wp.func
    def smoothstep(t: wp.float64) -> wp.float64:
        """3t^2 - 2t^3 of t clipped to [0, 1] (as garsim.geometry.proximity.smoothstep)."""
        u = wp.clamp(t, f64(0.0), f64(1.0))
        return u * u * (f64(3.0) - f64(2.0) * u)

    @wp.func
    def closest_on_triangle(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d) -> wp.vec3d:
        """(v, w, feature) of the closest point a + v (b - a) + w (c - a) (Ericson 5.1.5); feature 0 is the
        interior, 1 + k corner k, 4 + k the edge opposite corner k."""
        ab = b - a
        ac = c - a
        ap = p - a
        d1 = wp.dot(ab, ap)
        d2 = wp.dot(ac, ap)
        if d1 <= f64(0.0) and d2 <= f64(0.0):
            return wp.vec3d(f64(0.0), f64(0.0), f64(1.0))
        bp = p - b
        d3 = wp.dot(ab, bp)
        d4 = wp.dot(ac, bp)
        if d3 >= f64(0.0) and d4 <= d3:
            return wp.vec3d(f64(1.0), f64(0.0), f64(2.0))
        vc = d1 * d4 - d3 * d2
        if vc <= f64(0.0) and d1 >= f64(0.0) and d3 <= f64(0.0):
            return wp.vec3d(d1 / (d1 - d3), f64(0.0), f64(6.0))
        cp = p - c
        d5 = wp.dot(ab, cp)
        d6 = wp.dot(ac, cp)
        if d6 >= f64(0.0) and d5 <= d6:
            return wp.vec3d(f64(0.0), f64(1.0), f64(3.0))
        vb = d5 * d2 - d1 * d6
        if vb <= f64(0.0) and d2 >= f64(0.0) and d6 <= f64(0.0):
            return wp.vec3d(f64(0.0), d2 / (d2 - d6), f64(5.0))
        va = d3 * d6 - d5 * d4
        if va <= f64(0.0) and (d4 - d3) >= f64(0.0) and (d5 - d6) >= f64(0.0):
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            return wp.vec3d(f64(1.0) - w, w, f64(4.0))
        den = va + vb + vc
        return wp.vec3d(vb / den, vc / den, f64(0.0))

    @wp.func
    def face_normal(verts: wp.array(dtype=wp.vec3d), faces: wp.array2d(dtype=wp.int32), f: int) -> wp.vec3d:
        a = verts[faces[f, 0]]
        n = wp.cross(verts[faces[f, 1]] - a, verts[faces[f, 2]] - a)
        length = wp.length(n)
        if length > f64(1e-30):
            return n / length
        return wp.vec3d()

    @wp.func
    def feature_normal(surface: Surface, f: int, feature: int) -> wp.vec3d:
        """Angle-weighted pseudo-normal (unnormalised) of a feature of face f (see closest_on_triangle)."""
        verts = surface.verts
        faces = surface.faces
        n = face_normal(verts, faces, f)
        if feature >= 4:  # edge: the sum of its faces' unit normals
            g = surface.face_adj[f, feature - 4]
            if g >= 0:
                n = n + face_normal(verts, faces, g)
        elif feature >= 1:  # vertex: its corners' unit normals weighted by the corner angles
            v = faces[f, feature - 1]
            n = wp.vec3d()
            for k in range(surface.vf_start[v], surface.vf_start[v + 1]):
                g = surface.vf_face[k]
                c = 0
                if faces[g, 1] == v:
                    c = 1
                elif faces[g, 2] == v:
                    c = 2
                a = verts[v]
                u = verts[faces[g, (c + 1) % 3]] - a
                w = verts[faces[g, (c + 2) % 3]] - a
                cosine = wp.dot(u, w) / wp.max(wp.length(u) * wp.length(w), f64(1e-30))
                n = n + wp.acos(wp.clamp(cosine, f64(-1.0), f64(1.0))) * face_normal(verts, faces, g)
        return n

    @wp.func
    def signed_closest(surface: Surface, p: wp.vec3d, radius: wp.float64):
        """(found, signed distance, closest point, outward unit normal) of p, searched within ``radius``."""
        q = wp.mesh_query_point_no_sign(surface.mesh, wp.vec3(p), wp.float32(radius) + wp.float32(_SLACK))
        if not q.result:
            return 0, radius, wp.vec3d(), wp.vec3d()
        f = q.face
        verts = surface.verts
        faces = surface.faces
        a = verts[faces[f, 0]]
        b = verts[faces[f, 1]]
        c = verts[faces[f, 2]]
        vw = closest_on_triangle(p, a, b, c)
        cp = a + vw[0] * (b - a) + vw[1] * (c - a)
        fn = feature_normal(surface, f, int(vw[2]))
        diff = p - cp
        dist = wp.length(diff)
        sign = f64(1.0)
        if wp.dot(diff, fn) < f64(0.0):
            sign = f64(-1.0)
        n = wp.normalize(fn)
        if dist > f64(1e-12):
            n = sign * diff / dist
        return 1, sign * dist, cp, n

    @wp.func
    def contact_plane(surface: Surface, p: wp.vec3d, s: wp.float64, n: wp.vec3d, blend: wp.float64):
        """(point, outward unit normal) of a contact half-space at p that turns continuously with p across the
        ridges of a faceted surface, where the closest feature's own normal ``n`` jumps as p crosses the bisector of
        two faces (inside a convex ridge, outside a concave one: by the ridge's angle under an arbitrarily small
        move) or turns by the wedge's angle within |s| of an edge outside a convex ridge (``s``: p's signed
        distance). The faces g within |s| + ``blend`` of p average their unit normals, weighted by smoothstep((|s| +
        blend - |p - c_g|) / ``blend``) (c_g: g's closest point to p); the normal is that average where the faces
        agree and it agrees with ``n`` (the mean's length, and its cosine with ``n``, each cos(angle / 2) for two
        equally weighted faces of a ridge, both at least ``_AGREE_FULL``: ridges up to 50 degrees), ``n`` where either
        is at most ``_AGREE_NONE`` (the two sides of a gap between body parts or of a thin part, where the nearest
        surface changes sides and the normal jumps, as the distance's gradient does; many small faces on the far
        side would otherwise outweigh the near side's few), normalised from a smoothstep mix in between. The point
        is p - s * normal: the half-space is the first-order model of the signed distance at p (exactly ``s``
        there; along a blended normal, not exactly its gradient)."""
        reach = wp.abs(s) + blend
        r32 = wp.float32(reach) + wp.float32(_SLACK)
        p32 = wp.vec3(p)
        query = wp.mesh_query_aabb(surface.mesh, p32 - wp.vec3(r32, r32, r32), p32 + wp.vec3(r32, r32, r32))
        verts = surface.verts
        faces = surface.faces
        wsum = f64(0.0)
        nsum = wp.vec3d()
        g = int(0)  # noqa: UP018 (warp: a dynamic loop variable the query writes, not a constant)
        while wp.mesh_query_aabb_next(query, g):
            a = verts[faces[g, 0]]
            b = verts[faces[g, 1]]
            c = verts[faces[g, 2]]
            vw = closest_on_triangle(p, a, b, c)
            w = smoothstep((reach - wp.length(p - (a + vw[0] * (b - a) + vw[1] * (c - a)))) / blend)
            wsum = wsum + w
            nsum = nsum + w * face_normal(verts, faces, g)
        m = n
        length = wp.length(nsum)
        if wsum > f64(0.0) and length > f64(0.0):
            mean = nsum / length
            # agreement among the faces (the mean's length) and with the nearest feature (many small faces across a
            # gap can outweigh the near side's few: their mean then points into the near side)
            k = smoothstep((length / wsum - f64(_AGREE_NONE)) / f64(_AGREE_SPAN))
            k = k * smoothstep((wp.dot(mean, n) - f64(_AGREE_NONE)) / f64(_AGREE_SPAN))
            if k > f64(0.0):
                m = wp.normalize(k * mean + (f64(1.0) - k) * n)  # the mean is within 45 degrees of n: never zero
        return p - s * m, m

    @wp.kernel(enable_backward=False, module="unique")
    def query_points(
        surface: Surface,
        p: wp.array(dtype=wp.vec3d),
        radius: wp.float64,
        blend: wp.float64,
        found: wp.array(dtype=wp.int32),
        sd: wp.array(dtype=wp.float64),
        close: wp.array(dtype=wp.vec3d),
        normal: wp.array(dtype=wp.vec3d),
    ):
        t = wp.tid()
        ok, sd_t, cp, n = signed_closest(surface, p[t], radius)
        if ok == 1 and blend > f64(0.0):
            cp, n = contact_plane(surface, p[t], sd_t, n, blend)
        found[t] = ok
        sd[t] = sd_t
        close[t] = cp
        normal[t] = n

    return SimpleNamespace(
        Surface=Surface,
        smoothstep=smoothstep,
        closest_on_triangle=closest_on_triangle,
        face_normal=face_normal,
        feature_normal=feature_normal,
        signed_closest=signed_closest,
        contact_plane=contact_plane,
        query_points=query_points,
    )


def _wp(a: np.ndarray, dtype: Any) -> Any:
    """A warp CPU array over a numpy array's memory (no copy)."""
    return quiet_warp().array(a, dtype=dtype, device=_DEVICE, copy=False)


# ----------------------------------------------------------------------------------------------------
# obstacle: a warp BVH per face array, refit per pose


class Obstacle:
    """A triangle mesh's topology prepared for signed closest-point queries; :meth:`pose` moves it.

    Per face array: the BVH (built once, refit per pose), each face's neighbour across each edge and the
    faces around each vertex, from which the queries compute the pseudo-normals of the features they hit.
    """

    def __init__(self, faces: np.ndarray, num_vertices: int, faces_key: tuple = ()) -> None:
        wp = quiet_warp()
        self.faces_key = faces_key  # the content key of the face array (with the vertex count)
        f = np.asarray(faces, dtype=np.int64)
        nf = len(f)
        # the face across each face edge (edge k opposite corner k); -1 on a boundary
        a = np.stack([f[:, 1], f[:, 2], f[:, 0]], axis=1).ravel()
        b = np.stack([f[:, 2], f[:, 0], f[:, 1]], axis=1).ravel()
        key = np.minimum(a, b) * num_vertices + np.maximum(a, b)
        order = np.argsort(key, kind="stable")
        pair = np.flatnonzero(key[order][1:] == key[order][:-1])
        adj = np.full(3 * nf, -1, dtype=np.int64)
        adj[order[pair]] = order[pair + 1] // 3
        adj[order[pair + 1]] = order[pair] // 3
        # faces around each vertex (CSR)
        corner_face = np.argsort(f.ravel(), kind="stable") // 3
        start = np.concatenate([[0], np.cumsum(np.bincount(f.ravel(), minlength=num_vertices))])
        self.faces = wp.array(f.astype(np.int32), dtype=wp.int32, device=_DEVICE)
        self.indices = wp.array(f.astype(np.int32).ravel(), dtype=wp.int32, device=_DEVICE)
        self.face_adj = wp.array(adj.reshape(-1, 3).astype(np.int32), dtype=wp.int32, device=_DEVICE)
        self.vf_start = wp.array(start.astype(np.int32), dtype=wp.int32, device=_DEVICE)
        self.vf_face = wp.array(corner_face.astype(np.int32), dtype=wp.int32, device=_DEVICE)
        self.points32 = wp.zeros(num_vertices, dtype=wp.vec3, device=_DEVICE)
        self.points = wp.zeros(num_vertices, dtype=wp.vec3d, device=_DEVICE)
        self.mesh: Any = None
        self.key: tuple | None = None
        # what every kernel that queries the obstacle takes (the BVH's id is set once the first pose builds it)
        self.surface = surface_funcs().Surface()
        self.surface.verts, self.surface.faces, self.surface.face_adj = self.points, self.faces, self.face_adj
        self.surface.vf_start, self.surface.vf_face = self.vf_start, self.vf_face

    def pose(self, vertices: np.ndarray) -> "Obstacle":
        """Move the mesh to ``vertices`` (refit the BVH) unless it is there."""
        v = np.ascontiguousarray(vertices, dtype=np.float64)
        key = content_key(v)
        if key == self.key:
            return self
        self.points.numpy()[:] = v
        self.points32.numpy()[:] = v
        if self.mesh is None:
            self.mesh = quiet_warp().Mesh(points=self.points32, indices=self.indices)
            self.surface.mesh = self.mesh.id
        else:
            self.mesh.refit()
        self.key = key
        return self

    def query(
        self, points: np.ndarray, radius: float = UNBOUNDED, blend: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance (negative inside), closest point, outward unit normal and ``found`` of each point:
        exact where the surface is within ``radius`` (``found``), else distance ``radius``, zero vectors.
        ``blend`` > 0 (m): the point and normal are instead those of the continuous contact half-space
        (``contact_plane``) that garsim.refine uses with ``CONTACT_BLEND``."""
        if not np.isfinite(blend) or blend < 0:
            raise ValueError(f"blend must be a finite distance >= 0 metres (0: the exact closest point), got {blend!r}")
        wp = quiet_warp()
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        m = len(p)
        found, sd = np.zeros(m, dtype=np.int32), np.zeros(m)
        close, normal = np.zeros((m, 3)), np.zeros((m, 3))
        if m:
            wp.launch(
                surface_funcs().query_points,
                dim=m,
                inputs=[self.surface, _wp(p, wp.vec3d), float(radius), float(blend)],
                outputs=[_wp(found, wp.int32), _wp(sd, wp.float64), _wp(close, wp.vec3d), _wp(normal, wp.vec3d)],
                device=_DEVICE,
            )
        return sd, close, normal, found.astype(bool)


_OBSTACLES = ContentCache(4)


def obstacle(body_vertices: np.ndarray, body_faces: np.ndarray) -> Obstacle:
    """The obstacle for a triangle mesh, posed at ``body_vertices``: one per face array (cached by content);
    a new pose refits it, so use it before asking for another pose of the same faces."""
    f = np.asarray(body_faces, dtype=np.int64)
    n = len(body_vertices)
    key = content_key(f) + (n,)
    return _OBSTACLES.get(key, lambda: Obstacle(f, n, key)).pose(body_vertices)


def _as_points(points: np.ndarray, what: str = "points") -> np.ndarray:
    p = np.ascontiguousarray(np.asarray(points, dtype=np.float32))
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{what} must have shape (N, 3), got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{what} contain NaN/inf; fix them before the inside test")
    return p


class InsideTester:
    """Winding-number inside test against one (posable) closed triangle mesh, on warp's CPU device.

    ``accuracy`` is warp's fast-winding-number dipole accuracy (larger = more exact, slower);
    a point is inside when its winding number exceeds ``threshold``.
    """

    def __init__(
        self, body_vertices: np.ndarray, body_faces: np.ndarray, accuracy: float = 2.0, threshold: float = 0.5
    ) -> None:
        from garsim.geometry.io import validate_mesh

        wp = quiet_warp()
        v, f = validate_mesh(body_vertices, body_faces, "body")
        self.num_vertices = len(v)
        self.accuracy = float(accuracy)
        self.threshold = float(threshold)
        self._points = wp.array(v, dtype=wp.vec3, device=_DEVICE)
        self._indices = wp.array(f.astype(np.int32).ravel(), dtype=wp.int32, device=_DEVICE)
        self._mesh = wp.Mesh(points=self._points, indices=self._indices, support_winding_number=True)

    def update(self, body_vertices: np.ndarray) -> None:
        """Move the body (same topology, e.g. a new pose) and refit the BVH and winding-number data."""
        v = _as_points(body_vertices, "body_vertices")
        if len(v) != self.num_vertices:
            raise ValueError(f"update() needs {self.num_vertices} vertices (same topology), got {len(v)}")
        self._points.assign(v)
        self._mesh.refit()

    def _launch(self, points: np.ndarray, which: int, dtype) -> np.ndarray:
        wp = quiet_warp()
        p = _as_points(points)
        if len(p) == 0:
            return np.zeros(0, dtype=dtype)
        wp_points = wp.array(p, dtype=wp.vec3, device=_DEVICE)
        out = wp.zeros(len(p), dtype=wp.int32 if dtype is np.int32 else float, device=_DEVICE)
        kernel = _kernels()[which]
        wp.launch(
            kernel,
            dim=len(p),
            inputs=[self._mesh.id, wp_points, self.accuracy, self.threshold],
            outputs=[out],
            device=_DEVICE,
        )
        return out.numpy()

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: True where a point lies inside the mesh (winding number > threshold)."""
        return self._launch(points, 0, np.int32).astype(bool)

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) float32 distance to the closest surface point, negative inside."""
        return self._launch(points, 1, np.float32)

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) float32 closest surface points and (N,) int64 index of the face each lies on."""
        wp = quiet_warp()
        p = _as_points(points)
        out_point = wp.zeros(len(p), dtype=wp.vec3, device=_DEVICE)
        out_face = wp.zeros(len(p), dtype=wp.int32, device=_DEVICE)
        if len(p):
            wp.launch(
                _kernels()[2],
                dim=len(p),
                inputs=[self._mesh.id, wp.array(p, dtype=wp.vec3, device=_DEVICE)],
                outputs=[out_point, out_face],
                device=_DEVICE,
            )
        return out_point.numpy().reshape(-1, 3), out_face.numpy().astype(np.int64)

    def segment_hits(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """(E,) bool: True where the segment from ``starts[e]`` to ``ends[e]`` meets the surface (a ray hit
        within the segment's length; a zero-length segment never does)."""
        wp = quiet_warp()
        a, b = _as_points(starts, "starts"), _as_points(ends, "ends")
        if a.shape != b.shape:
            raise ValueError(f"starts {a.shape} and ends {b.shape} must have the same shape")
        out = wp.zeros(len(a), dtype=wp.int32, device=_DEVICE)
        if len(a):
            wp.launch(
                _kernels()[3],
                dim=len(a),
                inputs=[
                    self._mesh.id,
                    wp.array(a, dtype=wp.vec3, device=_DEVICE),
                    wp.array(b, dtype=wp.vec3, device=_DEVICE),
                ],
                outputs=[out],
                device=_DEVICE,
            )
        return out.numpy().astype(bool)


def _tester(body_vertices: np.ndarray, body_faces: np.ndarray) -> InsideTester:
    """The cached InsideTester of a body mesh (keyed by content, so an edited body is never served stale)."""
    v = np.ascontiguousarray(body_vertices, dtype=np.float32)
    f = np.ascontiguousarray(body_faces, dtype=np.int64)
    return _TESTERS.get(content_key(v, f), lambda: InsideTester(v, f))


def inside_mask(points: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray) -> np.ndarray:
    """One-shot convenience: (N,) bool inside-the-body mask (winding number, :meth:`InsideTester.inside`)."""
    return _tester(body_vertices, body_faces).inside(points)


def closest_on_mesh(
    points: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One-shot convenience: closest surface points (N, 3) and their faces (N,) (:meth:`InsideTester.closest`)."""
    return _tester(body_vertices, body_faces).closest(points)


def segment_hits(starts: np.ndarray, ends: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray) -> np.ndarray:
    """One-shot convenience: (E,) bool, segments that meet the body surface (:meth:`InsideTester.segment_hits`)."""
    return _tester(body_vertices, body_faces).segment_hits(starts, ends)


def collision_fraction(points: np.ndarray, body_vertices: np.ndarray, body_normals: np.ndarray) -> float:
    """DeePSD's collision ratio: fraction of points with (x - b_q) . n_q < 0 for the nearest body vertex q."""
    p = np.asarray(points)
    if len(p) == 0:
        return 0.0
    return float(np.mean(signed_offset_to_nearest(p, np.asarray(body_vertices), np.asarray(body_normals)) < 0.0))
