"""The ``garsim`` command line: thin wrappers that parse, call the library, and report.

Importing this module imports no numpy, torch or trimesh: ``garsim --help`` is instant, and the inference
commands (drape, animate) pin numpy's and torch's thread pools to one thread before the libraries load (on a
few shared cores, spinning up a thread pool for one small drape costs more than it saves; set
``OMP_NUM_THREADS`` / ``OPENBLAS_NUM_THREADS`` to override). User errors end with one line on stderr that says
what to fix and exit status 2; outputs are checked before any work.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import dataclasses
import json
import logging
import os
import sys
from functools import cache
from pathlib import Path

from garsim.atomic import atomic_write_bytes

FABRIC_CHOICES: tuple[str, ...] = ("silk", "cotton", "denim", "leather")
"""The fabric presets (``garsim.data.sample.FABRICS``, repeated here so that parsing imports no numpy)."""


def fabric_arg(text: str) -> str | dict[str, float]:
    """``--fabric``: a preset name, or physical values as ``bending=2e-5,density=0.2,stretch=3000`` (N·m, kg/m², N/m;
    optionally friction, bending_damping, stretch_damping, thickness), checked by the API."""
    if "=" not in text:
        name = text.strip().lower()
        if name not in FABRIC_CHOICES:
            raise argparse.ArgumentTypeError(
                f"unknown fabric {text!r}: a preset ({', '.join(FABRIC_CHOICES)}) or key=value physical values"
            )
        return name
    values: dict[str, float] = {}
    for item in text.split(","):
        key, _, value = item.partition("=")
        try:
            values[key.strip()] = float(value)
        except ValueError:  # no "=" leaves an empty value
            raise argparse.ArgumentTypeError(f"fabric value {item.strip()!r} is not key=number") from None
    return values


FABRIC_HELP = (
    f"a preset ({', '.join(FABRIC_CHOICES)}) or physical values, e.g. bending=2e-5,density=0.2,stretch=3000 "
    "(N·m, kg/m², N/m; optionally friction, bending_damping, stretch_damping, thickness, which only the "
    "simulator of `garsim data generate` reads: the model's drape depends on bending, density and stretch)"
)
INCOMPLETE = 3
"""Exit status of ``garsim data generate`` when jobs failed transiently (rerun to retry them; 2: a usage error)."""
MOTION_FRAMES = 30
"""``garsim animate --frames``' default: the frames of a --motion."""
FAMILY_CHOICES: tuple[str, ...] = ("skirt", "top", "tshirt", "longsleeve", "trousers", "dress")
"""The garment families (``garsim.data.sample.GARMENT_TYPES``, repeated for the same reason)."""
MODEL_CHOICES: tuple[str, ...] = ("garsim", "deepsd")
STRAP_CHOICES: tuple[str, ...] = ("band", "crest")
"""``garsim data generate --strap-pins`` (``garsim.physics.generate.STRAP_PINS``, repeated for the same reason)."""
GROUP_CHOICES: tuple[str, ...] = ("canonical_pose", "construction", "fabric", "family", "paired", "pose_mode")
"""What `garsim eval --by` groups rows by (``garsim.eval.experiments.GROUPS``, repeated for the same reason)."""
ANIMATION_FPS = 30.0
"""``garsim animate --fps`` unless a USD ``--targets`` stage gives its own rate."""
BODY_MESH_HELP = (
    "the body's mesh in a .glb/.gltf or USD --canonical / {targets} file that holds several (eyes, hair, a garment), "
    "by mesh, node or prim name (default: the mesh named Body; else a glTF's every mesh, a USD stage's only one)"
)
GARMENT_MESH_HELP = (
    "the garment's mesh in a .glb/.gltf or USD --garment file that also holds the avatar or other pieces, by mesh, "
    "node or prim name (default: every mesh of the file)"
)
USD_OUTPUTS: tuple[str, ...] = (".usd", ".usda", ".usdc")
MESH_OUTPUTS: tuple[str, ...] = (".obj", ".ply", ".glb", ".off", ".stl", *USD_OUTPUTS)
"""What ``garsim drape --out`` writes (``garsim.geometry.io.save_mesh``; USD: ``garsim.export``, one frame)."""
MESH_INPUTS: tuple[str, ...] = (".obj", ".ply", ".glb", ".gltf", ".off", ".stl", ".usd", ".usda", ".usdc", ".usdz")
"""What ``garsim drape`` reads (``garsim.geometry.io.SUPPORTED_EXTENSIONS``)."""
ANIMATION_OUTPUTS: tuple[str, ...] = (".glb", ".gltf", ".usd", ".usda", ".usdc", ".pc2", ".mp4", ".gif", ".npz")
"""What ``garsim animate --out`` writes (``garsim.export.SUPPORTED_EXTENSIONS``, and ``garsim view``'s ``.npz``)."""
SINGLE_THREAD_COMMANDS: tuple[str, ...] = ("drape", "animate")
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_USER_ERRORS = (ValueError, OSError, RuntimeError)
"""Exceptions reported as one line (MeshError and ExportError are ValueErrors; a missing, unreadable or
unwritable file an OSError); anything else is a bug and keeps its traceback."""
WIDENING_FLAGS = ("fabric_decoder_film", "global_context", "target_surface", "local_rotation")
"""GarSimConfig switches that `garsim train` can add to a model (`GraphModel.widened`: new layers at zero;
local_rotation adds none, it changes how the decoded correction is applied)."""


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the examples' line breaks and appends each option's default (also the library's defaults of
    options that leave them to a config class, read from its source without importing it)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "%(default)" in text or not action.option_strings or action.default is argparse.SUPPRESS:
            return text
        lazy = getattr(action, "config_default", None)
        if action.default is None and lazy is not None:
            value = dataclass_default(*lazy)
            return text if value is None else f"{text} (default: {value})"
        if action.default is None or action.default is False:
            return text
        default = action.default
        if isinstance(default, (list, tuple)):
            default = " ".join(str(x) for x in default) if action.nargs else "/".join(str(x) for x in default)
        return f"{text} (default: {str(default).replace('%', '%%')})".strip()


