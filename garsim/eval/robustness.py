"""How a drape through the public API follows its input: the model issue's stability, equivariance and rest
checks as figures on any set of scenes (the committed fixture, a test split, the external check set).

Each check drapes a scene once as given and once changed, and reports the largest distance (mm) between the two
outputs at any garment vertex, after undoing the change:

- ``noise``: N(0, 1e-6 m) added to every vertex of the three input meshes (the largest change over ``noise_draws``
  independent draws: one draw samples a tangled drape's sensitivity, it does not bound it);
- ``obj_round_trip``: the three meshes written with ``save_mesh`` and draped from the files;
- ``face_permutation``: the garment's faces in a random order;
- ``vertex_permutation``: the garment's vertices in a random order (the output must follow the permutation);
- ``seam_split``: the garment written as GLB with its vertices split along a seam down its front (another tool's
  file: glTF stores one vertex per UV, so exporters split vertices at UV seams), draped from the file; every copy
  must land where its vertex does;
- ``turn_37``, ``turn_180``: the whole scene turned about the vertical (z) axis, the output turned back;
- ``shift_10m``: the whole scene moved 10 m horizontally, the output moved back;
- ``target_turn_90``, ``target_shift_2m``: the target body alone turned 90 deg about the vertical or moved 2 m (an
  avatar's root motion), the output turned or moved back.

``rest_mm`` is the mean displacement (mm) of the template draped onto its own canonical body (target = canonical):
a settled garment on a body that does not move should stay.
"""

from __future__ import annotations

import tempfile
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garsim.geometry.io import save_mesh

STABILITY_CHECKS: tuple[str, ...] = (
    "noise",
    "obj_round_trip",
    "face_permutation",
    "vertex_permutation",
    "seam_split",
)
SHIFT_M = np.array([10.0 / np.sqrt(2.0), -10.0 / np.sqrt(2.0), 0.0])  # 10 m, horizontal
MOVES: dict[str, tuple[float, np.ndarray | None, bool]] = {
    "turn_37": (37.0, None, True),
    "turn_180": (180.0, None, True),
    "shift_10m": (0.0, SHIFT_M, True),
    "target_turn_90": (90.0, None, False),
    "target_shift_2m": (0.0, np.array([1.2, -1.6, 0.05]), False),
}
"""Equivariance checks: (degrees about the vertical, shift in m, whether the whole scene moves); the ``target_``
ones move the target body alone (an avatar's root motion: it turns round or walks off), the garment must follow."""
EQUIVARIANCE_CHECKS: tuple[str, ...] = tuple(MOVES)
CHECKS: tuple[str, ...] = STABILITY_CHECKS + EQUIVARIANCE_CHECKS
NOISE_M = 1e-6

Mesh = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class Scene:
    """One drape as a user would ask for it: a template on its canonical body, a target body, a fabric."""

    name: str
    garment_type: str
    canonical: Mesh
    target: Mesh
    garment: Mesh
    fabric: Any  # a preset name or a dict of physical values (``GarSim.drape``'s ``fabric``)


def turn_about_vertical(vertices: np.ndarray, degrees: float, shift: np.ndarray | None = None) -> np.ndarray:
    """``vertices`` turned ``degrees`` about the z axis through the origin, then moved by ``shift``."""
    a = np.radians(degrees)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    out = np.asarray(vertices, dtype=np.float64) @ rot.T
    return out if shift is None else out + shift


