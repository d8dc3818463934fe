"""Ground-truth cloth simulation with Newton's VBD solver (CPU or CUDA): settle, move the body, reject.

``settle`` drapes a template garment on the canonical body under gravity (pinned vertices held)
until the garment's mean speed falls below a threshold; this gives the paper's template G.
``simulate_poses`` moves the body through a chain of target poses (the body's collision mesh is
re-fitted every substep, body positions interpolated between frames), drives the pinned vertices
along their LBS-prior targets, and at each target holds the pose until the cloth settles; several
fabric copies of one template run in one model (paired-fabric groups).
``check_result`` raises ``SimulationRejected`` for exploded or penetrating results, with a named reason.

Only ``garsim.physics`` imports Newton (an optional extra); inference code never does.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any, TypeVar

import numpy as np

from garsim.garments.fabrics import Fabric, edge_bending_stiffness, get_fabric
from garsim.garments.garment import Garment
from garsim.geometry.io import validate_mesh
from garsim.geometry.mesh import face_normals, face_pairs, unique_edges
from garsim.geometry.proximity import nearest_vertices

log = logging.getLogger(__name__)
_T = TypeVar("_T")

REJECT_NON_FINITE = "non_finite"
REJECT_OVERSTRETCHED = "overstretched"
REJECT_PENETRATION = "penetration"


CONTACTS_PER_PARTICLE = 32
"""Body-cloth contact records the tight contact buffer holds per particle (at least ``MIN_CONTACT_CAPACITY``).
Newton sizes the buffer for every candidate pair (~200,000 records for a 370-vertex t-shirt, of which about 2,000
are ever used; at most 11 per particle were seen, in a paired dress), and several of its kernels run over the
whole buffer every iteration, skipping the empty records: a tight buffer skips fewer and gives the same result.
A run that overflows it is run again with Newton's full-size buffer (``ContactOverflow``)."""
MIN_CONTACT_CAPACITY = 4096


class ContactOverflow(RuntimeError):
    """A collision pass needed more contact records than the tight buffer holds (its result is incomplete)."""


