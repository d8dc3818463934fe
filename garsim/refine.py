"""Fast physical refinement of a predicted garment: a few constraint projections in native code, no simulator.

:func:`refine` runs after the network on the inference path. It corrects what a learned prediction
gets wrong and a viewer notices, and leaves everything else exactly where the network put it:

(a) stretch: every edge longer than ``max_stretch`` x its rest length (from ``template``) is shortened
    to that limit; compression is left alone (cloth buckles);
(b) contact: every vertex closer than ``margin`` to the obstacle surface, or inside it, goes to
    ``margin`` outside along its contact normal (the outward direction from its closest point on the obstacle's
    triangles, averaged over the facets nearby: ``CONTACT_BLEND``);
(c) edges through the obstacle: an edge that meets the surface (an end inside, or the segment between
    two outside ends crossing it, as a limb cutting the cloth) gets its seven samples (t = 1/8 .. 7/8)
    near the surface pushed to ``SAMPLE_CLEARANCE`` x ``margin`` outside, until no edge meets it. An
    edge with a pinned end inside the obstacle cannot leave it and is left alone;
(d) a small bending term: the correction (not the shape) is diffused once to the one-ring with a
    weight from the fabric's bending length, so a stiff fabric lifts its neighbours a little with a
    pushed vertex. A valid drape has no correction, so this never moves it;
(e) optional ``fallback`` (the API passes the skinning prior): before (a)-(d), a mobile vertex the prediction
    got wrong in a way (a)-(c) would make worse is blended towards the fallback: deeper than ``FALLBACK_DEPTH``
    inside the obstacle, itself or on an edge through it (an edge's depth is that of its deepest sample: a limb
    through the cloth between two shallow vertices), with a weight that rises smoothly with the depth (0 at
    ``FALLBACK_DEPTH``, 1 at ``FALLBACK_DEPTH`` + ``FALLBACK_RAMP``) times a side factor, 1 where the fallback lies
    behind the push-out along the contact normal and 0 where it does not (``FALLBACK_SIDE``: there
    the push-out already goes the fallback's way); or on a torn edge (over ``FALLBACK_STRETCH`` x its rest length,
    weight 1 at ``FALLBACK_STRETCH`` + ``FALLBACK_STRETCH_RAMP``, as far as the fallback's own edge is less torn);
    the weight is spread over a
    few rings of the mesh (so a patch moves as a whole and fades out at its border), and further out where the
    fade would stretch an edge past ``FALLBACK_BORDER`` x its rest length (a patch far from the fallback fades
    over as many rings as it needs, not only those few). Pushed out to its own
    nearest surface point, a patch sunk past a limb's centre line wraps the limb's far side (stretched
    ~R / (R - depth), neighbours on opposite sides, edges through it); a sleeve wall with the wrist through it
    is pushed out on both sides of the wrist; a torn patch pulled back by (a) is dragged straight across the
    limb between its vertices. The prior follows the limbs by skinning, on the right side of them, even where
    it is itself inside the body (skinning sinks cloth into the torso at the armpit and between the thighs):
    from there (b) pushes it out to the right side, so its own depth does not reduce the weight. On the walk
    cycle this is what brings the sleeves' armpits and cuffs within the bounds (t-shirt max stretch 5.9 -> 1.1,
    long-sleeve 3.7 -> 1.2). A valid drape has nothing that deep or torn, so this never moves it.

Algorithm: position-based dynamics with Jacobi sweeps (order-independent, so the result does not depend on vertex
order), each vertex's corrections averaged with their own lengths as weights (sum c |c| / sum |c|: a constraint alone
moves its vertex in full, one that has just become violated counts as little as it moves it, and the average is
Lipschitz in the state, where a count of the active constraints, even one ramped in over 1 % of the limit, multiplied
the sensitivity of a torn neighbour's correction by ~20) and accelerated by the Chebyshev semi-iterative method (Wang
2015, "A Chebyshev semi-iterative approach for accelerating projective and position-based dynamics"; the momentum fades
out near a contact). Contacts are linearised as half-spaces (the first-order model of the signed distance s at the
query point p, with a normal n that turns continuously across the body's facets: n.(x - p) + s >= margin; see
``CONTACT_BLEND``) from exact distance queries, refreshed after every ``iterations`` sweeps (a round) for the
vertices that moved near the surface; rounds repeat until nothing is violated, at most ``MAX_ROUNDS`` (a fixed budget:
a prediction tangled with the body is improved, not solved); a final contact projection along the contact normals,
re-queried up to four times, brings every vertex to the margin (to a few micrometres where a deep vertex's contact
normal is not quite the distance's gradient; contact wins over stretch where they conflict), except past the
simulator's rejection bound: a last clamp shortens the edges still over ``TORN_STRETCH`` x their rest length to it
(Jacobi passes, by as much as they need), so no edge with a free end that can be shortened leaves over that bound, even
where that leaves a vertex nearer than the margin or inside (an edge that no move can shorten, at a free vertex between
pins pulled apart, stays as it is).

Continuity: no step is taken or skipped on a threshold of the state except at a fixed point (the rounds end early only
when nothing is violated, where more sweeps would not move anything), and every weight starts from 0 (the fallback's
seeds, a constraint's weight in the average, an edge sample's clearance, ``SAMPLE_RAMP``), so a tiny change of the input
changes the result a little (``garsim.eval.robustness``). Two stages that this rule removed moved tangled drapes by tens
of millimetres under 1e-6 m of input noise: longer rounds while an edge stayed torn, until it was not, and hand-overs to
the fallback of the patches of edges still through the body after the rounds, seeded in full from the surface on.
Without them, an edge sample's clearance ramped and the obstacle centred, the largest change under the robustness checks
fell from 293 to 6.7 mm on 60 of our own templates in the pose sampler's wide range, and from 17.0 to 0.70 mm on the
external set (``docs/studies/refine_continuity.md``). Averaging the corrections by their lengths instead of by a count
then brought the median scene's largest change from 0.09 to 0.02 mm on the external set and from 0.18 to 0.04 mm on
those wide poses, and the scenes over 0.5 mm from 8 to 2 and from 20 to 8 (three noise draws each;
``docs/studies/refine_averaging.md``), with the same or better stretch, collision and error figures. Contact normals
averaged over the nearby facets (``CONTACT_BLEND``) instead of the closest feature's, which turned by a ridge's angle
under any small move of a vertex inside the body, then brought those wide poses' scenes over 0.5 mm from 8 to 6 and
their median from 0.036 to 0.031 mm (``docs/studies/refine_contact_normal.md``). What still jumps, in drapes tangled
with the body: a vertex whose nearest surface changes sides where two body parts nearly meet (crotch, armpit), and the
Chebyshev step's gain, which carries such a jump over the sweeps and rounds (~5x a round on the external trousers
with a leg through them; momentum in the first round only, or less momentum, was no more stable on our own tangled
drapes and less momentum broke the walk cycle's edges-through bound: ``docs/studies/refine_chebyshev.md``).

Closest point on the obstacle (``garsim.geometry.inside.Obstacle``, the one exact query garsim has): a
warp BVH over the obstacle's triangles (float32) finds each point's
closest triangle; the closest point on it is recomputed in float64 (Ericson 5.1.5) together with the
feature it lies on (vertex, edge or interior), whose angle-weighted pseudo-normal gives the inside /
outside sign (Baerentzen & Aanaes 2005; exact for a closed, outward-oriented mesh). Every garment
vertex gets its exact signed distance once; afterwards the distance is 1-Lipschitz: a vertex that
moved by m from where it was last queried at distance d is at least d - m away, so only vertices that
may have come within ``margin`` + ``BAND`` of the surface are queried again, within |d| + m. An edge
is tested only where its ends' distances allow it to reach the surface ((d_i + d_j - length) / 2 <= 0),
by a ray query along it. The BVH and the adjacency the pseudo-normals need are built once per face
array; a new pose refits the BVH (~0.5 ms for Anny's 27k triangles), so the per-pose cost does not
depend on the garment and nothing is approximated away from it.

The sweeps, the queries, the bending term and the fallback blend are warp kernels on the CPU device, which runs
one thread in a fixed order: the accumulations, and so the results, are deterministic. A refit BVH gives the
answers of one built for the pose, up to rounding where a closest point lies on an edge shared by two triangles.

A second call on the same frame (``drape_sequence`` refines every frame again after smoothing the refined
frames over time: a near-valid drape a few millimetres from the first result) can start from the first one's
queries (:class:`RefineMemo`): the 1-Lipschitz bound then holds from the first call's query points, so only the
vertices that may be within ``margin`` + ``BAND`` are queried (the query of every vertex without a radius is
the costliest step of a call), with the result of a call without the memo.

Limits: the obstacle should be closed and outward-oriented for the sign to be right (zero-area triangles are skipped by
the closest-point search and add no normal to a contact's average); where it intersects itself (a posed body's armpits
or thighs) the nearest surface can be that of the other part. Stretch and contact can conflict (a pinned vertex inside
the body, a garment too small for the body, cloth tangled with a limb): contact wins up to ``TORN_STRETCH``, stretch
beyond it (a test maxi skirt with a knee raised into it, where the prediction was torn 6.7x and the prior 8x, left 1.7x
edges against the knee; the clamp brings them to 1.5x and leaves 0.4% of its vertices inside). Pinned vertices that the
prior stretched apart (a long-sleeve's neckline) leave the edges between them and their neighbours over the limit
whatever the sweeps do: such a garment always runs ``MAX_ROUNDS`` rounds. A prediction torn far past the limit (a leg
through trousers) is left to the final clamp after the ordinary rounds, and edges still through the body after them stay
through (see Continuity)."""