def split_at_seam(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The garment as a file split along a seam stores it: the vertices shared by the front faces left and right of
    the garment's centre (x, y of its vertex mean; the body faces -y) get copies appended, which the right-hand faces
    use. Returns the split vertices, faces and each split vertex's original (N + S,)."""
    v, f = np.asarray(vertices), np.asarray(faces, dtype=np.int64)
    centre, centroids = v.mean(axis=0), v[f].mean(axis=1)
    front = centroids[:, 1] < centre[1]
    right = front & (centroids[:, 0] > centre[0])
    sides = np.zeros((2, len(v)), dtype=bool)
    sides[0, f[front & ~right].ravel()] = True
    sides[1, f[right].ravel()] = True
    seam = np.flatnonzero(sides.all(axis=0))
    renumber = np.arange(len(v))
    renumber[seam] = len(v) + np.arange(len(seam))
    split = f.copy()
    split[right] = renumber[f[right]]
    return np.concatenate([v, v[seam]]), split, np.concatenate([np.arange(len(v)), seam])


def _drape(sim: Any, canonical: Any, target: Any, garment: Any, fabric: Any) -> np.ndarray:
    return np.asarray(sim.drape(canonical, target, garment, fabric=fabric), dtype=np.float64)


def _max_mm(a: np.ndarray, b: np.ndarray) -> float:
    return 1000.0 * float(np.linalg.norm(a - b, axis=1).max())


def perturbation_changes(sim: Any, scene: Scene, seed: int = 0, noise_draws: int = 1) -> dict[str, float]:
    """The largest change (mm) of any output vertex under each of ``CHECKS``, against the scene draped as given
    (``noise``: over ``noise_draws`` draws)."""
    if isinstance(noise_draws, bool) or not isinstance(noise_draws, int) or noise_draws < 1:
        raise ValueError(f"noise_draws must be an integer >= 1, got {noise_draws!r}")
    rng = np.random.default_rng(seed)
    can, tgt, (gv, gf) = scene.canonical, scene.target, scene.garment
    ref = _drape(sim, can, tgt, (gv, gf), scene.fabric)
    out: dict[str, float] = {"noise": 0.0}
    for _ in range(noise_draws):
        noisy = [(v + rng.normal(0.0, NOISE_M, v.shape), f) for v, f in (can, tgt, (gv, gf))]
        out["noise"] = max(out["noise"], _max_mm(_drape(sim, *noisy, scene.fabric), ref))
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for name, (v, f) in (("canonical", can), ("target", tgt), ("garment", (gv, gf))):
            paths.append(str(Path(tmp) / f"{name}.obj"))
            save_mesh(paths[-1], v, f)
        out["obj_round_trip"] = _max_mm(_drape(sim, *paths, scene.fabric), ref)
        sv, sf, source = split_at_seam(gv, gf)
        save_mesh(Path(tmp) / "split.glb", sv, sf)
        out["seam_split"] = _max_mm(_drape(sim, can, tgt, str(Path(tmp) / "split.glb"), scene.fabric), ref[source])
    faces = gf[rng.permutation(len(gf))]
    out["face_permutation"] = _max_mm(_drape(sim, can, tgt, (gv, faces), scene.fabric), ref)
    perm = rng.permutation(len(gv))
    permuted = _drape(sim, can, tgt, (gv[perm], np.argsort(perm)[gf]), scene.fabric)
    out["vertex_permutation"] = _max_mm(permuted, ref[perm])
    for check, (degrees, shift, whole) in MOVES.items():

        def move(mesh: Mesh, degrees: float = degrees, shift: np.ndarray | None = shift) -> Mesh:
            return turn_about_vertical(mesh[0], degrees, shift), mesh[1]

        moved = _drape(sim, move(can) if whole else can, move(tgt), move((gv, gf)) if whole else (gv, gf), scene.fabric)
        back = turn_about_vertical(moved - (0.0 if shift is None else shift), -degrees)
        out[check] = _max_mm(back, ref)
    return out


def rest_displacement_mm(sim: Any, scene: Scene) -> float:
    """Mean displacement (mm) of the template draped onto its own canonical body."""
    out = _drape(sim, scene.canonical, scene.canonical, scene.garment, scene.fabric)
    return 1000.0 * float(np.linalg.norm(out - scene.garment[0], axis=1).mean())


def measure(sim: Any, scenes: Iterable[Scene], seed: int = 0, noise_draws: int = 1) -> dict[str, Any]:
    """Every check (``noise`` over ``noise_draws`` draws) and the rest displacement on each scene, and a summary: the
    worst scene per check (all scenes and per garment type), the worst and mean rest displacement."""
    rows = []
    for i, scene in enumerate(scenes):
        row: dict[str, Any] = {"name": scene.name, "garment_type": scene.garment_type}
        row["vertices"] = len(scene.garment[0])
        row.update(perturbation_changes(sim, scene, seed=seed + i, noise_draws=noise_draws))
        row["rest_mm"] = rest_displacement_mm(sim, scene)
        rows.append(row)
    if not rows:
        raise ValueError("no scenes to measure")
    groups = {"all": list(rows)}
    for row in rows:
        groups.setdefault(row["garment_type"], []).append(row)
    summary = {
        group: {
            "n": len(members),
            **{check: max(r[check] for r in members) for check in CHECKS},
            "stability_max_mm": max(r[c] for r in members for c in STABILITY_CHECKS),
            "equivariance_max_mm": max(r[c] for r in members for c in EQUIVARIANCE_CHECKS),
            "rest_max_mm": max(r["rest_mm"] for r in members),
            "rest_mean_mm": float(np.mean([r["rest_mm"] for r in members])),
        }
        for group, members in sorted(groups.items())
    }
    return {"rows": rows, "summary": summary}


def scenes_from_store(
    root: str | Path,
    split: str | None = None,
    resolution: str | None = None,
    per_type: int | None = None,
    wide_poses: int | None = None,
) -> list[Scene]:
    """One scene per sequence of a garsim dataset folder (the first ``per_type`` of each garment type): its
    template at ``resolution`` (default: the finest stored, as a user's garment comes) on its canonical body, the
    first stored target body, its fabric (physical values where it has no preset name). ``wide_poses`` (a seed):
    the target is instead the sequence's body in a pose of the sampler's whole range (``JointLimits()``), where the
    network's drape is often tangled with the body: a stress test of the post-process."""
    from garsim.data.sample import CUSTOM_FABRIC
    from garsim.data.store import DatasetStore

    store = DatasetStore(root)
    scenes: list[Scene] = []
    taken: Counter[str] = Counter()
    for k, entry in enumerate(store.entries()):
        if (split is not None and entry["split"] != split) or taken[entry["garment_type"]] == per_type:
            continue  # read only the sequences it keeps
        taken[entry["garment_type"]] += 1
        rec = store.read_sequence(entry)
        level = resolution or ("full" if "full" in rec.levels else "low")
        if level not in rec.levels:
            raise ValueError(f"{root}: sequence {rec.seq_id} has no {level!r} resolution ({sorted(rec.levels)})")
        lv = rec.levels[level]
        target = rec.body_targets[0] if wide_poses is None else _wide_pose(rec, wide_poses + k)
        values = rec.meta.get("fabric_values")
        fabric = dict(values) if rec.fabric == CUSTOM_FABRIC and values else rec.fabric
        scenes.append(
            Scene(
                name=rec.seq_id,
                garment_type=rec.garment_type,
                canonical=(rec.body_canonical.astype(np.float64), rec.body_faces),
                target=(target.astype(np.float64), rec.body_faces),
                garment=(lv.template.astype(np.float64), lv.faces),
                fabric=fabric,
            )
        )
    return scenes


def scenes_from_jobs(count: int, seed: int = 0, wide_poses: int = 0) -> list[Scene]:
    """``count`` garments as the data generator plans them (``plan_jobs`` with ``seed``: the families and both
    constructions in turn, their sampled parameters, vertex counts, phenotypes and first fabrics), built on their
    body's T-pose and not simulated, each draped onto its body in a pose of the sampler's whole range (seed
    ``wide_poses`` + k): tangled drapes that stress the post-process without a dataset folder."""
    from garsim.bodies.anny import AnnyBody
    from garsim.data.sample import CUSTOM_FABRIC
    from garsim.physics.generate import GenerateConfig, build_garment, plan_jobs

    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"count must be an integer >= 1, got {count!r}")
    jobs = plan_jobs(GenerateConfig(out=Path("."), seed=seed, num_train=count, num_test=0, num_ood=0))
    scenes = []
    for k, job in enumerate(jobs):
        body = AnnyBody(job.phenotype)
        garment = build_garment(job, body)
        fabric = {key: v for key, v in job.fabrics[0].items() if key != "name"}
        name = job.fabrics[0]["name"]
        scenes.append(
            Scene(
                name=f"{job.job_id}-{job.construction}",
                garment_type=job.family,
                canonical=(body.canonical().vertices.astype(np.float64), body.faces),
                target=(_posed_wide(body, wide_poses + k).astype(np.float64), body.faces),
                garment=(garment.vertices.astype(np.float64), garment.faces),
                fabric=fabric if name == CUSTOM_FABRIC else name,
            )
        )
    return scenes