class _Parser(argparse.ArgumentParser):
    """Usage errors are one line: what is wrong and where the help is."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


@cache
def dataclass_default(module: str, cls: str, name: str) -> str | None:
    """The default of field ``name`` of dataclass ``cls`` in garsim module ``module``, read from the source
    (importing the trainer or the generator would load torch or the simulator just to print the help)."""
    path = Path(__file__).parent.joinpath(*module.split(".")[1:]).with_suffix(".py")
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError):
        return None
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == cls:
            for item in node.body:
                if (
                    isinstance(item, ast.AnnAssign)
                    and isinstance(item.target, ast.Name)
                    and item.target.id == name
                    and item.value is not None
                ):
                    try:
                        return repr(ast.literal_eval(item.value))
                    except ValueError:
                        return None
    return None


def _config_default(action: argparse.Action, module: str, cls: str, name: str) -> None:
    action.config_default = (module, cls, name)  # type: ignore[attr-defined]


def _grouping(text: str) -> str:
    """``garsim eval --by``: a grouping key of GROUP_CHOICES, or keys crossed as ``a/b``."""
    unknown = [k for k in text.split("/") if k not in GROUP_CHOICES]
    if unknown:
        raise argparse.ArgumentTypeError(f"cannot group by {unknown}; choose from {', '.join(GROUP_CHOICES)}")
    return text


def _check_output(path: str | os.PathLike, extensions: tuple[str, ...], flag: str) -> Path:
    """Fail before any work when ``path`` has another extension or its folder cannot be written."""
    from garsim.atomic import check_writable_folder

    p = Path(path)
    ext = p.suffix.lower()
    if ext not in extensions:
        got = repr(ext) if ext else "a file without an extension"
        raise ValueError(f"{flag} {p}: cannot write {got}; use one of {', '.join(extensions)}")
    if p.is_dir():
        raise ValueError(f"{flag} {p} is a folder; give a file name ending in {', '.join(extensions)}")
    check_writable_folder(p.parent, label=f"{flag} {p}")
    return p


def _shard(text: str) -> tuple[int, int]:
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--shard must look like K/N (e.g. 0/4), got {text!r}") from None
    if not (n >= 1 and 0 <= k < n):
        raise argparse.ArgumentTypeError(f"--shard K/N needs 0 <= K < N, got {text!r}")
    return k, n


def _write_json(path: str | Path, obj: object) -> Path:
    return atomic_write_bytes(path, json.dumps(obj, indent=1).encode())


def _check_folder(path: str | os.PathLike, flag: str = "--out") -> Path:
    """Fail before any work when files cannot be written in the folder ``path`` (created later if missing)."""
    from garsim.atomic import check_writable_folder

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{flag} {p} is a file; give a folder")
    return check_writable_folder(p, label=f"{flag} {p}")


def cmd_demo(args: argparse.Namespace) -> int:
    _check_folder(args.out)
    from garsim.demo import DemoConfig, run_demo

    outputs = run_demo(
        DemoConfig(out=Path(args.out), seed=args.seed, target_vertices=args.vertices, frames=args.frames)
    )
    for path in outputs:
        print(path)
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from garsim.view import ViewerUnavailable, serve

    try:
        serve(args.path, host=args.host, port=args.port, block=True, up=args.up, units=args.units)
    except ViewerUnavailable as exc:
        print(exc, file=sys.stderr)
        return 2
    return 0


def _drape_outputs(args: argparse.Namespace, batch: bool) -> tuple[Path | None, Path | None, str]:
    """Check ``--out`` and ``--png`` before any work -> (out file or folder, png file or folder, output extension)."""
    fmt = f".{args.format}" if args.format else None
    if not batch:
        out = _check_output(args.out, MESH_OUTPUTS, "--out")
        if fmt and fmt != out.suffix.lower():
            raise ValueError(f"--format {args.format} disagrees with --out {out}; drop --format or rename --out")
        png = _check_output(args.png, (".png",), "--png") if args.png else None
        return out, png, out.suffix.lower()
    for flag, value in (("--out", args.out), ("--png", args.png)):
        if value and not Path(value).is_dir() and Path(value).suffix.lower() in (*MESH_INPUTS, ".png"):
            raise ValueError(
                f"{flag} {value}: with several targets, give a folder (one file per target, named after it)"
            )
    out = _check_folder(args.out)
    png = _check_folder(args.png, "--png") if args.png else None
    ext = fmt or Path(args.garment).suffix.lower()
    return out, png, ".glb" if ext == ".gltf" else ext if ext in MESH_OUTPUTS else ".obj"


def _drape_targets(values: list[str]) -> list[Path]:
    """The target meshes: each file given, and each folder's mesh files in name order (numbers by value)."""
    from garsim.geometry.io import natural_order

    paths = []
    for value in values:
        p = Path(value)
        if not p.exists():
            raise ValueError(f"--target {p}: no such file or folder")
        if not p.is_dir():
            paths.append(p)  # an unreadable file is reported when it is read
            continue
        found = natural_order(
            q for q in p.iterdir() if q.suffix.lower() in MESH_INPUTS and not q.name.startswith(".") and q.is_file()
        )
        if not found:
            raise ValueError(f"--target {p}: the folder has no mesh files ({', '.join(MESH_INPUTS)})")
        paths += found
    return paths


def _same_file(a: Path, b: str | Path) -> bool:
    try:
        return a.resolve() == Path(b).resolve()
    except (OSError, RuntimeError):
        return False


def cmd_drape(args: argparse.Namespace) -> int:
    batch = len(args.target) > 1 or any(Path(t).is_dir() for t in args.target)
    targets = _drape_targets(args.target)  # listed, not read: a missing path or an empty folder is said first
    out, png, ext = _drape_outputs(args, batch)  # then the outputs: nothing is computed for a bad path
    if batch:
        outs = [out / f"{t.stem}{ext}" for t in targets]
        pngs = [png / f"{t.stem}.png" if png else None for t in targets]
        seen: dict[Path, Path] = {}
        for t, o in zip(targets, outs):
            if o in seen:
                raise ValueError(f"--target {seen[o]} and {t} would both be written to {o}: rename one")
            seen[o] = t
    else:
        outs, pngs = [out], [png]
    for o in outs:
        for flag, given in [("--canonical", args.canonical), ("--garment", args.garment)] + [
            ("--target", t) for t in targets
        ]:
            if _same_file(o, given):
                raise ValueError(f"--out {o} would overwrite the input {flag} {given}; write elsewhere")
    import numpy as np

    from garsim.api import GarSim, Scene, from_internal
    from garsim.geometry.io import MeshError, save_mesh

    canonical = _read_input(args.canonical, args, body=True, rest=True)
    gv, gf, attributes = _read_garment(args)  # UVs and normals go to the output
    garment = (gv, gf)
    bodies = []
    for path in targets:  # every target is read and checked before the first drape
        body = _read_input(path, args, body=True)
        if body[0].shape != canonical[0].shape or not np.array_equal(body[1], canonical[1]):
            raise MeshError(
                f"{path}: {len(body[0])} vertices, {len(body[1])} faces: the target body must have the canonical "
                f"body's topology ({len(canonical[0])} vertices, {len(canonical[1])} faces); pose the same body mesh"
                f"{_mesh_choice_hint(path)}"
            )
        bodies.append(body)
    pinned = "auto" if args.pinned == "auto" else _read_pinned(args.pinned) if args.pinned else None

    scene = Scene.make(canonical, garment, args.fabric, pinned, up=args.up, units=args.units)  # once for all targets
    samples = [scene.sample(body) for body in bodies]  # bad meshes are refused before the model loads
    sim = GarSim.prior_only() if args.prior_only else GarSim.pretrained()
    for sample, path, png_path in zip(samples, outs, pngs):
        pred = scene.unweld(sim.predict(sample))  # on the file's vertices (coincident ones were draped as one)
        # in the input's units, but glTF's are metres (as `garsim animate` writes them)
        units = "m" if path.suffix.lower() in (".glb", ".gltf") else args.units
        verts = from_internal(pred, args.up, units).astype(np.float32)
        if png_path is not None:  # the render is the likelier of the two writes to fail: before the mesh
            from garsim.geometry.render import render_views

            render_views(png_path, [(sample.body_target, sample.body_faces), (pred, gf)])
        # a Z-up result is turned Y-up for glTF (its axis, as `garsim animate` writes it) and with --y-up (Blender);
        # with --up y the result is already in the input's Y-up axis
        y_up = args.up == "z" and (args.y_up or path.suffix.lower() in (".glb", ".gltf"))
        if path.suffix.lower() in USD_OUTPUTS:  # one frame, in the input's axis and units, both declared
            from garsim.export import export_animation

            export_animation(path, verts[None], gf, up=args.up, units=units, uvs=attributes.vertex_uvs(gf, len(gv)))
        else:
            attrs = None if attributes.empty else attributes.recompute_normals(verts, gf)
            axes = {"input_up": "y" if y_up or args.up == "y" else "z", "input_units": units}  # for garsim view
            save_mesh(path, verts, gf, y_up=y_up, attributes=attrs, metadata=axes)
        print(path)
        if png_path is not None:
            print(png_path)
    return 0


def _read_pinned(path: str) -> object:
    """Pinned garment vertex indices from a text file (whitespace- or newline-separated integers)."""
    import numpy as np

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"--pinned {p}: no such file (give a text file of garment vertex indices)")
    if not p.read_text(errors="replace").split():
        raise ValueError(f"--pinned {p}: the file is empty (give garment vertex indices, or --pinned auto)")
    try:
        values = np.loadtxt(p, dtype=np.float64, ndmin=1).ravel()
    except ValueError as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"--pinned {p}: not a list of integer vertex indices ({first})") from None
    if not np.all(np.isfinite(values)) or not np.all(values == np.round(values)):
        raise ValueError(f"--pinned {p}: vertex indices must be integers")
    return values.astype(np.int64)