# No ``from __future__ import annotations`` here: warp reads the kernels' annotations, and a string annotation
# cannot name the local warp struct (Surface) that they take.
from functools import lru_cache
from types import SimpleNamespace
from typing import Any

import numpy as np

from garsim.garments.fabrics import Fabric, get_fabric
from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.inside import UNBOUNDED, Obstacle, obstacle, quiet_warp, surface_funcs
from garsim.geometry.mesh import unique_edges
from garsim.geometry.proximity import smoothstep

DEFAULT_STRETCH = 1.10
"""Default edge-length limit (x rest length) for preset-like fabrics (membrane stiffness >= 3e3 N/m)."""
MAX_DEFAULT_STRETCH = 1.15
"""The derived default never exceeds this (a very soft custom fabric gets up to it)."""
BAND = 0.004
"""m: vertices within ``margin`` + this of the obstacle get exact contact half-spaces for the sweeps."""
MAX_ROUNDS = 4
"""Rounds of ``iterations`` sweeps at most; a round ends with fresh exact queries for moved vertices."""
TORN_STRETCH = 1.5
"""x rest length (the simulator's own rejection bound): the final clamp shortens the edges still longer."""
EDGE_SAMPLES = (0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875)
"""Edge parameters of the samples that push an edge out of the obstacle for (c)."""
SAMPLE_CLEARANCE = 0.1
"""Edge samples of (c) go this fraction of ``margin`` outside, so that the segment between two of them clears
the surface too ..."""
SAMPLE_RAMP = 0.001
"""m: ... in full once the body reaches this far through the edge (the deeper of its ends inside, or half the length
of the segment inside the body where both ends are outside), from 0 as it starts to meet the surface (at once in
full, an edge that came to touch the surface between its samples moved its vertices by ~0.7 mm in one round)."""
RELAXATION = 1.0
"""Over-relaxation of the averaged Jacobi stretch sweeps (1 = plain averaging)."""
CHEBYSHEV_RHO = 0.95
"""Spectral radius estimate of the Chebyshev acceleration (0 = plain Jacobi). 0.98 leaves the walk cycle's 99th
percentile of the stretch 0.01-0.03 lower in the same four rounds but overshoots: a coarse settled drape whose
long edges cut the body moves twice as far (test_api_stability); 0.99 also oscillates against contacts."""
FALLBACK_DEPTH = 0.01
"""m: a mobile vertex deeper than this inside the obstacle starts to be blended towards the ``fallback``."""
FALLBACK_RAMP = 0.01
"""m: ... and is blended fully (weight 1) this much deeper (a smoothstep in between)."""
FALLBACK_STRETCH = 2.0
"""x rest length: a mobile vertex with an edge longer than this is blended towards the ``fallback`` too (a torn
patch: projecting its edges back drags its vertices straight across the limb between them) ..."""
FALLBACK_STRETCH_RAMP = 1.0
"""... fully once the edge is this much (x rest length) longer (a smoothstep in between), and only as far as the
fallback's own edge is shorter: scaled by the same smoothstep of the two length ratios' difference (0 where the
fallback is torn as much, as the skinning prior is between a skirt's legs)."""
FALLBACK_SIDE = 0.5
"""A deep vertex, or the deepest sample of an edge through the obstacle, seeds the fallback only where the fallback
lies behind its push-out: with c the cosine between its contact normal and the way to the fallback,
the seed is scaled by smoothstep(-c / this), 0 from c = 0 on (the push-out already takes it the fallback's way, and
handing the patch to the skinning prior there only adds the prior's error), 1 from c = -this (pushed out to its own
nearest surface it would wrap the limb's far side). On 260 training samples of v4 the blend without this test and
the torn-edge factor below cost 1.9 mm of mean error over no fallback at all (skirts 7.2 mm, dresses 2.3), with
them 0.5 mm (docs/studies/fallback_side.md)."""
FALLBACK_SIDE_EPS = 0.001
"""m: the way to the fallback counts fully once the fallback is this far off, so that the cosine is continuous where
prediction and fallback meet."""
_SIDE_EPS2 = FALLBACK_SIDE_EPS**2
FALLBACK_PASSES = 4
"""Passes that spread the fallback weight over the mesh (w = max(w, mean of w over the closed one-ring))."""
FALLBACK_BORDER = 1.5
"""x rest length: then, where the fade would stretch an edge past this (and past both its length in the prediction
and in the fallback), the weight at its lower end is raised just enough to keep it there (the smaller root of a
quadratic), and so on outwards: the fade widens only where the patch moves far from its neighbours (the 4 rings
alone tore the border of a long-sleeve's blended forearm patch from 5.2x to 10x, which the sweeps then could not
close against the contacts) ..."""
FALLBACK_WIDEN_PASSES = 64
"""... over at most this many Jacobi passes (each widens the fade by one ring; they stop once nothing changes)."""
CLAMP_PASSES = 1000
"""Passes at most of the final clamp of edges still over ``TORN_STRETCH`` x their rest length after the contact
projection (``_State.clamp_torn``; none where no edge is that long: a strip pinned beside a sphere, left at 2.7x by
the contacts, took ~400) ..."""
CLAMP_PATIENCE = 50
"""... ending early once the total excess over the bound has not fallen for this many passes ..."""
CLAMP_PLAIN = 8
"""... the first this many plain Jacobi passes (the test skirt's took 5 and moved no vertex more than 4 mm), the rest
accelerated ..."""
CLAMP_RHO = 0.99
"""... by the Chebyshev step with this spectral radius estimate (8x fewer passes than plain Jacobi on that strip; the
least-excess iterate is kept, so an oscillation costs passes, not the result)."""
CONTACT_BLEND = 0.001
"""m: a contact half-space's normal averages those of the body's faces within this of the nearest one's distance
where they agree (``garsim.geometry.inside`` ``contact_plane``), so that it turns with the vertex instead of jumping
where the vertex crosses the bisector of two faces (inside a convex ridge of the faceted body: the external set's
trousers with a leg through them moved 2.5 mm under 1e-6 m of input noise, a vertex 4 mm inside a thigh turning its
normal by 20 degrees)."""
_STRETCH_TOL = 1e-3  # relative: an edge within limit * (1 + this) counts as satisfied
_DIST_TOL = 1e-6  # m
_DEVICE = "cpu"


# ----------------------------------------------------------------------------------------------------
# warp kernels (built on first use; warp caches the compiled code on disk)