def _posed_wide(body: Any, seed: int) -> np.ndarray:
    """``body`` in a pose of the sampler's whole range."""
    from garsim.bodies.poses import PoseSampler

    return body.pose(PoseSampler(seed=seed, body=body).sample(1)[0]).vertices


def _wide_pose(rec: Any, seed: int) -> np.ndarray:
    """The body of a dataset sequence (its phenotype) in a pose of the sampler's whole range."""
    from garsim.bodies.anny import AnnyBody

    if "phenotype" not in rec.meta:
        raise ValueError(f"sequence {rec.seq_id} stores no phenotype: its body cannot be posed anew")
    body = AnnyBody(rec.meta["phenotype"])
    if len(body.faces) != len(rec.body_faces):
        raise ValueError(f"sequence {rec.seq_id}: its body is not Anny's topology")
    return _posed_wide(body, seed)


def scenes_from_npz(folder: str | Path) -> list[Scene]:
    """Scenes from a folder of ``*.npz`` drapes (``body_canonical``, ``body_target``, ``garment_template``,
    ``garment_faces``, ``garment_type``, ``fabric``) sharing the body faces in ``body_faces.npy``, as the
    external check set stores them."""
    folder = Path(folder)
    faces_path = folder / "body_faces.npy"
    files = sorted(folder.glob("*.npz"))
    if not files or not faces_path.is_file():
        raise ValueError(f"{folder}: expected *.npz drapes and body_faces.npy beside them")
    body_faces = np.load(faces_path, allow_pickle=False)
    scenes = []
    for path in files:
        with np.load(path, allow_pickle=False) as d:
            scenes.append(
                Scene(
                    name=path.stem,
                    garment_type=str(d["garment_type"]),
                    canonical=(d["body_canonical"].astype(np.float64), body_faces),
                    target=(d["body_target"].astype(np.float64), body_faces),
                    garment=(d["garment_template"].astype(np.float64), d["garment_faces"]),
                    fabric=str(d["fabric"]),
                )
            )
    return scenes