def _read_input(
    path: str,
    args: argparse.Namespace,
    attributes: bool = False,
    body: bool = False,
    rest: bool = False,
    pick: str | None = None,
) -> tuple:
    """A user's mesh file in file order, as ``load_mesh`` (``attributes``: ``load_mesh_with_attributes``) reads it;
    a USD stage, which declares its axis and unit, brought to ``--up`` / ``--units`` like the other inputs. ``body``:
    a glTF's or USD stage's body mesh alone (``--body-mesh``, else the mesh named Body); ``rest``: a skinned USD body
    in its skeleton's rest pose (a canonical body), not its animation's first frame (a glTF is read as it stores
    its nodes). ``pick``: the mesh of that name alone (a garment exported with its avatar)."""
    from garsim.geometry.io import (
        USD_EXTENSIONS,
        from_internal,
        load_gltf_mesh,
        load_mesh,
        load_mesh_with_attributes,
        validate_mesh,
    )

    ext = Path(path).suffix.lower()
    if pick is not None and ext not in (".glb", ".gltf", *USD_EXTENSIONS):
        raise ValueError(f"{path}: a mesh is picked by name (--garment-mesh {pick}) from a .glb/.gltf or USD file")
    if ext in USD_EXTENSIONS:
        from garsim.geometry.usd_stage import read_usd_mesh

        mesh = args.body_mesh if body else pick
        v, f, attrs = read_usd_mesh(path, z_up_metres=True, mesh=mesh, body=body or pick is not None, rest=rest)
        v, f = validate_mesh(from_internal(v, args.up, args.units), f, name=str(path))
        return (v, f, attrs.check(len(f), str(path))) if attributes else (v, f)
    if (body or pick is not None) and ext in (".glb", ".gltf"):  # one mesh as stored, as --targets frames are read
        v, f, attrs = load_gltf_mesh(path, args.body_mesh if body else pick)
        return (v, f, attrs) if attributes else (v, f)
    return load_mesh_with_attributes(path) if attributes else load_mesh(path)


def _mesh_choice_hint(path: str | Path, flag: str = "--body-mesh", what: str = "the body") -> str:
    """'; it holds N meshes (...): pick <what> with <flag>' for a glTF or USD file of several meshes (a body read
    with its eyes, hair or garment; a garment with its avatar), else ''."""
    from garsim.geometry.io import USD_EXTENSIONS

    p = Path(path)
    if p.suffix.lower() in (".glb", ".gltf"):
        from garsim.geometry.gltf_scene import GltfScene

        names = [i.name or f"node {i.node}" for i in GltfScene.read(p).instances]
    elif p.suffix.lower() in USD_EXTENSIONS:
        from garsim.geometry.usd_stage import open_stage

        stage, prims = open_stage(p)  # the stage must outlive its prims
        names = [prim.GetName() for prim in prims]
    else:
        return ""
    if len(names) < 2:
        return ""
    listed = ", ".join(names[:6]) + ", ..." * (len(names) > 6)
    return f"; it holds {len(names)} meshes ({listed}): pick {what} with {flag}"


def _read_garment(args: argparse.Namespace) -> tuple:
    """The --garment file's mesh (--garment-mesh, else all of it, with a warning when a glTF or USD file holds
    several meshes) with its surface attributes."""
    garment = _read_input(args.garment, args, attributes=True, pick=args.garment_mesh)
    hint = "" if args.garment_mesh is not None else _mesh_choice_hint(args.garment, "--garment-mesh", "the garment")
    if hint:
        logging.getLogger("garsim").warning("%s: draped as one garment%s", args.garment, hint)
    return garment


def _load_targets(src: Path, canonical: tuple, args: argparse.Namespace) -> tuple[list, float]:
    """(target body vertex arrays, frames per second) from a folder of OBJs, an .npz with 'vertices' (T, V, 3), an
    animated glTF sampled at ``--fps``, a USD stage's animated body (sampled at ``--fps``, by default its own rate;
    its declared axis and unit brought to ``--up`` / ``--units``) or a .pc2 point cache; every body must have the
    canonical body's topology."""
    import numpy as np

    from garsim.geometry.io import (
        USD_EXTENSIONS,
        MeshError,
        from_internal,
        load_mesh,
        load_mesh_animation,
        natural_order,
    )

    fps = ANIMATION_FPS if args.fps is None else args.fps
    faces = canonical[1]
    ext = src.suffix.lower()
    if args.animation is not None and ext not in (".glb", ".gltf"):
        raise ValueError(f"--animation picks an animation of a .glb/.gltf --targets file, not of {src}")
    if args.body_mesh is not None and ext not in (".glb", ".gltf", *USD_EXTENSIONS):
        raise ValueError(f"--body-mesh picks the body in a .glb/.gltf or USD --targets file, not in {src}")
    if ext in (".glb", ".gltf", *USD_EXTENSIONS) and src.is_file():
        if ext in USD_EXTENSIONS:
            from garsim.geometry.usd_stage import load_usd_animation

            frames, f, fps = load_usd_animation(src, args.body_mesh, args.fps)
            frames = from_internal(frames, args.up, args.units)
        else:
            frames, f = load_mesh_animation(src, fps, args.animation, mesh=args.body_mesh)
        if f.shape != faces.shape or not np.array_equal(f, faces):
            raise MeshError(
                f"{src}: {frames.shape[1]} vertices, {len(f)} faces: the animated body must have the canonical body's "
                f"topology ({len(faces)} faces) in the same vertex order{_mesh_choice_hint(src)}"
            )
        if len(frames) == 1:
            logging.getLogger("garsim").warning("%s: nothing in it moves the body: one target frame, as stored", src)
        return list(frames), fps
    if ext == ".pc2" and src.is_file():
        from garsim.export import read_pc2

        frames, _, rate = read_pc2(src)
        if frames.shape[1] != len(canonical[0]):
            raise MeshError(
                f"{src}: {frames.shape[1]} points per frame, the canonical body has {len(canonical[0])} vertices; "
                "cache the same body mesh"
            )
        if rate != 1.0 and len(frames) > 1:  # a sample every `rate` frames: one per frame, linearly between them
            t = np.arange(0.0, (len(frames) - 1) * rate + 1e-6)
            k = np.minimum((t / rate).astype(int), len(frames) - 2)
            u = (t / rate - k)[:, None, None]
            frames = ((1 - u) * frames[k] + u * frames[k + 1]).astype(np.float32)
        return list(frames), fps
    if src.is_dir():
        files = natural_order(src.glob("*.obj"))  # frame_2 before frame_10
        if not files:
            raise ValueError(f"--targets {src}: the folder has no .obj files")
        targets = []
        for path in files:
            v, f = load_mesh(path)
            if f.shape != faces.shape or not np.array_equal(f, faces):
                raise MeshError(
                    f"{path}: {len(v)} vertices, {len(f)} faces: every target body must have the canonical body's "
                    f"topology ({len(faces)} faces); pose the same body mesh"
                )
            targets.append(v)
        return targets, fps
    if not src.is_file():
        raise ValueError(f"--targets {src}: no such file or folder")
    if src.suffix.lower() != ".npz":
        raise ValueError(
            f"--targets {src}: give a folder of body OBJs, an .npz with 'vertices' (T, V, 3), an animated "
            ".glb/.gltf or USD stage, or a .pc2 point cache"
        )
    try:
        with np.load(src, allow_pickle=False) as z:
            # 'vertices', or the bodies of a `garsim animate --out x.npz` (its 'body_frames')
            key = next((k for k in ("vertices", "body_frames") if k in z.files), None)
            if key is None:
                raise ValueError(
                    f"--targets {src}: no array 'vertices' (has {', '.join(z.files) or 'none'}); "
                    "store the target bodies as vertices (T, V, 3)"
                )
            targets = np.asarray(z[key])
            if key == "body_frames":  # an animate .npz stores garsim's frame (Z up, metres): read as --up/--units
                targets = from_internal(targets, args.up, args.units)
    except ValueError:
        raise
    except Exception as exc:  # noqa: BLE001 - a truncated or foreign file raises zipfile/pickle/OS errors
        raise ValueError(f"--targets {src}: not a readable .npz ({type(exc).__name__}: {exc})") from None
    if targets.ndim != 3 or targets.shape[-1] != 3 or len(targets) == 0:
        raise ValueError(f"--targets {src}: '{key}' must have shape (T, V, 3) with T >= 1, got {targets.shape}")
    return list(targets), fps