@lru_cache(maxsize=1)
def _kernels() -> SimpleNamespace:
    wp = quiet_warp()
    f64 = wp.float64
    surface_query = surface_funcs()  # the shared exact query (garsim.geometry.inside)
    signed_closest, Surface = surface_query.signed_closest, surface_query.Surface
    contact_plane = surface_query.contact_plane
    ramp = surface_query.smoothstep

    @wp.kernel(enable_backward=False, module="unique")
    def vertex_state(
        surface: Surface,
        x: wp.array(dtype=wp.vec3d),
        mobile: wp.array(dtype=wp.float64),
        band: wp.float64,
        first: int,
        xq: wp.array(dtype=wp.vec3d),
        dq: wp.array(dtype=wp.float64),
        cq: wp.array(dtype=wp.vec3d),
        nq: wp.array(dtype=wp.vec3d),
        d: wp.array(dtype=wp.float64),
        active: wp.array(dtype=wp.int32),
        xs: wp.array(dtype=wp.vec3d),
        fresh: wp.array(dtype=wp.int32),
    ):
        """Each vertex's signed distance ``d`` (exact, or a lower bound >= ``band``) and whether it has a
        contact half-space (``active``: exact, mobile, within ``band``); (xq, dq) is its last exact query, (cq, nq)
        its contact half-space's point and normal there where it was within ``band``. ``first``: 0, query the
        vertices that moved and may be within ``band``; 1, query every vertex without a radius; 2 (a warm start:
        (xq, dq) from an earlier call on the same obstacle pose), query every vertex that may be within ``band``;
        with ``first`` != 0 every edge is tested again."""
        i = wp.tid()
        fresh[i] = 0
        if first != 0 or wp.length(x[i] - xs[i]) > f64(0.0):  # moved since the last edge tests (sample_state)
            fresh[i] = 1
            xs[i] = x[i]
        moved = wp.length(x[i] - xq[i])
        if first != 0 or moved > f64(0.0):
            bound = dq[i] - moved  # the distance is 1-Lipschitz
            if first != 1 and bound >= band:
                d[i] = bound
                active[i] = 0
                return
            radius = f64(UNBOUNDED)
            if first != 1:
                radius = wp.abs(dq[i]) + moved
            ok, s, cp, n = signed_closest(surface, x[i], radius)
            if s < band:  # a half-space (active, the fallback's side test, the final projection): continuous
                cp, n = contact_plane(surface, x[i], s, n, f64(CONTACT_BLEND))
            xq[i] = x[i]
            dq[i] = s
            cq[i] = cp
            nq[i] = n
        d[i] = dq[i]
        active[i] = 0
        if dq[i] < band and mobile[i] > f64(0.0):
            active[i] = 1

    @wp.kernel(enable_backward=False, module="unique")
    def sample_state(
        surface: Surface,
        x: wp.array(dtype=wp.vec3d),
        d: wp.array(dtype=wp.float64),
        mobile: wp.array(dtype=wp.float64),
        edges: wp.array2d(dtype=wp.int32),
        ts: wp.array(dtype=wp.float64),
        keep: wp.float64,
        floor: wp.float64,
        hit: wp.array(dtype=wp.int32),
        close: wp.array2d(dtype=wp.vec3d),
        normal: wp.array2d(dtype=wp.vec3d),
        listed: wp.array(dtype=wp.int32),
        count: wp.array(dtype=wp.int32),
        fresh: wp.array(dtype=wp.int32),
        depth: wp.array(dtype=wp.float64),
        deep_normal: wp.array(dtype=wp.vec3d),
        deep_t: wp.array(dtype=wp.float64),
        clearance: wp.array(dtype=wp.float64),
    ):
        """Whether edge e meets the surface (``hit``: an endpoint inside, or the segment crosses it), and if
        so the half-space of each of its samples nearer than ``keep`` (appended to ``listed`` as
        e * len(ts) + k); ``depth`` is the signed distance of its deepest sample, ``deep_normal`` / ``deep_t`` that
        sample's outward normal and edge parameter; ``clearance`` how far outside its samples go, ``floor`` x a
        smoothstep of how far the body reaches through it over ``SAMPLE_RAMP``. The distance is 1-Lipschitz: a
        segment is at least (d_i + d_j - length) / 2 away."""
        e = wp.tid()
        i = edges[e, 0]
        j = edges[e, 1]
        if hit[e] == 0 and fresh[i] == 0 and fresh[j] == 0:
            return  # neither end moved since it was found clear (and the obstacle does not move within a call)
        seg = x[j] - x[i]
        length = wp.length(seg)
        hit[e] = 0
        depth[e] = f64(UNBOUNDED)
        if d[i] + d[j] - length > f64(0.0):
            return
        if (mobile[i] == f64(0.0) and d[i] < f64(0.0)) or (mobile[j] == f64(0.0) and d[j] < f64(0.0)):
            return  # a pinned end inside the obstacle: the edge cannot leave it
        reach = wp.max(-d[i], -d[j])  # an end inside: the deeper one
        if d[i] > f64(0.0) and d[j] > f64(0.0):
            if not wp.mesh_query_ray_anyhit(surface.mesh, wp.vec3(x[i]), wp.vec3(seg), 1.0):
                return
            q = wp.mesh_query_ray(surface.mesh, wp.vec3(x[i]), wp.vec3(seg), 1.0)
            inside = f64(1.0)
            if q.result:
                inside = f64(1.0) - f64(q.t)  # the segment from its first entry ...
            r = wp.mesh_query_ray(surface.mesh, wp.vec3(x[j]), -wp.vec3(seg), 1.0)
            if r.result:
                inside = inside - f64(r.t)  # ... to its last exit
            reach = f64(0.5) * wp.max(inside, f64(0.0)) * length
        hit[e] = 1
        clearance[e] = floor * ramp(reach / f64(SAMPLE_RAMP))
        deep_n = wp.vec3d()
        for k in range(ts.shape[0]):
            t = ts[k]
            bound = wp.max(d[i] - t * length, d[j] - (f64(1.0) - t) * length)
            if bound < keep:
                p = (f64(1.0) - t) * x[i] + t * x[j]
                radius = wp.max(-bound, keep)  # nothing within it: the sample is farther out than keep
                ok, s, cp, n = signed_closest(surface, p, radius)
                if ok == 1 and s < keep:
                    cp, n = contact_plane(surface, p, s, n, f64(CONTACT_BLEND))
                    close[e, k] = cp
                    normal[e, k] = n
                    listed[wp.atomic_add(count, 0, 1)] = e * ts.shape[0] + k
                if ok == 1 and s < depth[e]:
                    depth[e] = s
                    deep_n = n
                    deep_t[e] = t
        if depth[e] < f64(UNBOUNDED):
            if depth[e] >= keep:  # not listed: its contact normal is not computed yet
                p = (f64(1.0) - deep_t[e]) * x[i] + deep_t[e] * x[j]
                cp, deep_n = contact_plane(surface, p, depth[e], deep_n, f64(CONTACT_BLEND))
            deep_normal[e] = deep_n

    @wp.func
    def edge_over(
        x: wp.array(dtype=wp.vec3d),
        stretch_edges: wp.array2d(dtype=wp.int32),
        rest: wp.array(dtype=wp.float64),
        limit: wp.array(dtype=wp.float64),
        ratio: wp.float64,
        scale: wp.float64,
    ) -> int:
        """1 if an edge is longer than ``scale`` x the larger of ``ratio`` x its rest length and its limit."""
        for e in range(stretch_edges.shape[0]):
            bound = scale * wp.max(ratio * rest[e], limit[e])
            if wp.length(x[stretch_edges[e, 1]] - x[stretch_edges[e, 0]]) > bound:
                return 1
        return 0

    @wp.kernel(enable_backward=False, module="unique")
    def violations(
        x: wp.array(dtype=wp.vec3d),
        stretch_edges: wp.array2d(dtype=wp.int32),
        rest: wp.array(dtype=wp.float64),
        limit: wp.array(dtype=wp.float64),
        mobile: wp.array(dtype=wp.float64),
        d: wp.array(dtype=wp.float64),
        hit: wp.array(dtype=wp.int32),
        margin: wp.float64,
        stretch: int,
        out: wp.array(dtype=wp.int32),
    ):
        """out[0] = 1 if an edge is over its limit (``stretch`` != 0 only), a mobile vertex nearer than the margin or
        an edge meets the surface."""
        out[0] = wp.int32(0)  # (wp in the body: warp resolves the annotations from the body's closure)
        if stretch != 0 and edge_over(x, stretch_edges, rest, limit, f64(0.0), f64(1.0 + _STRETCH_TOL)) == 1:
            out[0] = 1
            return
        for i in range(x.shape[0]):
            if mobile[i] > f64(0.0) and d[i] < margin - f64(_DIST_TOL):
                out[0] = 1
                return
        for e in range(hit.shape[0]):
            if hit[e] == 1:
                out[0] = 1
                return

    @wp.kernel(enable_backward=False, module="unique")
    def torn_edges(
        x: wp.array(dtype=wp.vec3d),
        stretch_edges: wp.array2d(dtype=wp.int32),
        rest: wp.array(dtype=wp.float64),
        limit: wp.array(dtype=wp.float64),
        ratio: wp.float64,
        scale: wp.float64,
        out: wp.array(dtype=wp.int32),
    ):
        """out[0] = ``edge_over`` (an edge longer than ``scale`` x max(``ratio`` x rest length, limit))."""
        out[0] = wp.int32(edge_over(x, stretch_edges, rest, limit, ratio, scale))  # (wp: see violations)

    @wp.kernel(enable_backward=False, module="unique")
    def sweeps(
        iterations: int,
        relax: wp.float64,
        rho: wp.float64,
        margin: wp.float64,
        clearance: wp.array(dtype=wp.float64),
        x: wp.array(dtype=wp.vec3d),
        mobile: wp.array(dtype=wp.float64),
        stretch_edges: wp.array2d(dtype=wp.int32),
        limit: wp.array(dtype=wp.float64),
        sample_edges: wp.array2d(dtype=wp.int32),
        ts: wp.array(dtype=wp.float64),
        listed: wp.array(dtype=wp.int32),
        count: wp.array(dtype=wp.int32),
        s_close: wp.array2d(dtype=wp.vec3d),
        s_normal: wp.array2d(dtype=wp.vec3d),
        v_active: wp.array(dtype=wp.int32),
        v_close: wp.array(dtype=wp.vec3d),
        v_normal: wp.array(dtype=wp.vec3d),
        d: wp.array(dtype=wp.float64),
        acc: wp.array(dtype=wp.vec3d),
        wsum: wp.array(dtype=wp.float64),
        current: wp.array(dtype=wp.vec3d),
        previous: wp.array(dtype=wp.vec3d),
        chebyshev: wp.array(dtype=wp.float64),
    ):
        """``iterations`` Jacobi sweeps (one thread, launched with dim 1): (a) stretch, averaged (weighted by the
        corrections' lengths) and over-relaxed; (c) edge-sample half-spaces, averaged alike; (b) vertex half-spaces,
        projected; with ``rho``
        > 0 each sweep ends with the Chebyshev semi-iterative step (Wang 2015) from the iterate before
        (``chebyshev``: the last weight and the number of sweeps so far)."""
        n = x.shape[0]
        if rho > f64(0.0):
            for i in range(n):
                current[i] = x[i]  # the iterate this sweep starts from (kept up to date by the last loop below)
        for _it in range(iterations):
            for e in range(stretch_edges.shape[0]):
                i = stretch_edges[e, 0]
                j = stretch_edges[e, 1]
                dx = x[j] - x[i]
                length2 = wp.dot(dx, dx)
                if length2 > limit[e] * limit[e]:
                    length = wp.sqrt(length2)
                    size = (length - limit[e]) / (mobile[i] + mobile[j])
                    corr = size / length * dx
                    acc[i] = acc[i] + mobile[i] * size * corr
                    wsum[i] = wsum[i] + mobile[i] * size
                    acc[j] = acc[j] - mobile[j] * size * corr
                    wsum[j] = wsum[j] + mobile[j] * size
            for i in range(n):
                if wsum[i] > f64(0.0):
                    x[i] = x[i] + relax * acc[i] / wsum[i]
                    acc[i] = wp.vec3d()
                    wsum[i] = f64(0.0)
            for m in range(count[0]):
                e = listed[m] // ts.shape[0]
                k = listed[m] % ts.shape[0]
                i = sample_edges[e, 0]
                j = sample_edges[e, 1]
                t = ts[k]
                wi = mobile[i] * (f64(1.0) - t)
                wj = mobile[j] * t
                den = wi * (f64(1.0) - t) + wj * t
                nrm = s_normal[e, k]
                depth = clearance[e] - wp.dot((f64(1.0) - t) * x[i] + t * x[j] - s_close[e, k], nrm)
                if depth > f64(0.0) and den > f64(0.0):
                    lam = depth / den
                    acc[i] = acc[i] + (wi * lam) * (wi * lam) * nrm
                    wsum[i] = wsum[i] + wi * lam
                    acc[j] = acc[j] + (wj * lam) * (wj * lam) * nrm
                    wsum[j] = wsum[j] + wj * lam
            w = f64(1.0)
            if rho > f64(0.0):
                if chebyshev[1] == f64(1.0):
                    w = f64(2.0) / (f64(2.0) - rho * rho)
                elif chebyshev[1] > f64(1.0):
                    w = f64(4.0) / (f64(4.0) - rho * rho * chebyshev[0])
                chebyshev[0] = w
                chebyshev[1] = chebyshev[1] + f64(1.0)
            for i in range(n):
                xi = x[i]
                if wsum[i] > f64(0.0):
                    xi = xi + acc[i] / wsum[i]
                    acc[i] = wp.vec3d()
                    wsum[i] = f64(0.0)
                if w != f64(1.0):  # less momentum nearer a contact (continuous in the distance)
                    near = wp.clamp((d[i] - margin) / f64(BAND), f64(0.0), f64(1.0))
                    xi = xi + near * (w - f64(1.0)) * (xi - previous[i])
                if v_active[i] == 1:
                    g = wp.dot(xi - v_close[i], v_normal[i]) - margin
                    if g < f64(0.0):
                        xi = xi - g * v_normal[i]
                x[i] = xi
                if rho > f64(0.0):
                    previous[i] = current[i]
                    current[i] = xi

    @wp.func
    def side_weight(normal: wp.vec3d, shift: wp.vec3d) -> wp.float64:
        """:func:`fallback_side` of one point."""
        c = wp.dot(normal, shift) / wp.sqrt(wp.dot(shift, shift) + f64(_SIDE_EPS2))
        return ramp(-c / f64(FALLBACK_SIDE))

    @wp.func
    def border_weight(c: wp.vec3d, s: wp.vec3d, bound: wp.float64, w_lo: wp.float64, w_hi: wp.float64) -> wp.float64:
        """The least w in [w_lo, w_hi] with |c - w s| <= bound (the smaller root of the quadratic; one exists
        since the edge is within ``bound`` at w_hi)."""
        a = wp.dot(s, s)
        if a <= f64(0.0):
            return w_lo
        b = wp.dot(c, s)
        root = (b - wp.sqrt(wp.max(b * b - a * (wp.dot(c, c) - bound * bound), f64(0.0)))) / a
        return wp.clamp(root, w_lo, w_hi)

    @wp.kernel(enable_backward=False, module="unique")
    def fallback_blend(
        x: wp.array(dtype=wp.vec3d),
        d: wp.array(dtype=wp.float64),
        sample_edges: wp.array2d(dtype=wp.int32),
        hit: wp.array(dtype=wp.int32),
        edge_depth: wp.array(dtype=wp.float64),
        deep_normal: wp.array(dtype=wp.vec3d),
        deep_t: wp.array(dtype=wp.float64),
        normal_q: wp.array(dtype=wp.vec3d),
        stretch_edges: wp.array2d(dtype=wp.int32),
        rest: wp.array(dtype=wp.float64),
        edges: wp.array2d(dtype=wp.int32),
        closed_inv_degree: wp.array(dtype=wp.float64),
        mobile: wp.array(dtype=wp.float64),
        prior: wp.array(dtype=wp.vec3d),
        w: wp.array(dtype=wp.float64),
        ring: wp.array(dtype=wp.float64),
        previous: wp.array(dtype=wp.vec3d),
        out: wp.array(dtype=wp.int32),
        border: wp.float64,
    ):
        """(e), one thread: the fallback weight ``w`` of :func:`fallback_weight` from the seeds of
        :func:`fallback_seed` (a deep vertex with its contact normal ``normal_q``; an edge through the
        obstacle, counted from ``FALLBACK_DEPTH``, at its deepest sample), then x += w * mobile * (prior - x);
        out[1] = 1 if a vertex moved."""
        n = x.shape[0]
        out[1] = 0
        seeded = wp.int32(0)
        for i in range(n):
            w[i] = ramp((-d[i] - f64(FALLBACK_DEPTH)) / f64(FALLBACK_RAMP))
            if w[i] > f64(0.0):
                w[i] = w[i] * side_weight(normal_q[i], prior[i] - x[i])
            if w[i] > f64(0.0):
                seeded = 1
        for e in range(hit.shape[0]):
            if hit[e] == 1:
                v = ramp((-edge_depth[e] - f64(FALLBACK_DEPTH)) / f64(FALLBACK_RAMP))
                if v > f64(0.0):
                    a = sample_edges[e, 0]
                    b = sample_edges[e, 1]
                    t = deep_t[e]
                    shift = (f64(1.0) - t) * (prior[a] - x[a]) + t * (prior[b] - x[b])
                    v = v * side_weight(deep_normal[e], shift)
                if v > f64(0.0):
                    seeded = 1
                    w[sample_edges[e, 0]] = wp.max(w[sample_edges[e, 0]], v)
                    w[sample_edges[e, 1]] = wp.max(w[sample_edges[e, 1]], v)
        for e in range(stretch_edges.shape[0]):
            ratio = wp.length(x[stretch_edges[e, 1]] - x[stretch_edges[e, 0]]) / rest[e]
            v = ramp((ratio - f64(FALLBACK_STRETCH)) / f64(FALLBACK_STRETCH_RAMP))
            if v > f64(0.0):
                own = wp.length(prior[stretch_edges[e, 1]] - prior[stretch_edges[e, 0]]) / rest[e]
                v = v * ramp((ratio - own) / f64(FALLBACK_STRETCH_RAMP))
            if v > f64(0.0):
                seeded = 1
                w[stretch_edges[e, 0]] = wp.max(w[stretch_edges[e, 0]], v)
                w[stretch_edges[e, 1]] = wp.max(w[stretch_edges[e, 1]], v)
        if seeded == 0:
            return
        for _pass in range(FALLBACK_PASSES):  # w = max(w, mean of w over the closed one-ring)
            for i in range(n):
                ring[i] = w[i]
            for e in range(edges.shape[0]):
                ring[edges[e, 0]] = ring[edges[e, 0]] + w[edges[e, 1]]
                ring[edges[e, 1]] = ring[edges[e, 1]] + w[edges[e, 0]]
            for i in range(n):
                w[i] = wp.max(w[i], ring[i] * closed_inv_degree[i])
        for _pass in range(FALLBACK_WIDEN_PASSES):  # Jacobi: raise the lower end of each over-stretched blend
            for i in range(n):
                ring[i] = w[i]
            for e in range(stretch_edges.shape[0]):
                hi = stretch_edges[e, 0]
                lo = stretch_edges[e, 1]
                if w[lo] > w[hi]:
                    hi = stretch_edges[e, 1]
                    lo = stretch_edges[e, 0]
                if w[lo] < w[hi]:
                    c = x[hi] + w[hi] * (prior[hi] - x[hi]) - x[lo]
                    s = prior[lo] - x[lo]
                    bound = wp.max(border * rest[e], wp.length(x[hi] - x[lo]))
                    bound = wp.max(bound, wp.length(prior[hi] - prior[lo]))
                    if wp.length(c - w[lo] * s) > bound * f64(1.0 + _STRETCH_TOL):
                        ring[lo] = wp.max(ring[lo], border_weight(c, s, bound, w[lo], w[hi]))
            widened = wp.int32(0)
            for i in range(n):
                if ring[i] > w[i]:
                    w[i] = ring[i]
                    widened = 1
            if widened == 0:
                break
        for i in range(n):
            wi = w[i] * mobile[i]
            if wi > f64(0.0):
                x[i] = x[i] + wi * (prior[i] - x[i])
                out[1] = 1
            previous[i] = x[i]

    @wp.kernel(enable_backward=False, module="unique")
    def diffuse(
        alpha: wp.float64,
        x: wp.array(dtype=wp.vec3d),
        x0: wp.array(dtype=wp.vec3d),
        edges: wp.array2d(dtype=wp.int32),
        mobile: wp.array(dtype=wp.float64),
        inv_degree: wp.array(dtype=wp.float64),
        ring: wp.array(dtype=wp.vec3d),
    ):
        """(d), one thread: x += alpha * (mean correction x - x0 of the one-ring - own correction) at each mobile
        vertex (``ring``: scratch, left zero)."""
        for e in range(edges.shape[0]):
            i = edges[e, 0]
            j = edges[e, 1]
            ring[i] = ring[i] + (x[j] - x0[j])
            ring[j] = ring[j] + (x[i] - x0[i])
        for i in range(x.shape[0]):
            if mobile[i] > f64(0.0):
                x[i] = x[i] + alpha * mobile[i] * (ring[i] * inv_degree[i] - (x[i] - x0[i]))
            ring[i] = wp.vec3d()

    return SimpleNamespace(
        vertex_state=vertex_state,
        sample_state=sample_state,
        violations=violations,
        torn_edges=torn_edges,
        sweeps=sweeps,
        fallback_blend=fallback_blend,
        diffuse=diffuse,
    )


