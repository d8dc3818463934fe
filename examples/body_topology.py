"""Other body meshes: the same drapes with the body given in another triangulation, through the public API.

A user's body is rarely Anny's own mesh. For seeded test samples of every family this drapes the garment with the
body as stored (Anny's topology: the LBS prior from recovered bones) and with the same body surface in three other
triangulations (any other topology: the rig-free prior): midpoint-subdivided (4x the faces, the very same surface),
isotropically remeshed at about Anny's vertex count, and decimated to about a quarter. Each variant's target body
is the stored target carried over by barycentric coordinates on the canonical surface, so the ground truth is the
stored simulation throughout. Scored: mean error to the simulation of the raw network (``collision_margin=None``),
the API defaults and the prior, per family and variant.

Run: .venv/bin/python examples/body_topology.py --data ~/garsim-data/v4test --per-family 6 \
    --json docs/studies/body_topology.json
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np

from garsim.api import GarSim
from garsim.data.sample import Sample
from garsim.data.store import DatasetStore
from garsim.garments.remesh import barycentric_map, transfer_barycentric
from garsim.geometry.mesh import face_areas

Variant = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def subdivided(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle split into four at its edge midpoints: the same surface, 4x the faces."""
    import trimesh

    return trimesh.remesh.subdivide(v, f)


def _meshlab(v: np.ndarray, f: np.ndarray, step: Callable) -> tuple[np.ndarray, np.ndarray]:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(v, np.float64), face_matrix=np.asarray(f, np.int32)))
    step(ms, pymeshlab)
    ms.meshing_remove_unreferenced_vertices()
    m = ms.current_mesh()
    return np.asarray(m.vertex_matrix()), np.asarray(m.face_matrix(), dtype=np.int64)