def cmd_animate(args: argparse.Namespace) -> int:
    out = _check_output(args.out, ANIMATION_OUTPUTS, "--out")  # checked before any work
    sources = [name for name, given in (("--motion", args.motion), ("--poses", args.poses)) if given]
    if args.canonical or args.targets:
        sources.append("--canonical with --targets")
    if len(sources) > 1:
        raise ValueError(f"give one of {' or '.join(sources)}, not both")
    if not sources or (sources == ["--canonical with --targets"] and not (args.canonical and args.targets)):
        raise ValueError(
            "give one of --motion NAME or --poses FILE (the default Anny body), or --canonical and --targets (a "
            "folder of body OBJs, an .npz with an array 'vertices' of shape (T, V, 3), an animated .glb/.gltf or USD "
            "stage, or a .pc2)"
        )
    if args.frames is not None and not args.motion:
        raise ValueError("--frames sets the length of a --motion; --poses and --targets give their own frames")
    frames = MOTION_FRAMES if args.frames is None else args.frames
    if args.motion and frames < 2:
        raise ValueError(f"--frames must be >= 2, got {frames}")
    if args.fps is not None and args.fps <= 0:
        raise ValueError(f"--fps must be > 0, got {args.fps}")
    if (args.animation is not None or args.body_mesh is not None) and not args.targets:
        raise ValueError("--animation and --body-mesh read a .glb/.gltf or USD --targets file; give --targets")
    if args.interpolate is not None and (not args.poses or args.interpolate < 2):
        raise ValueError("--interpolate N (N >= 2) resamples the keyframes of --poses FILE")
    import numpy as np

    from garsim.api import GarSim, SequenceConfig, check_smoothing, fabric_fields
    from garsim.export import animation_files, export_animation
    from garsim.geometry.io import from_internal

    inputs = (("--garment", args.garment), ("--canonical", args.canonical), ("--poses", args.poses))
    for o in animation_files(out, with_body=True):  # a .pc2 also writes <stem>.obj and the body's files
        for flag, given in (*inputs, ("--targets", args.targets)):
            if given and _same_file(o, given):
                raise ValueError(f"--out {out} would overwrite the input {flag} {given} (as {o}); write elsewhere")
        if (
            args.targets
            and o.suffix.lower() == ".obj"
            and Path(args.targets).is_dir()
            and _same_file(o.parent, args.targets)
        ):
            raise ValueError(
                f"--out {out} would write {o.name} into the --targets folder {args.targets} (a body OBJ there is a "
                "target); write elsewhere"
            )
    fabric_fields(args.fabric)
    smoothing = check_smoothing(SequenceConfig.smoothing if args.smoothing is None else args.smoothing)
    pinned = "auto" if args.pinned == "auto" else _read_pinned(args.pinned) if args.pinned else None
    gv, gf, attributes = _read_garment(args)
    garment = (gv, gf)
    uvs = attributes.vertex_uvs(gf, len(gv))  # the animation formats store one UV per vertex
    if uvs is None and attributes.uvs is not None:
        logging.getLogger("garsim").warning(
            "%s: the UVs have seams (a vertex with two UVs); animations store one per vertex, so they are dropped",
            args.garment,
        )
    if args.motion or args.poses:
        from garsim.bodies import poses

        if args.motion:
            try:  # before Anny is built
                sequence = poses.motion(args.motion, frames)
            except ValueError as exc:  # a motion of K keyframes (its start included) needs K frames
                raise ValueError(f"--frames {frames} for --motion {args.motion}: the motion's {exc}") from None
        else:
            sequence = poses.read_pose_sequence(args.poses)
            if args.interpolate is not None:
                sequence = poses.resample_poses(sequence, args.interpolate)
        from garsim.bodies.anny import AnnyBody
        from garsim.export import BodySkin

        body = AnnyBody()
        faces = body.faces
        # Anny's bodies are in garsim's Z-up metres; the garment is in --up / --units: bring the bodies there
        canonical = (from_internal(body.canonical().vertices, args.up, args.units), faces)
        posed, transforms = poses.pose_bodies_rigged(body, sequence)
        targets = list(from_internal(posed, args.up, args.units))
        tpose = poses.pose_bodies_rigged(body, [body.t_pose()])[1][0]  # stored: the file is its own canonical body
        rig = BodySkin(
            body.rest_vertices, body.skin_weights, body.skin_indices, transforms, tuple(body.bone_labels), tpose
        )
        fps = ANIMATION_FPS if args.fps is None else args.fps
    else:
        canonical = _read_input(args.canonical, args, body=True, rest=True)
        faces = canonical[1]
        targets, fps = _load_targets(Path(args.targets), canonical, args)
        rig = None
    sim = GarSim.prior_only() if args.prior_only else GarSim.pretrained()
    frames = sim.drape_sequence(
        canonical,
        targets,
        garment,
        fabric=args.fabric,
        pinned=pinned,
        progress=not args.quiet,
        up=args.up,
        units=args.units,
        smoothing=smoothing,
    )
    if out.suffix.lower() == ".npz":  # garsim view's sequence: with the prior, to compare and colour by correction
        from garsim.geometry.io import to_internal
        from garsim.view import ViewData

        prior = GarSim.prior_only().drape_sequence(
            canonical, targets, garment, fabric=args.fabric, pinned=pinned, up=args.up, units=args.units
        )
        internal = [to_internal(a, args.up, args.units) for a in (frames, np.stack(targets), prior)]
        view = ViewData(internal[0], gf, internal[1], faces, internal[2], fps=fps, name=out.name)
        print(view.save_npz(out))
        return 0
    extra = {} if uvs is None else {"uvs": uvs}
    if attributes.normals is not None:  # the garment came with normals: each frame gets its own, facing as given
        from garsim.geometry.mesh import vertex_normals

        given = attributes.normals[attributes.normal_faces]  # (F, 3 corners, 3)
        side = 1.0 if np.sum(vertex_normals(gv, gf)[gf] * given) >= 0 else -1.0  # against the winding: flipped
        extra["normals"] = np.stack([side * vertex_normals(f, gf) for f in frames]).astype(np.float32)
    metadata = {
        **sim.sequence_metadata(args.fabric, smoothing),
        "input_up": args.up,  # glTF and the previews are converted to Y-up / Z-up metres; USD declares its own
        "input_units": args.units,
    }
    written = export_animation(
        out,
        frames,
        gf,
        metadata=metadata,
        up=args.up,
        units=args.units,
        body_frames=np.stack(targets),
        body_faces=faces,
        fps=fps,
        body_skin=rig,  # an Anny body goes into a glTF skinned to its bones
        **extra,
    )
    for path in written:
        print(path)
    return 0


def cmd_data_generate(args: argparse.Namespace) -> int:
    _check_folder(args.out)
    from garsim.physics.generate import GenerateConfig, generate

    given = {
        "num_train": args.train,
        "num_test": args.test,
        "num_ood": args.ood,
        "min_vertices": args.min_vertices,
        "max_vertices": args.max_vertices,
        "targets_per_job": args.targets,
        "strap_pins": args.strap_pins,
    }
    cfg = GenerateConfig(
        out=Path(args.out),
        seed=args.seed,
        workers=args.workers,
        shard=args.shard,
        limit=args.limit,
        paired_first=args.paired_first,
        reuse=Path(args.reuse) if args.reuse else None,
        sim={"graphs": False} if args.no_graphs else {},
        **{k: v for k, v in given.items() if v is not None},
    )
    summary = generate(cfg, progress=not args.quiet)
    secs = summary.pop("seconds")
    if secs:
        summary["mean_seconds_per_sequence"] = round(sum(secs) / len(secs), 2)
    print(json.dumps(summary, indent=2))
    if summary.get("errors"):  # transient failures (a failed write, a killed worker): not rejections
        print(
            f"garsim data generate: {summary['errors']} jobs failed and were not recorded; rerun the same command "
            "to retry them",
            file=sys.stderr,
        )
        return INCOMPLETE
    return 0