# ----------------------------------------------------------------------------------------------------
# garment constraints (cached by content: a garment reused across poses is prepared once)


class _Constraints:
    """The edges of a garment, the stretch-limited ones with their limits, and the mobile vertices."""

    def __init__(
        self, template: np.ndarray, faces: np.ndarray, pinned: np.ndarray, limit: float, key: tuple = ()
    ) -> None:
        wp = quiet_warp()
        self.key = key
        n = len(template)
        tpl = np.asarray(template, dtype=np.float64)
        self.edges = unique_edges(faces) if len(faces) else np.zeros((0, 2), dtype=np.int64)
        e = self.edges
        self.mobile = (~pinned).astype(np.float64)
        rest = np.linalg.norm(tpl[e[:, 1]] - tpl[e[:, 0]], axis=1)
        moving = (self.mobile[e[:, 0]] + self.mobile[e[:, 1]]) > 0
        use = (rest > 1e-12) & moving
        self.stretch_edges = e[use]
        self.limit = limit * rest[use]
        self.rest = rest[use]
        self.mean_edge = float(rest.mean()) if len(rest) else 0.0
        deg = np.bincount(e.ravel(), minlength=n).astype(np.float64)
        self.inv_degree = np.where(deg > 0, 1.0 / np.maximum(deg, 1.0), 0.0)
        self.moving_edges = e[moving]
        self.closed_inv_degree = 1.0 / (deg + 1.0)
        self.wp_mobile = wp.array(self.mobile, dtype=wp.float64, device=_DEVICE)
        self.wp_stretch = wp.array(self.stretch_edges.astype(np.int32).reshape(-1, 2), dtype=wp.int32, device=_DEVICE)
        self.wp_limit = wp.array(self.limit, dtype=wp.float64, device=_DEVICE)
        self.wp_rest = wp.array(self.rest, dtype=wp.float64, device=_DEVICE)
        self.wp_closed_inv_degree = wp.array(self.closed_inv_degree, dtype=wp.float64, device=_DEVICE)
        self.wp_edges = wp.array(e.astype(np.int32).reshape(-1, 2), dtype=wp.int32, device=_DEVICE)
        self.wp_inv_degree = wp.array(self.inv_degree, dtype=wp.float64, device=_DEVICE)
        self.wp_moving = wp.array(self.moving_edges.astype(np.int32).reshape(-1, 2), dtype=wp.int32, device=_DEVICE)
        self.wp_ts = wp.array(np.asarray(EDGE_SAMPLES, dtype=np.float64), dtype=wp.float64, device=_DEVICE)
        self.buffers = _buffers(n, (len(self.moving_edges), len(EDGE_SAMPLES)))
        self.commands: tuple | None = None  # (obstacle, margin, recorded launches): see _State.commands