class SimulationRejected(RuntimeError):
    """A simulation result that must not be stored; ``reason`` is one of the ``REJECT_*`` names."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass
class SimConfig:
    """Time stepping, settling and contact parameters of the Newton VBD simulation."""

    fps: float = 30.0  # stored frames per simulated second
    # The solver budget (substeps x iterations per frame) sets the ground truth, not only its cost: a settled drape
    # is a different rest state at every budget, with or without a 10x stricter settling test
    # (docs/studies/solver_convergence.md). 10 x 4 (the v1-v3 data) left edges stretched +0.7% (p99 +5-9%) and
    # drapes 10-42 mm (mean per vertex) from 80 x 8's. At 160 iterations per frame, smaller steps beat more
    # iterations: 40 x 4 lands 6-18 mm from 80 x 8 (20 x 8: 10-22, 10 x 16: 14-27) at about 20 x 8's CPU per settle,
    # ~2x 10 x 4's per sample (fewer frames to settle); 40 x 8 (3-12 mm) costs another ~1.5-2x. 80 x 8 itself is not
    # the limit for skirts and dresses (their distance to the body still grows 4-7 mm from 40 x 8 to 80 x 8).
    substeps: int = 40  # VBD steps per frame
    iterations: int = 4  # VBD iterations per step
    damping: float = 0.993614  # velocity factor per substep: 0.9747 per 1/300 s before, the same drag per second
    settle_damping: float | None = None  # damping while settling (template, holds); None = ``damping``
    settle_iterations: int | None = None  # VBD iterations while settling; None = ``iterations``
    settle_speed: float = 0.02  # m/s: settled when the mean free-vertex speed stays below this
    settle_patience: int = 3  # consecutive frames below the threshold
    min_settle_frames: int = 8
    max_settle_frames: int = 120
    max_hold_frames: int = 60  # settling cap after each motion, at the target pose
    gravity: float = -9.81
    soft_contact_gap: float = (
        0.006  # m: contact detection gap (Anny's ~6 mm triangles: 0.01 gave ~40 contacts per particle, 2x the cost)
    )
    collide_every: int = 2  # body-cloth collision detection every k-th substep (contacts kept in between)
    contact_ke: float = 1.0e4  # body-cloth contact stiffness (N/m)
    contact_kd: float = 1.0e-2  # body-cloth contact damping
    flat_rest_angles: bool = True  # fabric cut flat: zero rest dihedral angles
    crop_margin: float | None = 0.06  # m: collide only with body faces this close to the garment's box (at any frame)
    abort_stretch: float = 3.0  # stop early when any edge exceeds this multiple of its rest length
    device: str = "auto"  # warp device: "auto" = the first CUDA device when present, else "cpu"
    # Capture each kind of substep once as a Warp graph and replay it (in C++ on the CPU, a CUDA graph on a GPU):
    # the same kernels with the same arguments, bit-identical to launching them one by one, without ~100 us of
    # Python per launch (docs/studies/generator_profile.md). How frames are launched, not what they compute.
    graphs: bool = True
    # Size the body-cloth contact buffer for CONTACTS_PER_PARTICLE records per particle, not every candidate pair:
    # the same result with fewer empty records skipped (a run that overflows it runs again with the full buffer).
    tight_contacts: bool = True

    def __post_init__(self) -> None:
        if self.fps <= 0 or self.substeps < 1 or self.iterations < 1:
            raise ValueError(
                f"fps > 0, substeps >= 1 and iterations >= 1 required, got {self.fps}, "
                f"{self.substeps}, {self.iterations}"
            )
        for name in ("damping", "settle_damping"):
            value = getattr(self, name)
            if value is not None and not (0.0 < value <= 1.0):
                raise ValueError(f"{name} is a per-substep velocity factor in (0, 1], got {value}")
        if self.collide_every < 1:
            raise ValueError(f"collide_every >= 1 required, got {self.collide_every}")
        if self.settle_iterations is not None and self.settle_iterations < 1:
            raise ValueError(f"settle_iterations >= 1 required, got {self.settle_iterations}")
        if self.max_settle_frames < 1 or self.min_settle_frames < 0 or self.settle_patience < 1:
            raise ValueError("max_settle_frames >= 1, min_settle_frames >= 0, settle_patience >= 1 required")

    @property
    def frame_dt(self) -> float:
        return 1.0 / self.fps

    @property
    def dt(self) -> float:
        return 1.0 / (self.fps * self.substeps)


def _check_mesh(name: str, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``geometry.io.validate_mesh`` as the solver wants it: contiguous float32 vertices, int32 faces."""
    v, f = validate_mesh(vertices, faces, name)
    return np.ascontiguousarray(v, dtype=np.float32), np.ascontiguousarray(f, dtype=np.int32)