def cmd_data_info(args: argparse.Namespace) -> int:
    from garsim.data.store import DatasetStore

    info = DatasetStore(args.dir).info()
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(
        f"{info['root']}: {info['samples']} samples ({info['settled_samples']} settled) in {info['sequences']} "
        f"sequences of {info['garment_instances']} garment instances, {info['rejected_sequences']} rejected"
    )
    for key, n in info["samples_by"].items():
        print(f"  {key:40s} {n:6d} samples")
    for fam, f in info["per_family"].items():
        print(
            f"  {fam:12s} acceptance {f['acceptance_rate']:.0%} of {f['jobs']} jobs, "
            f"{f['cpu_seconds_per_settled_sample']:.1f} CPU s per settled sample"
        )
    return 0


def cmd_data_verify(args: argparse.Namespace) -> int:
    from garsim.data.store import DatasetStore

    problems = DatasetStore(args.dir).verify()
    for p in problems:
        print(p)
    print(f"{len(problems)} problem(s) found" if problems else "ok: every listed file is complete and intact")
    return 1 if problems else 0


def cmd_train(args: argparse.Namespace) -> int:
    _check_folder(args.out)
    if args.remesh_copies is not None and args.remesh_copies < 0:
        raise ValueError(f"--remesh-copies must be >= 0, got {args.remesh_copies}")
    from garsim.model.baselines import load_model
    from garsim.model.config import GarSimConfig
    from garsim.train.data import train_val_samples
    from garsim.train.losses import LossWeights
    from garsim.train.trainer import TrainConfig, Trainer

    train, val = train_val_samples(
        args.data, resolution=args.resolution, val_every=args.val_every, families=args.families
    )
    init = load_model(args.init) if args.init else None
    given = {
        "epochs": args.epochs,
        "batch_size": args.batch_size,
        "lr": args.lr,
        "seed": args.seed,
        "threads": args.threads,
        "model": init.kind if init is not None else args.model,
        "device": args.device,
        "remesh_copies": args.remesh_copies,
        "mirror": True if args.mirror else None,
        "trainable": tuple(args.trainable) if args.trainable else None,
    }
    losses = {
        "col": args.collision_weight,
        "eps": args.collision_eps,
        "dir": args.direction_weight,
        "pair": args.pair_weight,
        "pair_smooth": args.pair_smooth,
        "fold": args.fold_weight,
        "relative": args.relative_l2,
    }
    cfg = TrainConfig(
        out_dir=args.out,
        collision_start_epoch=args.collision_start,
        losses=LossWeights(**{k: v for k, v in losses.items() if v is not None}),
        progress=not args.quiet,
        resume=not args.restart,
        **{k: v for k, v in given.items() if v is not None},
    )
    if int(os.environ.get("RANK", "0")) == 0:  # record which sequences this run saw (the store may grow later)
        ids = {name: sorted({s.meta["seq_id"] for s in part}) for name, part in (("train", train), ("val", val))}
        _write_json(Path(args.out) / "sequences.json", ids)
    if cfg.remesh_copies:  # remeshed variants of the training samples' full meshes; validation stays as stored
        from garsim.train.augment import remesh_augmented

        full = train
        if args.resolution != "full":
            full, _ = train_val_samples(args.data, resolution="full", val_every=args.val_every, families=args.families)
        originals = len(train)
        train = remesh_augmented(train, full, cfg.remesh_copies, seed=cfg.seed)
        print(f"remeshing: {len(train) - originals} variants of {len(full)} full-resolution training samples")
    if cfg.mirror:  # every training sample (variants included) mirrored left to right as well
        from garsim.train.augment import MirrorAugmented

        train = MirrorAugmented(train)
    print(f"training on {len(train)} samples, validating on {len(val)} ({args.resolution} resolution)")
    model_config = init.config if init is not None else GarSimConfig(**({"head": args.head} if args.head else {}))
    if cfg.mirror and getattr(model_config, "semantic", "grid") == "vertex":
        raise ValueError(
            "--mirror needs the grid body-semantic input: a vertex-mode mask is indexed by body vertex and does not "
            "follow the reflection"
        )
    added = {k: True for k in WIDENING_FLAGS if getattr(args, k) and not getattr(model_config, k)}
    if added and cfg.model != "garsim":
        flag = "--" + next(iter(added)).replace("_", "-")
        raise ValueError(f"{flag} is an option of GarSim; the {cfg.model!r} model has none")
    if added:
        model_config = dataclasses.replace(model_config, **added)
        init = init.widened(model_config) if init is not None else None  # its new layers start at zero
    if args.num_steps is not None and args.num_steps != model_config.num_steps:
        if cfg.model != "garsim":
            raise ValueError(f"--num-steps sets GarSim's message passing; the {cfg.model!r} model has none")
        if init is not None:  # appended steps start as the identity
            init = init.deepened(args.num_steps)
        model_config = dataclasses.replace(model_config, num_steps=args.num_steps)
    history = Trainer(model_config, cfg, train, val or None, init=init).fit()
    if history:
        print(json.dumps(history[-1], indent=2))
    return 0


def cmd_average(args: argparse.Namespace) -> int:
    from garsim.model.soup import average_models

    weights = args.weights or [1.0 / len(args.models)] * len(args.models)
    print(average_models(args.models, weights).save(args.out))
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    if args.out:
        _check_output(args.out, (".json",), "--out")
    from garsim.api import GarSim
    from garsim.eval.experiments import (
        compare_models,
        evaluate_split,
        format_comparison,
        format_table,
        paired_fabric_agreement,
    )
    from garsim.model.baselines import load_model

    other = None
    if args.compare:  # loaded first: a wrong folder fails before any scoring
        try:
            other = load_model(args.compare)
        except (ValueError, OSError) as exc:
            raise ValueError(f"--compare {args.compare}: not a model folder ({exc})") from None
    model = load_model(args.model) if args.model else GarSim.default().model
    report: dict = {"model": args.model or "shipped", "resolution": args.resolution, "by": args.by}
    name = model.kind if model is not None else "garsim"
    for split in args.splits:
        report[split] = evaluate_split(
            model, args.data, split, args.resolution, refine=args.refine, name=name, by=args.by
        )
        print(f"## {split} split ({args.resolution} resolution)\n{format_table(report[split])}\n")
        if args.compare:
            table = compare_models(model, other, args.data, split, args.resolution, by=args.by)
            report.setdefault("compare", {"other": args.compare})[split] = table
            names = ("model", "other") if args.model else ("shipped", "other")
            print(f"## {split} split: raw error against {args.compare}\n{format_comparison(table, *names)}\n")
    if model is not None:
        fab = paired_fabric_agreement(model, args.data, resolution=args.resolution)
        report["paired_fabrics"] = fab
        print(
            f"paired-fabric groups (test): {fab['groups']}, ordering agreement {fab['ordering_agreement']} over "
            f"{fab['pairs_over_gap']} neighbouring pairs past the gap, spread ratio {fab['spread_ratio']}, "
            f"midway fabrics between their presets {fab['midway_between']}"
        )
    if args.out:
        print(_write_json(args.out, report))
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    if args.out:
        _check_output(args.out, (".json",), "--out")
    from garsim.api import GarSim
    from garsim.eval.bench import (
        bench_cold_call,
        bench_inference,
        bench_newton,
        bench_ratios,
        format_bench,
        format_bench_markdown,
        machine_info,
    )
    from garsim.model.runtime import GarSimRuntime

    sim = GarSim.load(args.model) if args.model else GarSim.pretrained()
    reference = None
    if isinstance(sim.model, GarSimRuntime):  # the same weights in torch: the forward's speed-up in this run
        from garsim.api import WEIGHTS_DIR
        from garsim.model.garsim import GarSimModel

        reference = GarSimModel.load(args.model or WEIGHTS_DIR)
    report: dict = {"machine": machine_info(threads=1)}
    report["garsim"] = bench_inference(
        sim.model, args.sizes, repeats=args.repeats, garment=args.garment, reference=reference
    )
    print(format_bench(report["garsim"]))
    cold_sizes = [n for n in args.sizes if args.cold_max is None or n <= args.cold_max]
    if cold_sizes:  # `garsim drape` in a fresh process: always the shipped model
        report["cold"] = bench_cold_call(cold_sizes, garment=args.garment)
        for n, r in report["cold"].items():
            print(
                f"{n} v: cold first call (garsim drape, fresh process) {r['cold_call_wall_ms'] / 1000:.2f} s, "
                f"peak RSS {r['cold_call_peak_rss_mb']:.0f} MiB"
            )
    newton_sizes = [n for n in args.sizes if args.newton_max is None or n <= args.newton_max]
    if args.newton and newton_sizes:
        report["newton"] = bench_newton(newton_sizes, garment=args.garment)
    report["ratios"] = bench_ratios(report)
    for n, q in report["ratios"].items():
        if "paper_over_api" in q:
            print(f"{n} v: GarSim.drape {q['paper_over_api']:.1f}x faster than the paper's {q['paper_s']} s")
        if "newton_over_api" in q:
            r = report["newton"][n]
            print(f"{n} v: Newton {r['wall_ms'] / 1000:.1f} s ({r['frames']} frames) = {q['newton_over_api']:.0f}x")
    if args.out:
        from garsim.atomic import atomic_write_bytes
        from garsim.eval.plots import plot_bench

        out = Path(args.out)
        command = " ".join(
            ["garsim bench", *(["--model", args.model] if args.model else []), "--sizes", *map(str, args.sizes)]
            + ["--garment", args.garment, "--repeats", str(args.repeats), *(["--newton"] if args.newton else [])]
            + ([f"--cold-max {args.cold_max}"] if args.cold_max is not None else [])
            + ([f"--newton-max {args.newton_max}"] if args.newton and args.newton_max is not None else [])
            + ["--out", str(out)]
        )
        print(_write_json(out, report))
        print(atomic_write_bytes(out.with_suffix(".md"), format_bench_markdown(report, command).encode()))
        print(plot_bench(report, out.with_suffix(".png")))
    return 0