def _buffers(n: int, samples: tuple[int, int]) -> dict[str, Any]:
    """The refinement's working arrays for a garment of ``n`` vertices and ``samples`` edge samples,
    allocated once and reused by every call on that garment (the sweeps leave ``acc`` and ``wsum``, the weighted
    corrections and the sum of their weights, zero)."""
    wp = quiet_warp()
    kinds = {
        "x": (n, wp.vec3d),
        "xq": (n, wp.vec3d),
        "cq": (n, wp.vec3d),
        "nq": (n, wp.vec3d),
        "dq": (n, wp.float64),
        "d": (n, wp.float64),
        "v_active": (n, wp.int32),
        "xs": (n, wp.vec3d),
        "fresh": (n, wp.int32),
        "acc": (n, wp.vec3d),
        "wsum": (n, wp.float64),
        "current": (n, wp.vec3d),
        "previous": (n, wp.vec3d),
        "hit": (samples[0], wp.int32),
        "s_depth": (samples[0], wp.float64),
        "s_deep_normal": (samples[0], wp.vec3d),
        "s_deep_t": (samples[0], wp.float64),
        "s_clearance": (samples[0], wp.float64),
        "s_close": (samples, wp.vec3d),
        "s_normal": (samples, wp.vec3d),
        "s_list": (samples[0] * samples[1], wp.int32),
        "s_count": (1, wp.int32),
        "chebyshev": (2, wp.float64),
        "flag": (2, wp.int32),
        "torn": (1, wp.int32),
        "x0": (n, wp.vec3d),
        "prior": (n, wp.vec3d),
        "w": (n, wp.float64),
        "ring": (n, wp.float64),
        "ring3": (n, wp.vec3d),  # diffuse's one-ring sums (its own: it needs them zero on entry, and leaves them so)
    }
    return {name: wp.zeros(shape, dtype=dtype, device=_DEVICE) for name, (shape, dtype) in kinds.items()}