def remeshed(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Isotropic explicit remeshing at about the input's vertex count (another triangulation of the surface)."""
    length = math.sqrt(1.155 * float(face_areas(v, f).sum()) / len(v))
    return _meshlab(
        v,
        f,
        lambda ms, pml: ms.meshing_isotropic_explicit_remeshing(
            iterations=6, targetlen=pml.PureValue(length), maxsurfdist=pml.PureValue(0.2 * length)
        ),
    )


def decimated(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge collapse to a quarter of the faces."""
    return _meshlab(
        v,
        f,
        lambda ms, pml: ms.meshing_decimation_quadric_edge_collapse(
            targetfacenum=len(f) // 4, preservenormal=True, preservetopology=True, planarquadric=True
        ),
    )


VARIANTS: dict[str, Variant | None] = {
    "anny": None,
    "subdivided": subdivided,
    "remeshed": remeshed,
    "decimated": decimated,
}


def body_pair(sample: Sample, variant: Variant | None) -> tuple[tuple, tuple]:
    """(canonical, target) body meshes of ``sample`` in ``variant``'s triangulation."""
    c, t, f = sample.body_canonical, sample.body_target, sample.body_faces
    if variant is None:
        return (c, f), (t, f)
    v2, f2 = variant(np.asarray(c, np.float64), f)
    to_new = barycentric_map(v2, c, f)
    return (transfer_barycentric(c, to_new), f2), (transfer_barycentric(t, to_new), f2)


def pick(samples: list[Sample], per_family: int, seed: int) -> list[Sample]:
    """``per_family`` seeded samples of each garment family."""
    rng = np.random.default_rng(seed)
    fams: dict[str, list[Sample]] = defaultdict(list)
    for s in samples:
        fams[s.garment_type].append(s)
    out = []
    for fam in sorted(fams):
        idx = rng.choice(len(fams[fam]), size=min(per_family, len(fams[fam])), replace=False)
        out.extend(fams[fam][i] for i in sorted(idx))
    return out


def per_vertex(fabric: str = "denim") -> dict[str, dict[str, float]]:
    """How far single vertices move when only the body's triangulation changes: a 600-vertex skirt on Anny's T-pose
    body walking (the scene of tests/test_api_stability.py). Per variant, mean / max mm of the API defaults, the raw
    network, the prior, and the raw network given the Anny-mesh (LBS) prior (the network's own dependence)."""
    import dataclasses

    from garsim.api import make_sample
    from garsim.bodies.anny import AnnyBody
    from garsim.bodies.poses import walk_pose
    from garsim.garments.templates import make_garment

    body = AnnyBody()
    can = body.canonical()
    tgt = body.pose({b: v[0] for b, v in walk_pose(0.8, stride=0.5).items()})
    g = make_garment("skirt", body, {"length": 0.5, "flare": 0.4}, target_vertices=600)
    base = ((can.vertices.astype(np.float64), body.faces), (tgt.vertices.astype(np.float64), body.faces))
    garment = (g.vertices, g.faces)
    sims = {"defaults": GarSim.pretrained(), "raw": GarSim.pretrained(collision_margin=None)}
    sims["prior"] = GarSim.prior_only()
    ref = {k: sim.drape(*base, garment, fabric=fabric) for k, sim in sims.items()}
    ref_sample = make_sample(*base, garment, fabric=fabric)
    net_ref = sims["raw"].model.predict(ref_sample)
    out: dict[str, dict[str, float]] = {}
    for name, variant in VARIANTS.items():
        if variant is None:
            continue
        pair = body_pair(ref_sample, variant)
        moved = {k: sims[k].drape(*pair, garment, fabric=fabric) - ref[k] for k in sims}
        same_prior = dataclasses.replace(make_sample(*pair, garment, fabric=fabric), prior=ref_sample.prior)
        moved["raw, Anny-mesh prior"] = sims["raw"].model.predict(same_prior) - net_ref
        out[name] = {}
        for k, d in moved.items():
            mm = 1000.0 * np.linalg.norm(d, axis=1)
            out[name][f"{k} mean mm"], out[name][f"{k} max mm"] = float(mm.mean()), float(mm.max())
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="dataset folder with a test split")
    parser.add_argument("--split", default="test")
    parser.add_argument("--per-family", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    samples = pick(DatasetStore(args.data).samples(args.split, "low"), args.per_family, args.seed)
    load = (lambda **o: GarSim.load(args.model, **o)) if args.model else GarSim.pretrained
    methods = {"raw": load(collision_margin=None), "defaults": load(), "prior": GarSim.prior_only()}
    errors: dict[str, dict[str, dict[str, list[float]]]] = defaultdict(lambda: defaultdict(lambda: defaultdict(list)))
    vertices: dict[str, list[int]] = defaultdict(list)
    for k, s in enumerate(samples):
        fabric = s.fabric if s.fabric_values is None else dict(s.fabric_values)
        garment = (s.garment, s.garment_faces)
        for name, variant in VARIANTS.items():
            canonical, target = body_pair(s, variant)
            vertices[name].append(len(canonical[0]))
            for method, sim in methods.items():
                pred = sim.drape(canonical, target, garment, fabric=fabric, pinned=s.pinned)
                err = 1000.0 * float(np.linalg.norm(pred - s.target, axis=1).mean())
                for fam in (s.garment_type, "all"):
                    errors[name][method][fam].append(err)
        print(f"{k + 1}/{len(samples)} {s.meta.get('name')}", flush=True)
    report = {
        "command": "examples/body_topology.py "
        + " ".join(f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if v is not None),
        "samples": len(samples),
        "body_vertices": {n: [int(min(v)), int(max(v))] for n, v in vertices.items()},
        "mean_error_mm": {
            n: {m: {f: float(np.mean(e)) for f, e in fams.items()} for m, fams in by.items()}
            for n, by in errors.items()
        },
    }
    table = [
        "| body | vertices | family | prior mm | raw mm (ratio) | defaults mm (ratio) |",
        "|---|---|---|---|---|---|",
    ]
    for n, by in report["mean_error_mm"].items():
        lo, hi = report["body_vertices"][n]
        for fam in sorted(by["prior"], key=lambda f: (f == "all", f)):
            p, r, d = (by[m][fam] for m in ("prior", "raw", "defaults"))
            table.append(f"| {n} | {lo}-{hi} | {fam} | {p:.1f} | {r:.1f} ({r / p:.3f}) | {d:.1f} ({d / p:.3f}) |")
    print("\n".join(table))
    report["per_vertex"] = per_vertex()
    for n, row in report["per_vertex"].items():
        print(n, " ".join(f"{k} {v:.2f}" for k, v in row.items()))
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