EXAMPLES: dict[str, str] = {
    "garsim": "garsim drape --canonical a.obj --target b.obj --garment g.obj --out draped.obj",
    "demo": "garsim demo --out demo_out",
    "view": "garsim view demo_out/walk_dress.npz   # then open http://127.0.0.1:8080",
    "drape": "garsim drape --canonical a.obj --target b.obj --garment g.obj --fabric silk --out draped.obj "
    "--png draped.png\n  garsim drape --canonical a.glb --target b.glb --garment g.glb --up y --units cm "
    "--out draped.glb\n  garsim drape --canonical a.obj --target bodies/ --garment g.obj --pinned auto --out draped/",
    "animate": "garsim animate --garment skirt.obj --motion walk --out walk.glb\n"
    "  garsim animate --garment skirt.obj --poses keyframes.json --interpolate 48 --out poses.usdc\n"
    "  garsim animate --garment g.obj --canonical a.obj --targets bodies/ --up y --units cm --out anim.pc2",
    "train": "garsim train --data ~/garsim-data/v4 --out runs/v1 --resolution low",
    "average": "garsim average --models garsim/weights runs/finetune/best --weights 0.5 0.5 --out runs/soup",
    "eval": "garsim eval --data ~/garsim-data/v4test --model runs/v1/best --splits test ood --out results.json",
    "bench": "garsim bench --sizes 600 2400 --out bench.json",
    "data": "garsim data info ~/garsim-data/v4",
    "generate": "garsim data generate --out ~/garsim-data/v4 --seed 0 --workers 2",
    "info": "garsim data info ~/garsim-data/v4 --json",
    "verify": "garsim data verify ~/garsim-data/v4",
}
"""One example per command, shown at the end of its ``--help``."""
MOTION_CHOICES: tuple[str, ...] = ("walk", "raise_arms", "turn", "sit_down")
"""The motion library (``garsim.bodies.poses.MOTIONS``, repeated here so that parsing imports no torch)."""