_CONSTRAINTS = ContentCache(8, scope="garment")


def _constraints(template: np.ndarray, faces: np.ndarray, pinned: np.ndarray, limit: float) -> _Constraints:
    key = content_key(np.asarray(template, dtype=np.float64), faces, pinned) + (limit,)
    return _CONSTRAINTS.get(key, lambda: _Constraints(template, faces, pinned, limit, key))


# ----------------------------------------------------------------------------------------------------
# validation


def _points(a, name: str, n: int | None = None) -> np.ndarray:
    arr = np.asarray(a)
    if arr.ndim != 2 or arr.shape[1] != 3 or (n is not None and len(arr) != n):
        want = f"({n}, 3)" if n is not None else "(N, 3)"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite numbers (found NaN/inf or a non-numeric dtype)")
    return arr


def _faces(a, name: str, n: int) -> np.ndarray:
    f = np.asarray(a)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"{name} must be an integer (F, 3) array, got {f.dtype} {f.shape}")
    if len(f) and (f.min() < 0 or f.max() >= n):
        raise ValueError(f"{name} index vertices outside [0, {n - 1}]")
    return f.astype(np.int64, copy=False)


def default_max_stretch(fabric: str | Fabric) -> float:
    """The edge-length limit for a fabric: 1.10 for the presets, up to 1.15 for a very soft membrane."""
    s = get_fabric(fabric).stretch
    return float(min(MAX_DEFAULT_STRETCH, DEFAULT_STRETCH + float(np.clip(0.05 * np.log10(3.0e3 / s), 0.0, 0.05))))


def smoothing_weight(fabric: str | Fabric, edge_length: float) -> float:
    """Weight of the one-ring diffusion of the correction: 0.5 * l_b / (l_b + edge length), l_b the bending length."""
    lb = get_fabric(fabric).bending_length
    return float(0.5 * lb / (lb + max(edge_length, 1e-6)))


# ----------------------------------------------------------------------------------------------------
# the refinement


class RefineMemo:
    """What a :func:`refine` call learned about its result, for a later call on the same garment, obstacle pose and
    margin: the points of its last exact closest-point queries and their signed distances (two (N,) arrays).

    ``drape_sequence`` refines every frame twice (the second time after a temporal smoothing that moves the garment
    by millimetres); given the first call's memo, the second one starts from these distances (the distance is
    1-Lipschitz) and queries only the vertices that may have come within ``margin`` + ``BAND`` of the surface,
    instead of every vertex without a radius (the costliest step of a call on a near-valid drape). Its result is
    the one a call without the memo gives: every distance it uses below ``margin`` + ``BAND`` is exact either way.
    A memo of another garment, pose or margin is ignored (and overwritten). Not thread-safe (one memo per frame).
    """

    def __init__(self) -> None:
        self.key: tuple | None = None
        self.xq: np.ndarray | None = None
        self.dq: np.ndarray | None = None