def crop_body(
    body_frames: np.ndarray, body_faces: np.ndarray, boxes: np.ndarray, margin: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """Keep body faces with a vertex inside ``boxes`` (T, 2, 3) grown by ``margin`` at any frame.

    Returns (vertex indices kept, faces re-indexed into them). Far faces can never touch the
    garment, and collision cost grows with the body mesh; ``margin=None`` keeps everything.
    """
    body_faces = np.asarray(body_faces, dtype=np.int64)
    nv = body_frames.shape[1]
    if margin is None:
        return np.arange(nv), body_faces
    lo = boxes[:, 0][:, None] - margin
    hi = boxes[:, 1][:, None] + margin
    near = np.all((body_frames >= lo) & (body_frames <= hi), axis=2).any(axis=0)  # (Vb,)
    keep_face = near[body_faces].any(axis=1)
    if not keep_face.any():
        keep_face[:1] = True  # a contact mesh needs at least one triangle
    used = np.unique(body_faces[keep_face])
    remap = np.full(nv, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return used, remap[body_faces[keep_face]]


class ClothScene:
    """One Newton model: C copies of one garment (one per fabric) as VBD cloth, the body as a static,
    re-fittable triangle mesh.

    The copies occupy the same space but never touch (particle self-contact is off in VBD cloth
    here), so a paired-fabric group (one template, four fabrics, one body motion) is one launch.
    Each copy's hinges get their own stiffness from its fabric's bending rigidity
    (:func:`edge_bending_stiffness`), each particle its own mass from the fabric's areal density.
    Friction is one value per model (Newton's soft contact): the copies' mean. Each kind of substep is
    captured once as a Warp graph and replayed (``SimConfig.graphs``), and the contact buffer holds
    ``CONTACTS_PER_PARTICLE`` records per particle (``SimConfig.tight_contacts``): both bit-identical to
    launching every kernel with Newton's full-size buffer.
    """

    def __init__(
        self,
        garment_vertices: np.ndarray,
        garment_faces: np.ndarray,
        pinned: np.ndarray,
        body_vertices: np.ndarray,
        body_faces: np.ndarray,
        fabrics: Sequence[str | Fabric],
        config: SimConfig,
    ) -> None:
        from garsim.geometry.inside import quiet_warp

        wp = quiet_warp()
        import newton

        self.config = config
        fabrics = [get_fabric(f) for f in fabrics]
        if not fabrics:
            raise ValueError("at least one fabric is needed")
        gv, gf = _check_mesh("garment", garment_vertices, garment_faces)
        bv, bf = _check_mesh("body", body_vertices, body_faces)
        pinned = np.asarray(pinned, dtype=bool)
        if pinned.shape != (len(gv),):
            raise ValueError(f"pinned mask has shape {pinned.shape}, expected ({len(gv)},)")
        n = len(gv)
        self.copies = len(fabrics)
        self.num_particles = n
        self.pinned_idx = np.flatnonzero(pinned)
        self.all_pinned = (self.pinned_idx[None] + n * np.arange(self.copies)[:, None]).ravel()
        self.free = ~pinned
        if not self.free.any():
            raise ValueError("every garment vertex is pinned: nothing to simulate")
        friction = float(np.mean([f.friction for f in fabrics]))

        builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=(0.0, 0.0, config.gravity))
        shape_cfg = builder.default_shape_cfg.copy()
        shape_cfg.ke = config.contact_ke
        shape_cfg.kd = config.contact_kd
        shape_cfg.mu = friction
        self.body_mesh = newton.Mesh(bv, bf.ravel(), compute_inertia=False, is_solid=True)
        builder.add_shape_mesh(body=-1, mesh=self.body_mesh, cfg=shape_cfg)
        edge_ranges = []
        for fabric in fabrics:
            start = builder.edge_count
            builder.add_cloth_mesh(
                pos=wp.vec3(0.0, 0.0, 0.0),
                rot=wp.quat_identity(),
                scale=1.0,
                vel=wp.vec3(0.0, 0.0, 0.0),
                vertices=gv,
                indices=gf.ravel(),
                density=fabric.density,
                tri_ke=fabric.stretch,
                tri_ka=fabric.stretch,
                tri_kd=fabric.stretch_damping,
                edge_ke=1.0,  # replaced per hinge below
                edge_kd=0.0,
                particle_radius=fabric.thickness,
            )
            edge_ranges.append((start, builder.edge_count))
        builder.color(include_bending=True)
        device = config.device if config.device != "auto" else ("cuda:0" if wp.is_cuda_available() else "cpu")
        model = builder.finalize(device=device)
        if config.flat_rest_angles:
            model.edge_rest_angle.zero_()
        hinges = model.edge_indices.numpy()
        rest_q = model.particle_q.numpy()
        props = model.edge_bending_properties.numpy()
        for fabric, (a, b) in zip(fabrics, edge_ranges):
            ke = edge_bending_stiffness(fabric.bending, rest_q, hinges[a:b])
            props[a:b, 0] = ke
            props[a:b, 1] = ke * fabric.bending_damping
        model.edge_bending_properties.assign(props.astype(np.float32))
        flags = model.particle_flags.numpy()
        clear = ~np.array(int(newton.ParticleFlags.ACTIVE), dtype=flags.dtype)
        flags[self.all_pinned] &= clear
        model.particle_flags.assign(flags)
        model.soft_contact_ke = config.contact_ke
        model.soft_contact_kd = config.contact_kd
        model.soft_contact_mu = friction
        self.model = model
        # at least one record per particle and 512 (the worker count of VBD's contact scatter on a CPU), so that a
        # tight buffer changes no launch but the number of empty records skipped
        self.contact_capacity = (
            max(MIN_CONTACT_CAPACITY, CONTACTS_PER_PARTICLE * len(rest_q)) if config.tight_contacts else None
        )
        self.pipeline = newton.CollisionPipeline(
            model,
            soft_contact_max=self.contact_capacity,
            soft_contact_gap=config.soft_contact_gap,
            enable_rigid_soft_full_surface_contact=True,
        )
        self.contacts = self.pipeline.contacts()
        self._most_contacts = wp.zeros(1, dtype=wp.int32, device=device)  # the largest count of any pass so far
        self.solver = newton.solvers.SolverVBD(model, iterations=config.iterations)
        self.state_0 = model.state()
        self.state_1 = model.state()
        self.control = model.control()
        self.body_points = self.body_mesh.mesh.points
        self.damping = config.damping
        self.substeps_done = 0
        self._wp = wp
        self._pin_targets = wp.zeros(max(len(self.pinned_idx), 1), dtype=wp.vec3, device=device)
        self._pin_index = wp.array(self.all_pinned.astype(np.int32), dtype=wp.int32, device=device)
        self._graphs: dict[tuple[Any, ...], tuple[Any, Any, Any]] = {}

    def settling(self, on: bool) -> None:
        """Switch between the motion settings and the settling ones (``settle_iterations``, ``settle_damping``)."""
        cfg = self.config
        iterations, damping = (cfg.settle_iterations, cfg.settle_damping) if on else (None, None)
        self.solver.iterations = cfg.iterations if iterations is None else iterations
        self.damping = cfg.damping if damping is None else damping

    # -- state access (numpy round trips: views on CPU, copies on a CUDA device) -------------------
    def positions(self) -> np.ndarray:
        """(C, N, 3) positions of every copy; raises ``ContactOverflow`` if any collision pass so far overflowed
        the tight contact buffer."""
        if self.contact_capacity is not None:
            most = int(self._most_contacts.numpy()[0])
            if most > self.contact_capacity:
                raise ContactOverflow(f"a collision pass needed over {self.contact_capacity} contact records")
        return self.state_0.particle_q.numpy().reshape(self.copies, self.num_particles, 3).copy()

    def set_body(self, vertices: np.ndarray) -> None:
        """Move the body to ``vertices`` (Vb, 3) and refit its collision tree (on the host: Warp's CPU graphs do
        not record a mesh refit, so it stays outside them)."""
        self.body_points.assign(np.ascontiguousarray(vertices, dtype=np.float32))
        self.body_mesh.mesh.refit()

    def _launch_substep(self, place_pins: bool) -> None:
        """Launch one substep's operations (every one a Warp operation, so that they can be captured)."""
        from garsim.physics.scene_kernels import atomic_max_int, scale_vec3
        from garsim.physics.scene_kernels import place_pins as place_pins_kernel

        wp, cfg, device = self._wp, self.config, self.model.device
        if place_pins and len(self.all_pinned):
            q, qd = self.state_0.particle_q, self.state_0.particle_qd
            inputs = [self._pin_targets, self._pin_index, len(self.pinned_idx), q, qd]
            wp.launch(place_pins_kernel, len(self.all_pinned), inputs, device=device)
        self.state_0.clear_forces()
        if self.substeps_done % cfg.collide_every == 0:
            self.pipeline.collide(self.state_0, self.contacts)
            wp.launch(atomic_max_int, 1, [self.contacts.soft_contact_count, self._most_contacts], device=device)
        self.substeps_done += 1
        self.solver.step(self.state_0, self.state_1, self.control, self.contacts, cfg.dt)
        self.state_0, self.state_1 = self.state_1, self.state_0
        if self.damping < 1.0:
            qd = self.state_0.particle_qd
            wp.launch(scale_vec3, qd.shape[0], [qd, self.damping], device=device)

    def substep(self, body: np.ndarray | None = None, pins: np.ndarray | None = None) -> None:
        """One VBD substep; ``body`` (Vb, 3) moves the body first, ``pins`` (Np, 3) puts the pinned vertices of
        every copy there, at rest. With ``config.graphs`` each kind of substep is captured once and replayed."""
        if body is not None:
            self.set_body(body)
        if pins is not None and len(self.pinned_idx):
            self._pin_targets.assign(np.ascontiguousarray(pins, dtype=np.float32).reshape(len(self.pinned_idx), 3))
        if not self.config.graphs:
            self._launch_substep(pins is not None)
            return
        wp, device = self._wp, self.model.device
        # everything the recorded launches depend on: pin placement, the collision phase, the solver and damping
        # settings, and which state buffer holds the current state (every substep swaps them)
        key = (
            pins is not None,
            self.substeps_done % self.config.collide_every,
            self.solver.iterations,
            self.damping,
            id(self.state_0),
        )
        if key not in self._graphs:
            wp.capture_begin(device=device)  # records the launches, runs none of them
            try:
                self._launch_substep(pins is not None)
            finally:
                graph = wp.capture_end(device=device)
            self._graphs[key] = (graph, self.state_0, self.state_1)
            self.substeps_done -= 1  # the recording advanced the counter; the replay below does
        graph, self.state_0, self.state_1 = self._graphs[key]
        self.substeps_done += 1
        wp.capture_launch(graph)

    def frame(self) -> np.ndarray:
        """Step one frame (``substeps`` substeps, body and pins held) and return (C, N, 3) positions."""
        for _ in range(self.config.substeps):
            self.substep()
        return self.positions()


def _abort_reason(cur: np.ndarray, edges: np.ndarray, rest: np.ndarray, config: SimConfig) -> str | None:
    """Why a running simulation must stop now (non-finite or exploding), or None. ``cur`` is (..., N, 3)."""
    if not np.isfinite(cur).all():
        return REJECT_NON_FINITE
    if _edge_stretch(cur, edges, rest) > config.abort_stretch:
        return REJECT_OVERSTRETCHED
    return None


def _edge_stretch(vertices: np.ndarray, edges: np.ndarray, rest: np.ndarray) -> float:
    length = np.linalg.norm(vertices[..., edges[:, 1], :] - vertices[..., edges[:, 0], :], axis=-1)
    return float(np.max(length / np.maximum(rest, 1e-12)))


def mean_speed(prev: np.ndarray, cur: np.ndarray, free: np.ndarray, frame_dt: float) -> np.ndarray:
    """Mean speed (m/s) of the free vertices between two frames, per copy: (C, N, 3) -> (C,)."""
    return np.linalg.norm(cur[..., free, :] - prev[..., free, :], axis=-1).mean(axis=-1) / frame_dt


def _settle_loop(
    scene: ClothScene, max_frames: int, config: SimConfig, edges: np.ndarray, rest: np.ndarray
) -> tuple[np.ndarray, dict[str, Any]]:
    """Step whole frames until every copy's mean free-vertex speed stays below the threshold (or the cap).

    Returns the last (C, N, 3) positions and an info dict (frames, final speed per copy, settled, aborted).
    """
    scene.settling(True)
    prev = scene.positions()
    cur = prev
    calm = 0
    speed = np.full(scene.copies, np.nan)
    aborted = None
    frames = 0
    for _ in range(max_frames):
        cur = scene.frame()
        frames += 1
        aborted = _abort_reason(cur, edges, rest, config)
        if aborted:
            break
        speed = mean_speed(prev, cur, scene.free, config.frame_dt)
        prev = cur
        calm = calm + 1 if float(speed.max()) < config.settle_speed else 0
        if calm >= config.settle_patience and frames >= config.min_settle_frames:
            break
    scene.settling(False)
    settled = aborted is None and calm >= config.settle_patience
    return cur, {
        "frames": frames,
        "final_speed": [round(float(x), 5) for x in speed],
        "settled": settled,
        "aborted": aborted,
    }


def _full_contacts_on_overflow(run: Callable[[SimConfig], _T], config: SimConfig) -> _T:
    """``run(config)``; if a collision pass overflowed the tight contact buffer, run again from the start with
    Newton's full-size buffer: the result is that of a full-buffer run either way."""
    try:
        return run(config)
    except ContactOverflow as exc:
        log.info("%s: running again with Newton's full-size contact buffer", exc)
        return run(replace(config, tight_contacts=False))


def settle(
    garment: Garment,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    fabric: str | Fabric,
    config: SimConfig | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Drape ``garment`` on the (static) body under gravity until it comes to rest; pins held.

    Returns the settled vertices (N, 3) float32 and an info dict (frames, final mean speed in m/s,
    whether the speed threshold was reached, seconds, seconds per frame, an abort reason or None).
    """
    config = config or SimConfig()
    fabric = get_fabric(fabric)
    t0 = time.perf_counter()
    body_vertices = np.asarray(body_vertices, dtype=np.float32)
    box = np.stack([garment.vertices.min(0), garment.vertices.max(0)])[None]
    used, faces_c = crop_body(body_vertices[None], body_faces, box, config.crop_margin)
    edges = unique_edges(garment.faces)
    rest = np.linalg.norm(garment.vertices[edges[:, 1]] - garment.vertices[edges[:, 0]], axis=1)
    t1 = time.perf_counter()

    def run(cfg: SimConfig) -> tuple[np.ndarray, dict[str, Any]]:
        scene = ClothScene(garment.vertices, garment.faces, garment.pinned, body_vertices[used], faces_c, [fabric], cfg)
        return _settle_loop(scene, cfg.max_settle_frames, cfg, edges, rest)

    final, info = _full_contacts_on_overflow(run, config)
    t2 = time.perf_counter()
    info.update(
        fabric=fabric.name,
        build_seconds=t1 - t0,
        seconds=t2 - t0,
        seconds_per_frame=(t2 - t1) / max(info["frames"], 1),
        num_vertices=garment.num_vertices,
        config=asdict(config),
    )
    if not info["settled"]:
        log.info(
            "settle: %s stopped after %d frames at mean speed %s m/s (aborted=%s)",
            fabric.name,
            info["frames"],
            info["final_speed"],
            info["aborted"],
        )
    return final[0].astype(np.float32), info


def simulate_poses(
    template: np.ndarray,
    garment_faces: np.ndarray,
    pinned: np.ndarray,
    body_segments: Sequence[np.ndarray],
    body_faces: np.ndarray,
    pin_segments: Sequence[np.ndarray],
    fabrics: Sequence[str | Fabric],
    config: SimConfig | None = None,
) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """Move the body through a chain of target poses and settle at each; every fabric copy at once.

    ``body_segments[k]`` (T_k, Vb, 3) moves the body from the previous pose (frame 0 = the pose the
    garment rests on) to target k, ``pin_segments[k]`` (T_k, Np, 3) the pinned vertices with it.
    After each segment the body holds still until every copy's mean speed is below
    ``config.settle_speed`` (or ``max_hold_frames``). Returns the settled states, one (C, N, 3)
    array per target reached, and one info dict per target (motion and hold frames, final speed,
    settled, seconds, aborted). A segment that explodes ends the chain: its info has ``aborted``
    and no state.
    """
    config = config or SimConfig()
    fabrics = [get_fabric(f) for f in fabrics]
    pinned = np.asarray(pinned, dtype=bool)
    n_pin = int(pinned.sum())
    if len(body_segments) != len(pin_segments) or not body_segments:
        raise ValueError(
            f"need one pin segment per body segment (>= 1), got {len(body_segments)} and {len(pin_segments)}"
        )
    segs = [np.asarray(b, dtype=np.float32) for b in body_segments]
    pins = [np.asarray(p, dtype=np.float32) for p in pin_segments]
    for b, p in zip(segs, pins):
        if b.ndim != 3 or b.shape[2] != 3 or len(b) < 2:
            raise ValueError(f"each body segment must be (T >= 2, Vb, 3), got {b.shape}")
        if p.shape != (len(b), n_pin, 3):
            raise ValueError(f"pin segment must be (T={len(b)}, Np={n_pin}, 3), got {p.shape}")
        if not (np.isfinite(b).all() and np.isfinite(p).all()):
            raise ValueError("body / pin segments contain NaN/inf")
    t0 = time.perf_counter()
    gv = np.asarray(template, dtype=np.float32)
    all_body = np.concatenate(segs)
    all_pins = np.concatenate(pins)
    # the garment's box at every frame: the template's box carried along by the pinned vertices' mean motion
    shift = all_pins.mean(axis=1) - all_pins[:1].mean(axis=1) if n_pin else np.zeros((len(all_body), 3))
    boxes = np.stack([gv.min(0) + shift, gv.max(0) + shift], axis=1)
    used, faces_c = crop_body(all_body, body_faces, boxes, config.crop_margin)
    edges = unique_edges(garment_faces)
    rest = np.linalg.norm(gv[edges[:, 1]] - gv[edges[:, 0]], axis=1)
    s = config.substeps
    weights = (np.arange(1, s + 1, dtype=np.float32) / s)[:, None, None]

    def run(cfg: SimConfig) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
        scene = ClothScene(gv, garment_faces, pinned, segs[0][0, used], faces_c, fabrics, cfg)
        states: list[np.ndarray] = []
        infos: list[dict[str, Any]] = []
        for k, (body, pin) in enumerate(zip(segs, pins)):
            t1 = time.perf_counter()
            body = np.ascontiguousarray(body[:, used])
            aborted = None
            for j in range(1, len(body)):
                bodies = (1.0 - weights) * body[j - 1] + weights * body[j]
                ptarget = (1.0 - weights) * pin[j - 1] + weights * pin[j]
                for i in range(s):
                    scene.substep(bodies[i], ptarget[i])
                aborted = _abort_reason(scene.positions(), edges, rest, cfg)
                if aborted:
                    break
            info: dict[str, Any] = {"target": k, "motion_frames": len(body) - 1, "aborted": aborted}
            if aborted is None:
                state, hold = _settle_loop(scene, cfg.max_hold_frames, cfg, edges, rest)
                info.update(
                    hold_frames=hold["frames"],
                    final_speed=hold["final_speed"],
                    settled=hold["settled"],
                    aborted=hold["aborted"],
                )
            info["seconds"] = time.perf_counter() - t1
            infos.append(info)
            if info["aborted"]:
                log.info("simulate_poses: target %d aborted (%s)", k, info["aborted"])
                break
            states.append(state.astype(np.float32))
        return states, infos

    states, infos = _full_contacts_on_overflow(run, config)
    log.debug("simulate_poses: %d targets, %.1f s", len(states), time.perf_counter() - t0)
    return states, infos


def mean_body_distance(vertices: np.ndarray, body_vertices: np.ndarray) -> float:
    """Mean distance (m) from each garment vertex to its nearest body vertex."""
    return float(nearest_vertices(vertices, body_vertices)[1].mean())


def mean_fold_angle(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Mean dihedral fold angle (degrees) between adjacent faces: 0 for a flat sheet, larger when folded."""
    n = face_normals(np.asarray(vertices, dtype=np.float64), faces)
    fp = face_pairs(faces)
    cos = np.clip(np.einsum("ij,ij->i", n[fp[:, 0]], n[fp[:, 1]]), -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)).mean())