def _epilog(name: str) -> str:
    return "Example:\n  " + EXAMPLES[name]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="garsim", description=__doc__.split("\n\n")[0], epilog=_epilog("garsim"))
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    from garsim import __version__

    parser.add_argument("--version", action="version", version=f"garsim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, help_text: str, parent: argparse._SubParsersAction = sub) -> argparse.ArgumentParser:
        return parent.add_parser(name, help=help_text, description=help_text, epilog=_epilog(name))

    p = command(
        "demo",
        "drape six garment families on two body shapes in everyday poses; write OBJ, a PNG grid, and a walk "
        "animation as GLB, USDC and GIF",
    )
    p.add_argument("--out", default="demo_out", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the target poses")
    p.add_argument(
        "--vertices",
        type=int,
        default=800,
        help="garment resolution (vertices; the shipped model was trained and tested on ~4x decimated copies of "
        "300-2,500-vertex garments)",
    )
    p.add_argument("--frames", type=int, default=24, help="frames of the walk animation")
    p.set_defaults(func=cmd_demo)

    p = command("view", "interactive browser viewer of a drape or animation (needs garsim[view])")
    p.add_argument(
        "path",
        help="a .glb/.gltf or .usd/.usda/.usdc written by garsim, an .npz with 'frames' and 'faces' (optional "
        "'body_frames', 'body_faces', 'prior_frames'; `garsim animate --out x.npz` writes one with the prior), a .pc2, "
        "an OBJ, or a folder of OBJs",
    )
    p.add_argument("--port", type=int, default=8080, help="port (the next free one if taken)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (0.0.0.0: every interface)")
    p.add_argument(
        "--up",
        choices=("z", "y"),
        default=None,
        help="up axis of a .pc2 or OBJ input (default: as garsim wrote in the OBJ, else z; glTF and USD say their own)",
    )
    p.add_argument(
        "--units",
        choices=("m", "cm", "mm"),
        default=None,
        help="units of a .pc2 or OBJ input (default: as garsim wrote, else m)",
    )
    p.set_defaults(func=cmd_view)

    p = command("drape", "drape a garment mesh from a canonical body onto a target body (or several: batch mode)")
    p.add_argument(
        "--canonical",
        required=True,
        help="canonical body mesh (OBJ/PLY/GLB/glTF/OFF/STL/USD; a skinned USD body in its skeleton's rest pose)",
    )
    p.add_argument("--body-mesh", metavar="NAME", help=BODY_MESH_HELP.format(targets="--target"))
    p.add_argument("--garment-mesh", metavar="NAME", help=GARMENT_MESH_HELP)
    p.add_argument(
        "--target",
        required=True,
        nargs="+",
        metavar="TARGET",
        help="target body mesh(es), same topology as --canonical; several files or a folder (its meshes in name "
        "order, numbers by value: frame_2 before frame_10) drape the garment on each, --out then being a folder",
    )
    p.add_argument(
        "--garment",
        required=True,
        help="garment mesh draped on the canonical body; its UVs and normals (OBJ vt/vn, seams kept) go to the output",
    )
    p.add_argument("--fabric", default="cotton", type=fabric_arg, help=FABRIC_HELP)
    p.add_argument(
        "--pinned",
        metavar="FILE|auto",
        help="garment vertices that follow the prior exactly: a text file of vertex indices, or 'auto': the "
        "garment's top border loop(s) on the canonical body (after --up/--units): the waistband of skirts and "
        "trousers; the neckline (and the armholes of strapped tops) of garments hung from the shoulders",
    )
    p.add_argument(
        "--out",
        required=True,
        help=f"output garment mesh ({', '.join(MESH_OUTPUTS)}); with several targets a folder of <target name>.<ext>",
    )
    p.add_argument(
        "--format",
        choices=[e[1:] for e in MESH_OUTPUTS],
        help="file type of the outputs with several targets (default: the garment's, .gltf -> .glb)",
    )
    p.add_argument("--png", help="also render target body + draped garment to this PNG (with several targets: folder)")
    p.add_argument("--up", choices=("z", "y"), default="z", help="up axis of the input and output (Blender/glTF: y)")
    p.add_argument(
        "--units",
        choices=("m", "cm", "mm"),
        default="m",
        help="length unit of the input and output (a glTF/GLB output is in metres, as glTF requires)",
    )
    p.add_argument(
        "--y-up",
        action="store_true",
        help="write a Z-up result Y-up (Blender); implied by --up y, and always done for a glTF/GLB output",
    )
    p.add_argument("--prior-only", action="store_true", help="use the skinning prior, not the model")
    p.set_defaults(func=cmd_drape)

    p = command("animate", "drape a garment over a pose sequence; write GLB, USD, PC2 (+OBJ), MP4 or GIF")
    p.add_argument("--garment", required=True, help="garment mesh draped on the canonical body")
    p.add_argument("--motion", choices=MOTION_CHOICES, help="a motion of the library, on the default Anny body")
    p.add_argument("--frames", type=int, default=None, help=f"frames of a --motion (default {MOTION_FRAMES})")
    p.add_argument(
        "--poses",
        metavar="FILE",
        help="Anny poses per frame, on the default Anny body: a .json list of frames, each {bone: axis-angle "
        "[x, y, z] radians or 3x3/4x4 matrix} or {joint angle: degrees from the T-pose, e.g. hip_flexion_L}, or an "
        ".npz of one (T, 3)/(T, 3, 3)/(T, 4, 4) array per bone or (T,) per joint angle",
    )
    p.add_argument("--interpolate", type=int, metavar="N", help="resample the --poses keyframes to N frames (slerp)")
    p.add_argument(
        "--canonical",
        help="canonical body mesh (with --targets); a skinned .glb/.gltf is read in the pose it is stored in, so "
        "the animated --targets file itself can be its canonical body",
    )
    p.add_argument(
        "--targets",
        help="folder of target body OBJs (in name order, numbers by value), an .npz with 'vertices' (T, V, 3) "
        "(or an animate .npz's 'body_frames'), a .glb/.gltf whose body is animated (skin, shape keys or node "
        "motion; sampled at --fps from its first to its last key), a USD stage (time-sampled points, moving "
        "transforms or a UsdSkel skin, sampled at --fps, by default its own time codes per second; its declared "
        "axis and unit converted to --up/--units) or a .pc2 point cache of the canonical body",
    )
    p.add_argument("--animation", help="a .glb/.gltf --targets file's animation, by name or index (default: the first)")
    p.add_argument("--body-mesh", metavar="NAME", help=BODY_MESH_HELP.format(targets="--targets"))
    p.add_argument("--garment-mesh", metavar="NAME", help=GARMENT_MESH_HELP)
    p.add_argument("--fabric", default="cotton", type=fabric_arg, help=FABRIC_HELP)
    p.add_argument(
        "--pinned",
        metavar="FILE|auto",
        help="garment vertices that follow the prior exactly: a text file of vertex indices, or 'auto' (the "
        "garment's top border loops), as for `garsim drape`",
    )
    p.add_argument(
        "--up",
        choices=("z", "y"),
        default="z",
        help="up axis of the input meshes and of the PC2/OBJ output (USD declares it; glTF is always Y up)",
    )
    p.add_argument(
        "--units",
        choices=("m", "cm", "mm"),
        default="m",
        help="length unit of the input meshes and of the PC2/OBJ output (USD declares it; glTF is always metres)",
    )
    p.add_argument(
        "--fps",
        type=float,
        default=None,
        help=f"frames per second of the animation, at which a .glb/.gltf or USD --targets animation is sampled "
        f"(default {ANIMATION_FPS:g}; a USD --targets stage's own time codes per second)",
    )
    p.add_argument("--out", required=True, help=f"output file ({', '.join(ANIMATION_OUTPUTS)})")
    p.add_argument("--prior-only", action="store_true", help="use the skinning prior, not the model")
    _config_default(
        p.add_argument(
            "--smoothing",
            type=float,
            help="temporal smoothing of the network's correction to the prior, in frames (Gaussian std; 0: off); "
            "recorded in the output's metadata",
        ),
        "garsim.api",
        "SequenceConfig",
        "smoothing",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_animate)

    p = command("train", "train GarSim on a generated dataset (resumable; torchrun for DDP)")
    p.add_argument("--data", required=True, help="dataset folder made by `garsim data generate`")
    p.add_argument("--out", required=True, help="run folder: checkpoints, CSV log, best model")
    # unset values take TrainConfig's / LossWeights' defaults (garsim/train), declared once there
    trainer = ("garsim.train.trainer", "TrainConfig")
    _config_default(p.add_argument("--epochs", type=int, help="epochs"), *trainer, "epochs")
    _config_default(p.add_argument("--batch-size", type=int, help="samples per batch"), *trainer, "batch_size")
    _config_default(p.add_argument("--lr", type=float, help="peak learning rate (cosine decay)"), *trainer, "lr")
    _config_default(p.add_argument("--seed", type=int, help="seed"), *trainer, "seed")
    p.add_argument(
        "--resolution",
        choices=("low", "full", "both"),
        default="low",
        help="train on the ~4x decimated meshes (the paper's choice), the full ones, or both",
    )
    p.add_argument("--val-every", type=int, default=10, help="hold out every N-th training sequence")
    p.add_argument(
        "--families",
        nargs="+",
        choices=FAMILY_CHOICES,
        help="train (and validate) on these garment families only (default: all)",
    )
    p.add_argument(
        "--collision-start",
        type=int,
        default=None,
        help="epochs completed before the collision loss is on (0: from the start; default: when validation plateaus)",
    )
    losses = ("garsim.train.losses", "LossWeights")
    _config_default(
        p.add_argument("--collision-weight", type=float, help="α_col of Eq. 7 (the paper: 1)"), *losses, "col"
    )
    _config_default(
        p.add_argument("--collision-eps", type=float, help="ε of Eq. 6 in metres (margin kept off the body)"),
        *losses,
        "eps",
    )
    p.add_argument("--init", help="start from this trained model folder's weights (fine-tuning)")
    p.add_argument(
        "--head",
        choices=("direction_magnitude", "displacement", "position"),
        help="decoder head of a new model (default: GarSimConfig's, the paper's direction + magnitude)",
    )
    _config_default(
        p.add_argument("--direction-weight", type=float, help="weight of the direction term (direction head only)"),
        *losses,
        "dir",
    )
    _config_default(
        p.add_argument("--model", choices=MODEL_CHOICES, help="GarSim or the DeePSD-style baseline"), *trainer, "model"
    )
    _config_default(
        p.add_argument("--device", help="cpu (the documented path), cuda, cuda:N or auto (CUDA when present)"),
        *trainer,
        "device",
    )
    _config_default(
        p.add_argument(
            "--pair-weight",
            type=float,
            help="weight of the paired-fabric term (each paired group in one batch; garsim.train.pairs); 0: off",
        ),
        *losses,
        "pair",
    )
    _config_default(
        p.add_argument(
            "--pair-smooth",
            type=int,
            help="smoothing rounds over the mesh of the paired-fabric term's residual (its large-scale part only)",
        ),
        *losses,
        "pair_smooth",
    )
    _config_default(
        p.add_argument(
            "--fold-weight",
            type=float,
            help="weight of the fold-depth term: the prediction's mean fold angle against the simulation's; 0: off",
        ),
        *losses,
        "fold",
    )
    _config_default(
        p.add_argument(
            "--relative-l2",
            type=float,
            metavar="METRES",
            help="weigh each sample's L2 term by this over its prior's mean error (floored at a quarter of it), so "
            "tight garments count as much as loose ones; 0: off",
        ),
        *losses,
        "relative",
    )
    p.add_argument("--restart", action="store_true", help="ignore an existing checkpoint in --out")
    _config_default(p.add_argument("--threads", type=int, help="torch threads per process"), *trainer, "threads")
    _config_default(
        p.add_argument(
            "--remesh-copies",
            type=int,
            help="remeshed variants per training sample: its full mesh decimated to a random size between the low "
            "level's and 0.7x full, truth and prior carried over (validation is never augmented)",
        ),
        *trainer,
        "remesh_copies",
    )
    p.add_argument(
        "--mirror",
        action="store_true",
        help="also train on every training sample mirrored left to right (exact new ground truth: the physics is "
        "symmetric; validation is never augmented)",
    )
    p.add_argument(
        "--fabric-decoder-film",
        action="store_true",
        help="a FiLM of the node latents by the fabric before the decoder (GarSimConfig.fabric_decoder_film); with "
        "--init, added to that model's weights at zero",
    )
    p.add_argument(
        "--global-context",
        action="store_true",
        help="before each message-passing step, an MLP of the garment's pooled node latents added to every node "
        "(GarSimConfig.global_context); with --init, added to that model's weights at zero",
    )
    p.add_argument(
        "--target-surface",
        action="store_true",
        help="per vertex, the prior's offset from the target body's nearby surface, its normal and signed distance, "
        "encoded into the node latents (GarSimConfig.target_surface); with --init, added to that model's weights at "
        "zero",
    )
    p.add_argument(
        "--local-rotation",
        action="store_true",
        help="turn each vertex's decoded correction with the rotation that carries its template neighbourhood onto "
        "the prior's (GarSimConfig.local_rotation; no weights of its own); with --init, that model's weights read so",
    )
    p.add_argument(
        "--num-steps",
        type=int,
        help="message-passing steps L of a new model; with --init, steps appended to that model's, each the "
        "identity at first (default: GarSimConfig's, or the --init model's)",
    )
    p.add_argument(
        "--trainable",
        nargs="+",
        metavar="PREFIX",
        help="train only the parameters whose names start with these prefixes (e.g. processor.film), the rest "
        "frozen (default: all)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)

    p = command("average", "average saved models tensor by tensor (a model and its fine-tune: WiSE-FT)")
    p.add_argument("--models", nargs="+", required=True, help="two or more model folders of one config")
    p.add_argument("--weights", type=float, nargs="+", help="one weight each, summing to 1 (default: equal)")
    p.add_argument("--out", required=True, help="folder for the averaged model")
    p.set_defaults(func=cmd_average)

    p = command("eval", "the paper's metrics on a dataset split: GarSim vs the LBS prior")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--model", help="a trained model folder (default: the shipped model)")
    p.add_argument("--splits", nargs="+", default=["test", "ood"], help="dataset splits to score")
    p.add_argument("--refine", action="store_true", help="also score garsim+refine and prior+refine")
    p.add_argument("--resolution", choices=("low", "full"), default="low", help="mesh resolution scored")
    p.add_argument(
        "--by",
        nargs="+",
        type=_grouping,
        default=["family"],
        metavar="KEY",
        help=f"group the rows by these ({', '.join(GROUP_CHOICES)}, or two crossed as a/b, e.g. family/construction; "
        "each a set of rows beside 'all'; default: the garment family)",
    )
    p.add_argument(
        "--compare",
        metavar="MODEL",
        help="also score this model folder's raw network on the same samples: per group the mean difference with a "
        "95%% bootstrap interval over garment instances (is a difference more than noise?)",
    )
    p.add_argument("--out", help="write the results to this .json file")
    p.set_defaults(func=cmd_eval)

    p = command("bench", "end-to-end inference speed (one thread), optionally against Newton")
    p.add_argument("--model", help="a trained model folder (default: the shipped model)")
    p.add_argument("--sizes", type=int, nargs="+", default=[600, 2400], help="garment vertex counts")
    p.add_argument("--garment", default="skirt", help="garment family timed")
    p.add_argument("--repeats", type=int, default=9, help="timed repeats per size (the median is reported)")
    p.add_argument("--newton", action="store_true", help="also time the Newton simulation of the same drape")
    p.add_argument(
        "--cold-max",
        type=int,
        metavar="N",
        help="time the cold first call (garsim drape, shipped model, fresh process) only up to N vertices "
        "(0: none; default: every size)",
    )
    p.add_argument(
        "--newton-max",
        type=int,
        metavar="N",
        help="with --newton: simulate only the sizes up to N vertices (minutes each; default: every size)",
    )
    p.add_argument("--out", help="write the timings to this .json file, a .md table and a .png log-log plot beside it")
    p.set_defaults(func=cmd_bench)

    data = command("data", "ground-truth datasets: generate, info, verify").add_subparsers(
        dest="data_command", required=True, metavar="SUBCOMMAND"
    )
    p = command("generate", "simulate a dataset with Newton (resumable)", data)
    p.add_argument("--out", required=True, help="dataset folder (outside the source tree)")
    p.add_argument("--seed", type=int, default=0, help="seed of every job")
    # unset values take physics.generate.GenerateConfig's defaults (not imported here: the simulator stays off the
    # CLI's inference path; `garsim data generate` prints the settings it used in DIR/config.json)
    gen = ("garsim.physics.generate", "GenerateConfig")
    _config_default(p.add_argument("--train", type=int, help="training jobs (garment instances)"), *gen, "num_train")
    _config_default(
        p.add_argument("--test", type=int, help="test jobs: unseen instances, bodies, poses"), *gen, "num_test"
    )
    _config_default(
        p.add_argument("--ood", type=int, help="out-of-distribution jobs: parameters outside every training range"),
        *gen,
        "num_ood",
    )
    _config_default(
        p.add_argument("--min-vertices", type=int, help="garment resolution, lower end"), *gen, "min_vertices"
    )
    _config_default(
        p.add_argument("--max-vertices", type=int, help="garment resolution, upper end"), *gen, "max_vertices"
    )
    _config_default(
        p.add_argument(
            "--targets",
            type=int,
            help="target poses per job, chained, each settled (a chained state depends on the path: 1)",
        ),
        *gen,
        "targets_per_job",
    )
    _config_default(
        p.add_argument(
            "--strap-pins",
            choices=STRAP_CHOICES,
            help="how parametric tops and dresses are held: their bodice's top ring (their straps slide) or pins where "
            "the straps cross the shoulders, skinned by the torso (docs/studies/anatomy.md)",
        ),
        *gen,
        "strap_pins",
    )
    p.add_argument("--workers", type=int, default=2, help="parallel simulation processes")
    p.add_argument("--shard", type=_shard, default=(0, 1), help="K/N: run every N-th job from K")
    p.add_argument("--limit", type=int, help="stop after this many jobs (smoke runs)")
    p.add_argument(
        "--paired-first",
        action="store_true",
        help="run the paired-fabric groups before the other jobs (the same dataset, in another order)",
    )
    p.add_argument(
        "--reuse",
        metavar="DIR",
        help="a dataset folder of the same seed: copy its finished jobs that these settings would simulate alike "
        "(e.g. all but the parametric tops and dresses when only --strap-pins differs) instead of simulating them",
    )
    p.add_argument(
        "--no-graphs",
        action="store_true",
        help="launch every kernel from Python instead of replaying captured substeps (same results, slower)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_data_generate)
    p = command("info", "counts per split / family / fabric / pose, acceptance, cost, ranges", data)
    p.add_argument("dir", help="dataset folder")
    p.add_argument("--json", action="store_true", help="print everything as JSON")
    p.set_defaults(func=cmd_data_info)
    p = command("verify", "find missing, truncated or corrupt files", data)
    p.add_argument("dir", help="dataset folder")
    p.set_defaults(func=cmd_data_verify)
    return parser


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) if str(exc).strip() else type(exc).__name__


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command in SINGLE_THREAD_COMMANDS:  # before numpy and torch load (see the module docstring)
        for var in _THREAD_VARS:
            os.environ.setdefault(var, "1")
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # the reader of stdout went away (`garsim data info DIR | head`): stop quietly
        with contextlib.suppress(OSError, ValueError):  # nor complain when Python flushes stdout at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except _USER_ERRORS as exc:
        print(f"garsim {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"garsim {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