class _State:
    """The garment being refined and what the obstacle queries last said about its vertices and edge samples.

    Its arrays are the garment's buffers (see :func:`_buffers`) and its kernel launches are recorded once
    per garment, obstacle and margin (replaying a launch costs a tenth of packing its arguments again).
    """

    def __init__(
        self, x: np.ndarray, obs: Obstacle, con: _Constraints, margin: float, memo: RefineMemo | None = None
    ) -> None:
        self.con, self.margin, self.obs = con, margin, obs
        self.buf = con.buffers
        self.buf["x"].numpy()[:] = x
        self.buf["previous"].numpy()[:] = x
        self.buf["chebyshev"].zero_()
        self.cmd = self.commands(obs)
        self.memo_key = (con.key, obs.faces_key, obs.key, margin)
        if memo is not None and memo.key == self.memo_key:
            self.buf["xq"].numpy()[:] = memo.xq
            self.buf["dq"].numpy()[:] = memo.dq
            self.update(first=2)
        else:
            self.update(first=1)

    def remember(self, memo: RefineMemo) -> None:
        """Keep the last exact distance queries (points and signed distances) in ``memo`` for a later call."""
        memo.key = self.memo_key
        memo.xq = self.buf["xq"].numpy().copy()
        memo.dq = self.buf["dq"].numpy().copy()

    def commands(self, obs: Obstacle) -> SimpleNamespace:
        """The recorded launches of the kernels on this garment's buffers (cached on the garment)."""
        con, buf, margin = self.con, self.buf, self.margin
        if con.commands is not None and con.commands[0] is obs and con.commands[1] == margin:
            return con.commands[2]
        wp, k = quiet_warp(), _kernels()
        floor = SAMPLE_CLEARANCE * margin  # the least signed distance of an edge sample of a crossing edge
        keep = floor + 0.5 * BAND  # samples of a crossing edge below this get half-spaces

        def record(kernel: Any, dim: Any, inputs: list) -> Any:
            return wp.launch(kernel, dim=dim, inputs=inputs, device=_DEVICE, record_cmd=True)

        n, ne = buf["x"].shape[0], buf["hit"].shape[0]
        x, d = buf["x"], buf["d"]
        vertex = [x, con.wp_mobile, margin + BAND, 1, buf["xq"], buf["dq"], buf["cq"], buf["nq"], d, buf["v_active"]]
        vertex += [buf["xs"], buf["fresh"]]
        listed = [buf["s_list"], buf["s_count"]]
        samples = [
            x,
            d,
            con.wp_mobile,
            con.wp_moving,
            con.wp_ts,
            keep,
            floor,
            buf["hit"],
            buf["s_close"],
            buf["s_normal"],
            *listed,
            buf["fresh"],
            buf["s_depth"],
            buf["s_deep_normal"],
            buf["s_deep_t"],
            buf["s_clearance"],
        ]
        sweeps = [0, RELAXATION, CHEBYSHEV_RHO, margin, buf["s_clearance"], x, con.wp_mobile, con.wp_stretch]
        sweeps += [con.wp_limit]
        sweeps += [con.wp_moving, con.wp_ts, *listed, buf["s_close"], buf["s_normal"], buf["v_active"]]
        sweeps += [buf[name] for name in ("cq", "nq", "d", "acc", "wsum", "current", "previous", "chebyshev")]
        cmd = SimpleNamespace(
            vertex=record(k.vertex_state, n, [obs.surface, *vertex]),
            samples=record(k.sample_state, ne, [obs.surface, *samples]) if ne else None,
            violations=record(
                k.violations,
                1,
                [x, con.wp_stretch, con.wp_rest, con.wp_limit, con.wp_mobile, d, buf["hit"], margin, 1, buf["flag"]],
            ),
            torn=record(
                k.torn_edges, 1, [x, con.wp_stretch, con.wp_rest, con.wp_limit, TORN_STRETCH, 1.0, buf["torn"]]
            ),
            sweeps=record(k.sweeps, 1, sweeps),
            fallback=record(
                k.fallback_blend,
                1,
                [x, d, con.wp_moving, buf["hit"], buf["s_depth"], buf["s_deep_normal"], buf["s_deep_t"], buf["nq"]]
                + [con.wp_stretch, con.wp_rest, con.wp_edges]
                + [con.wp_closed_inv_degree, con.wp_mobile, buf["prior"], buf["w"], buf["ring"], buf["previous"]]
                + [buf["flag"], FALLBACK_BORDER],
            ),
            diffuse=record(
                k.diffuse, 1, [0.0, x, buf["x0"], con.wp_edges, con.wp_mobile, con.wp_inv_degree, buf["ring3"]]
            ),
        )
        con.commands = (obs, margin, cmd)
        return cmd

    def update(self, first: int = 0) -> None:
        """Re-query the vertices that may have come near the surface, then the edges that may cross it (``first``:
        see the ``vertex_state`` kernel)."""
        self.cmd.vertex.set_param_by_name("first", int(first))
        self.cmd.vertex.launch()
        self.buf["s_count"].zero_()
        if self.cmd.samples is not None:
            self.cmd.samples.launch()

    def violated(self, stretch: bool = True) -> bool:
        """Whether an edge is over its limit (``stretch`` only), a mobile vertex nearer than the margin or an edge
        meets the surface."""
        self.cmd.violations.set_param_by_name("stretch", int(stretch))
        self.cmd.violations.launch()
        return bool(self.buf["flag"].numpy()[0])

    def sweep(self, iterations: int) -> None:
        self.cmd.sweeps.set_param_by_name("iterations", int(iterations))
        self.cmd.sweeps.launch()

    def diffuse(self, x0: np.ndarray, alpha: float) -> None:
        """(d): blend each mobile vertex's correction from ``x0`` with its one-ring's mean one, weight ``alpha``."""
        self.buf["x0"].numpy()[:] = x0
        self.cmd.diffuse.set_param_by_name("alpha", float(alpha))
        self.cmd.diffuse.launch()

    def fall_back(self, prior: np.ndarray, border: float = FALLBACK_BORDER) -> np.ndarray | None:
        """Blend the mobile vertices that are deep inside the obstacle, on an edge deep through it (deeper than
        ``FALLBACK_DEPTH``) or on a torn edge towards ``prior``, the fade widened to keep edges within ``border`` x
        their rest length (the ``fallback_blend`` kernel; :func:`fallback_weight` is its reference once each vertex's
        ``d`` is lowered to the depth of the deepest edge through the body at it); returns the blended garment, or
        None (nothing moved)."""
        self.buf["prior"].numpy()[:] = prior
        self.cmd.fallback.set_param_by_name("border", float(border))
        self.cmd.fallback.launch()
        if not self.buf["flag"].numpy()[1]:
            return None
        self.update()
        return self.x.copy()

    def torn(self, scale: float = 1.0) -> bool:
        """Whether an edge with a free end is longer than ``scale`` x ``TORN_STRETCH`` x its rest length (and x its own
        limit)."""
        self.cmd.torn.set_param_by_name("ratio", float(TORN_STRETCH))
        self.cmd.torn.set_param_by_name("scale", float(scale))
        self.cmd.torn.launch()
        return bool(self.buf["torn"].numpy()[0])

    def clamp_torn(self) -> None:
        """Shorten every edge with a free end longer than (1 - ``_STRETCH_TOL`` / 2) x ``TORN_STRETCH`` x its rest
        length (and its own limit) to just within it: averaged Jacobi projections of those edges (weighted by the
        corrections' lengths, as in the sweeps), after ``CLAMP_PLAIN`` plain passes with a Chebyshev step
        (``CLAMP_RHO``; no momentum fade: contacts play no part here), until every edge is within, or the total excess
        has not fallen for ``CLAMP_PATIENCE`` passes (an edge no move can shorten: a free vertex between pins pulled
        apart), at most ``CLAMP_PASSES``; keeps the iterate of least total excess. Stretch wins over contact past the
        simulator's rejection bound, by as much as it needs (millimetres on the test split's torn skirt)."""
        if not self.torn(1.0 - 0.5 * _STRETCH_TOL):
            return
        x, con = self.x, self.con
        e, mob, n = con.stretch_edges, con.mobile, len(self.x)
        bound = np.maximum(TORN_STRETCH * con.rest, con.limit)
        target = (1.0 - _STRETCH_TOL) * bound  # a little inside, so that the passes end with every edge within
        within = (1.0 - 0.5 * _STRETCH_TOL) * bound
        previous, kept, best, since, w = x.copy(), x.copy(), np.inf, 0, 1.0
        length = np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)
        moving = np.zeros(n, dtype=bool)  # vertices a pass has stepped: they move on (the Chebyshev momentum)
        for k in range(CLAMP_PASSES + 1):
            if k:  # only edges at a moving vertex change length: the torn region, not the whole garment
                touched = np.flatnonzero(moving[e[:, 0]] | moving[e[:, 1]])
                length[touched] = np.linalg.norm(x[e[touched, 1]] - x[e[touched, 0]], axis=1)
            excess = float(np.maximum(length / within - 1.0, 0.0).sum())  # 0 exactly when every edge is within
            if excess < best:
                best, kept, since = excess, x.copy(), 0
            else:
                since += 1
            if excess == 0.0 or since >= CLAMP_PATIENCE or k == CLAMP_PASSES:
                break
            over = length > target
            eo, lo, to = e[over], length[over], target[over]
            moving[eo.ravel()] = True
            size = (lo - to) / (mob[eo[:, 0]] + mob[eo[:, 1]])  # each mobile end's share of the shortening
            corr = (size / lo)[:, None] * (x[eo[:, 1]] - x[eo[:, 0]])
            step, total = np.zeros((n, 3)), np.zeros(n)
            for end, sign in ((0, 1.0), (1, -1.0)):
                weight = mob[eo[:, end]] * size
                for c in range(3):
                    step[:, c] += np.bincount(eo[:, end], weights=sign * weight * corr[:, c], minlength=n)
                total += np.bincount(eo[:, end], weights=weight, minlength=n)
            step /= np.where(total > 0.0, total, 1.0)[:, None]
            j = k - CLAMP_PLAIN + 1  # plain passes first (a slightly torn drape closes in them, moved least)
            w = 1.0 if j <= 0 else 2.0 / (2.0 - CLAMP_RHO**2) if j == 1 else 4.0 / (4.0 - CLAMP_RHO**2 * w)
            x_new = previous + w * (x + step - previous)
            previous = x.copy()
            x[:] = x_new
        x[:] = kept

    def project_contacts(self) -> bool:
        """Move every mobile vertex closer than the margin to it along its normal; False if there was none."""
        d = self.buf["d"].numpy()
        bad = (d < self.margin - _DIST_TOL) & (self.con.mobile > 0)
        if not bad.any():
            return False
        self.buf["x"].numpy()[bad] += (self.margin - d[bad])[:, None] * self.buf["nq"].numpy()[bad]
        return True

    @property
    def x(self) -> np.ndarray:
        return self.buf["x"].numpy()