def inside_fraction(points: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray) -> float:
    """Fraction of ``points`` inside the body (warp winding-number test)."""
    from garsim.geometry.inside import InsideTester

    return float(np.mean(InsideTester(body_vertices, body_faces).inside(points)))


def check_result(
    frames: np.ndarray,
    garment_faces: np.ndarray,
    rest_edge_lengths: np.ndarray,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    max_stretch: float = 1.5,
    max_inside: float = 0.01,
    pinned: np.ndarray | None = None,
) -> None:
    """Accept simulated frames (T, N, 3) or raise ``SimulationRejected`` with a named reason.

    Rejects non-finite values, any edge longer than ``max_stretch`` x its rest length (edges in
    ``unique_edges(garment_faces)`` order), or more than ``max_inside`` of the garment vertices
    inside the body at any frame. ``body_vertices`` is (Vb, 3) for all frames or (T, Vb, 3).
    Edges between two ``pinned`` vertices are not simulated (they follow the skinned body, which
    stretches at the shoulders) and are left out of the stretch test. The reason is logged.
    """
    frames = np.asarray(frames)
    if frames.ndim == 2:
        frames = frames[None]
    edges = unique_edges(garment_faces)
    rest = np.asarray(rest_edge_lengths, dtype=np.float64)
    if rest.shape != (len(edges),):
        raise ValueError(f"rest_edge_lengths has shape {rest.shape}, expected ({len(edges)},) = unique_edges(faces)")
    body = np.asarray(body_vertices)
    if body.ndim == 3 and len(body) != len(frames):
        raise ValueError(f"body_vertices has {len(body)} frames, garment has {len(frames)}")

    def reject(reason: str, detail: str) -> None:
        log.warning("simulation rejected: %s: %s", reason, detail)
        raise SimulationRejected(reason, detail)

    finite = np.isfinite(frames).all(axis=(1, 2))
    if not finite.all():
        reject(REJECT_NON_FINITE, f"NaN/inf at frame {int(np.argmin(finite))}")
    d = frames[:, edges[:, 1]] - frames[:, edges[:, 0]]
    ratio = np.linalg.norm(d, axis=2) / np.maximum(rest, 1e-12)[None]
    if pinned is not None:
        pinned = np.asarray(pinned, dtype=bool)
        ratio[:, pinned[edges[:, 0]] & pinned[edges[:, 1]]] = 1.0
    worst = float(ratio.max())
    if worst > max_stretch:
        t, e = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        reject(
            REJECT_OVERSTRETCHED, f"edge {int(e)} at frame {int(t)} stretched {worst:.2f}x rest (limit {max_stretch}x)"
        )
    from garsim.geometry.inside import InsideTester

    tester = InsideTester(body[0] if body.ndim == 3 else body, body_faces)
    for t in range(len(frames)):
        if body.ndim == 3 and t > 0:
            tester.update(body[t])
        frac = float(np.mean(tester.inside(frames[t])))
        if frac > max_inside:
            reject(
                REJECT_PENETRATION,
                f"{100 * frac:.2f}% of garment vertices inside the body at frame {t} (limit {100 * max_inside:.1f}%)",
            )