def fallback_side(normal: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """(M,) side factor in [0, 1] of points whose closest surface points have outward unit ``normal`` (M, 3) and whose
    fallback is ``shift`` (M, 3) away: smoothstep(-cos / ``FALLBACK_SIDE``) of the cosine between them (1: the
    fallback lies behind the push-out, 0: not behind it)."""
    shift = np.asarray(shift, np.float64)
    cos = np.einsum("ij,ij->i", normal, shift) / np.sqrt(np.einsum("ij,ij->i", shift, shift) + _SIDE_EPS2)
    return smoothstep(-cos / FALLBACK_SIDE)


def fallback_seed(
    depth: np.ndarray, normal: np.ndarray, shift: np.ndarray, depth_from: float = FALLBACK_DEPTH
) -> np.ndarray:
    """(M,) fallback seed of points at signed distance ``depth`` (M,) from the obstacle (negative inside): 0 above
    -``depth_from``, 1 below -(``depth_from`` + ``FALLBACK_RAMP``), a smoothstep between, times their
    :func:`fallback_side`. A vertex's seed is its own; an edge through the obstacle seeds both its ends with its
    deepest sample's (that sample's prediction-to-fallback shift interpolated from the ends')."""
    return smoothstep((-np.asarray(depth, np.float64) - depth_from) / FALLBACK_RAMP) * fallback_side(normal, shift)


def fallback_weight(
    seed: np.ndarray,
    edges: np.ndarray,
    closed_inv_degree: np.ndarray,
    stretch_edges: np.ndarray | None = None,
    rest: np.ndarray | None = None,
    x: np.ndarray | None = None,
    prior: np.ndarray | None = None,
    border: float = FALLBACK_BORDER,
) -> np.ndarray:
    """Weight (N,) in [0, 1] of the fallback at each vertex from its ``seed`` (N,) (:func:`fallback_seed`); given the
    garment ``x`` (N, 3), at least smoothstep((ratio - ``FALLBACK_STRETCH``) / ``FALLBACK_STRETCH_RAMP``) at both ends
    of each of ``stretch_edges`` (E, 2) with its length ratio to ``rest`` (E,); then ``FALLBACK_PASSES`` times
    w = max(w, mean of w over the vertex and its neighbours along ``edges``), so that a patch moves as a whole and its
    border fades over a few rings; then, given the ``prior`` (N, 3) it is blended towards, at most
    ``FALLBACK_WIDEN_PASSES`` Jacobi passes that raise the lower weight of each stretch edge whose blended length
    x + w (prior - x) would exceed ``border`` x its rest length and both its lengths in ``x`` and ``prior``
    to the least weight that keeps it there, until nothing changes. Continuous in the inputs; 0 where nothing is
    deep or torn."""
    w = np.array(seed, dtype=np.float64)
    edged = x is not None and stretch_edges is not None and len(stretch_edges) > 0
    if edged:
        a, b = stretch_edges[:, 0], stretch_edges[:, 1]
        ratio = np.linalg.norm(x[b] - x[a], axis=1) / rest
        wt = smoothstep((ratio - FALLBACK_STRETCH) / FALLBACK_STRETCH_RAMP)
        if prior is not None:  # only where the fallback's own edge is less torn
            own = np.linalg.norm(prior[b] - prior[a], axis=1) / rest
            wt = wt * smoothstep((ratio - own) / FALLBACK_STRETCH_RAMP)
        np.maximum.at(w, a, wt)
        np.maximum.at(w, b, wt)
    if not w.any() or len(edges) == 0:
        return w
    n = len(w)
    for _ in range(FALLBACK_PASSES):
        ring = np.bincount(edges[:, 0], weights=w[edges[:, 1]], minlength=n)
        ring += np.bincount(edges[:, 1], weights=w[edges[:, 0]], minlength=n)
        w = np.maximum(w, (w + ring) * closed_inv_degree)
    if prior is None or not edged:
        return w
    shift = prior - x
    bound = np.maximum(border * rest, np.linalg.norm(x[b] - x[a], axis=1))
    bound = np.maximum(bound, np.linalg.norm(prior[b] - prior[a], axis=1))
    for _ in range(FALLBACK_WIDEN_PASSES):
        swap = w[b] > w[a]
        hi, lo = np.where(swap, b, a), np.where(swap, a, b)
        c = x[hi] + w[hi, None] * shift[hi] - x[lo]
        s = shift[lo]
        over = (w[lo] < w[hi]) & (np.linalg.norm(c - w[lo, None] * s, axis=1) > bound * (1.0 + _STRETCH_TOL))
        if not over.any():
            break
        c, s, bd, lo, w_lo, w_hi = c[over], s[over], bound[over], lo[over], w[lo[over]], w[hi[over]]
        qa, qb = np.einsum("ij,ij->i", s, s), np.einsum("ij,ij->i", c, s)
        disc = np.maximum(qb * qb - qa * (np.einsum("ij,ij->i", c, c) - bd * bd), 0.0)
        root = np.where(qa > 0, (qb - np.sqrt(disc)) / np.where(qa > 0, qa, 1.0), w_lo)
        wider = w.copy()
        np.maximum.at(wider, lo, np.clip(root, w_lo, w_hi))
        if not (wider > w).any():
            break
        w = wider
    return w


def _rounds(state: _State, iterations: int, x0: np.ndarray | None = None, alpha: float = 0.0) -> None:
    """Rounds of ``iterations`` sweeps, each ending with fresh queries, until nothing is violated, at most
    ``MAX_ROUNDS``; the first round diffuses the correction from ``x0`` with weight ``alpha`` (the bending term)."""
    for rnd in range(MAX_ROUNDS):
        state.sweep(iterations)
        if rnd == 0 and alpha > 0 and x0 is not None and len(state.con.edges):
            state.diffuse(x0, alpha)
        state.update()
        if not state.violated():
            return


def refine(
    garment: np.ndarray,
    template: np.ndarray,
    faces: np.ndarray,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    fabric: str | Fabric = "cotton",
    pinned: np.ndarray | None = None,
    iterations: int = 10,
    margin: float = 0.002,
    max_stretch: float | None = None,
    fallback: np.ndarray | None = None,
    memo: RefineMemo | None = None,
) -> np.ndarray:
    """Project a predicted garment onto the stretch-limit and no-penetration constraints (see module doc).

    ``garment`` (N, 3) the prediction on the target body, ``template`` (N, 3) its rest shape (edge rest
    lengths), ``faces`` (F, 3); ``body_vertices`` / ``body_faces`` any closed, outward-oriented
    triangle mesh as the obstacle; ``pinned`` (N,) bool vertices that never move; ``fallback`` (N, 3), optional,
    a garment on the right side of the obstacle's parts (the skinning prior): mobile vertices more than
    ``FALLBACK_DEPTH`` inside the obstacle (themselves or on an edge through it) or on an edge torn over
    ``FALLBACK_STRETCH`` x its rest length are first blended towards it (:func:`fallback_weight`, spread over the
    mesh so that a patch moves as a whole), where pushing them out to the nearest surface would wrap them
    around the wrong side of a limb. ``memo``, optional (:class:`RefineMemo`): filled with this call's last distance
    queries; given to a later call on the same garment, body pose and margin (a second pass over the same frame), it
    spares that call the query of every vertex, with the same result. Returns (N, 3) in
    the garment's float dtype (float64 for integer input); a garment that violates nothing is returned
    unchanged.
    """
    x_in = _points(garment, "garment")
    n = len(x_in)
    tpl = _points(template, "template", n)
    f = _faces(faces, "faces", n)
    fb = None if fallback is None else np.asarray(_points(fallback, "fallback", n), dtype=np.float64)
    bv = _points(body_vertices, "body_vertices")
    bf = _faces(body_faces, "body_faces", len(bv))
    if len(bf) == 0:
        raise ValueError("body_faces is empty: the obstacle needs at least one triangle")
    fab = get_fabric(fabric)
    if pinned is None:
        pin = np.zeros(n, dtype=bool)
    else:
        pin = np.asarray(pinned)
        if pin.shape != (n,) or pin.dtype != bool:
            raise ValueError(f"pinned must be a bool array of shape ({n},), got {pin.dtype} {pin.shape}")
    if memo is not None and not isinstance(memo, RefineMemo):
        raise ValueError(f"memo must be a garsim.refine.RefineMemo or None, got {type(memo).__name__}")
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    if not isinstance(margin, (int, float, np.floating)) or not np.isfinite(margin) or margin < 0:
        raise ValueError(f"margin must be a finite number >= 0 metres, got {margin!r}")
    if max_stretch is None:
        limit = default_max_stretch(fab)
    else:
        if not isinstance(max_stretch, (int, float, np.floating)) or not np.isfinite(max_stretch) or max_stretch < 1:
            raise ValueError(f"max_stretch must be a finite number >= 1, got {max_stretch!r}")
        limit = float(max_stretch)
    out_dtype = x_in.dtype if np.issubdtype(x_in.dtype, np.floating) else np.float64
    if n == 0:
        return np.array(x_in, dtype=out_dtype)

    # in a frame centred on the obstacle: its BVH is float32, whose rounding 10 m from the origin (~1 um) moved a
    # tangled drape by ~1 mm; centred, a moved scene is refined alike
    origin = np.asarray(bv, dtype=np.float64).mean(axis=0)
    x0 = np.asarray(x_in, dtype=np.float64) - origin
    state = _State(x0, obstacle(bv - origin, bf), _constraints(tpl, f, pin, limit), float(margin), memo)
    if not state.violated():
        if memo is not None:
            state.remember(memo)
        return np.array(x_in, dtype=out_dtype)

    if fb is not None:
        blended = state.fall_back(fb - origin)
        if blended is not None:
            x0 = blended
    _rounds(state, iterations, x0, smoothing_weight(fab, state.con.mean_edge))
    # final contact projection (contact wins over stretch), re-checked with exact distances, then the
    # clamp of edges still torn past the simulator's bound (stretch wins there)
    for _ in range(4):
        if not state.project_contacts():
            break
        state.update()
    state.clamp_torn()
    if memo is not None:
        state.remember(memo)
    out = state.x + origin
    out[pin] = x_in[pin]  # exactly where they were (the sweeps never move them; the frame's round trip would)
    return out.astype(out_dtype)
