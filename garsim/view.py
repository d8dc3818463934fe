"""``garsim view``: an interactive browser viewer (viser) for drapes and animations.

Reads a ``.glb``/``.gltf`` (garsim.export's animations frame by frame, or any glTF scene sampled over its first
animation: node transforms, skins and morph targets applied, :mod:`garsim.geometry.gltf_scene`), a USD stage
(``.usd``/``.usda``/``.usdc``/``.usdz``: time-sampled or skinned points, through the prims' transforms, in its
declared axis and unit), an ``.npz`` with ``frames`` (T, N, 3) and ``faces`` (optional ``body_frames`` (T, Vb, 3) or
(Vb, 3), ``body_faces``, ``prior_frames`` (T, N, 3), ``fps``), a ``.pc2`` (+ the OBJ beside it, and
``<stem>_body.pc2``), one mesh file, or a folder of OBJs (one sequence in name order, numbers by value; files whose
name contains ``body`` / ``prior`` are the body / the prior); a .pc2 or OBJ in the ``up`` axis and ``units`` given,
else as garsim's metadata line in the OBJ says, else Z-up metres. The page has a frame slider with play, body and
garment toggles and, when a prior is present, a prior-vs-prediction toggle and the correction ``|prediction - prior|``
as vertex colour.

viser is an optional extra (``pip install 'garsim[view]'``), imported only by :func:`serve`.
"""

from __future__ import annotations

import itertools
import json
import re
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garsim.geometry.io import USD_EXTENSIONS, to_internal
from garsim.geometry.mesh import vertex_normals

VIEWER_NEEDS = "garsim view needs viser: pip install 'garsim[view]'"
GARMENT_RGB = (0.23, 0.46, 0.69)
BODY_RGB = (200, 200, 200)


class ViewerUnavailable(RuntimeError):
    """viser is not installed."""


@dataclass
class ViewData:
    """A garment sequence (Z up, metres) with an optional body sequence and prior."""

    frames: np.ndarray  # (T, N, 3) float32
    faces: np.ndarray  # (F, 3) int64
    body_frames: np.ndarray | None = None  # (T, Vb, 3)
    body_faces: np.ndarray | None = None
    prior_frames: np.ndarray | None = None  # (T, N, 3)
    fps: float = 30.0
    name: str = ""

    def __post_init__(self) -> None:
        f = np.asarray(self.frames, dtype=np.float32)
        if f.ndim == 2:
            f = f[None]
        if f.ndim != 3 or f.shape[-1] != 3 or len(f) == 0:
            raise ValueError(f"{self.name}: garment frames must have shape (T, N, 3), got {np.shape(self.frames)}")
        self.frames = f
        self.faces = _faces(self.faces, f.shape[1], f"{self.name}: garment faces")
        if self.body_frames is not None:
            if self.body_faces is None:
                raise ValueError(f"{self.name}: body frames without body faces")
            b = np.asarray(self.body_frames, dtype=np.float32)
            b = np.broadcast_to(b, (len(f), *b.shape)) if b.ndim == 2 else b
            if b.ndim != 3 or b.shape[-1] != 3 or len(b) != len(f):
                raise ValueError(f"{self.name}: body frames must have shape ({len(f)}, Vb, 3), got {b.shape}")
            self.body_frames = b
            self.body_faces = _faces(self.body_faces, b.shape[1], f"{self.name}: body faces")
        if self.prior_frames is not None:
            p = np.asarray(self.prior_frames, dtype=np.float32)
            p = p[None] if p.ndim == 2 else p
            if p.shape != f.shape:
                raise ValueError(f"{self.name}: prior frames must have the garment's shape {f.shape}, got {p.shape}")
            self.prior_frames = p
        for what, a in (("garment", f), ("body", self.body_frames), ("prior", self.prior_frames)):
            if a is not None and not np.isfinite(a).all():
                raise ValueError(f"{self.name}: the {what} frames hold NaN or infinite values")
        if not (np.isfinite(self.fps) and self.fps > 0):
            self.fps = 30.0

    @property
    def num_frames(self) -> int:
        return int(self.frames.shape[0])

    def save_npz(self, path: str | Path) -> Path:
        """Write the sequence (atomically) as the ``.npz`` that ``load_npz`` (and ``garsim view``) reads; returns the
        path."""
        from garsim.atomic import atomic_write

        arrays = {"frames": self.frames, "faces": self.faces, "fps": np.float32(self.fps)}
        optional = {"body_frames": self.body_frames, "body_faces": self.body_faces, "prior_frames": self.prior_frames}
        arrays.update({k: v for k, v in optional.items() if v is not None})

        def write(tmp: str) -> None:
            with open(tmp, "wb") as fh:  # a file object: np.savez would add ".npz" to the temporary name
                np.savez_compressed(fh, **arrays)

        return atomic_write(path, write)

    def correction(self) -> np.ndarray | None:
        """|prediction - prior| per frame and vertex (T, N), metres; None without a prior."""
        if self.prior_frames is None:
            return None
        return np.linalg.norm(self.frames - self.prior_frames, axis=-1)


def _faces(faces: Any, n: int, what: str) -> np.ndarray:
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu":
        raise ValueError(f"{what} must be an (F, 3) integer array, got shape {f.shape} of {f.dtype}")
    if f.size and (f.min() < 0 or f.max() >= n):
        raise ValueError(f"{what} index vertices outside 0..{n - 1}")
    return f.astype(np.int64)


# ----------------------------------------------------------------------------- readers


def load_gltf(path: str | Path) -> ViewData:
    """A .glb/.gltf written by garsim.export, or any glTF scene: its meshes as they show (node transforms, skins,
    morph targets), sampled over its first animation at the file's ``extras.fps`` (else 30); the mesh named like
    ``body`` is the body, like ``prior`` the prior, the first other mesh the garment."""
    from garsim.geometry.gltf_scene import GltfScene
    from garsim.geometry.io import y_up_to_z_up

    p = Path(path)
    scene = GltfScene.read(p)
    roles: dict[str, Any] = {}
    for inst in scene.instances:
        name = inst.name.lower()
        roles.setdefault("body" if "body" in name else "prior" if "prior" in name else "garment", inst)
    if "garment" not in roles:
        roles["garment"] = scene.instances[0]
    extras = scene.doc.get("extras") or {}
    fps = float(extras.get("fps", 30.0))
    if scene.animations:
        verts = scene.frames(fps)
    else:
        verts = scene.vertices()[None]
    if str(extras.get("up", "Y")).upper() != "Z":
        verts = y_up_to_z_up(verts)
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for role, inst in roles.items():
        index, faces = scene.instance_part(inst)
        out[role] = verts[:, index].astype(np.float32), faces
    frames, faces = out["garment"]
    body = out.get("body")
    prior = out.get("prior")
    return ViewData(
        frames,
        faces,
        body_frames=None if body is None else body[0],
        body_faces=None if body is None else body[1],
        prior_frames=None if prior is None else prior[0],
        fps=fps,
        name=p.name,
    )


def load_npz(path: str | Path) -> ViewData:
    p = Path(path)
    with np.load(p, allow_pickle=False) as z:
        missing = [k for k in ("frames", "faces") if k not in z.files]
        if missing:
            raise ValueError(
                f"{p}: needs arrays 'frames' (T, N, 3) and 'faces' (F, 3); missing {missing} (has {sorted(z.files)})"
            )
        get = {k: z[k] for k in z.files}
    return ViewData(
        get["frames"],
        get["faces"],
        body_frames=get.get("body_frames"),
        body_faces=get.get("body_faces"),
        prior_frames=get.get("prior_frames"),
        fps=float(get.get("fps", 30.0)),
        name=p.name,
    )


_FRAME_NUMBER = re.compile(r"[_\-.]?\d+$")


def load_obj_folder(path: str | Path, up: str | None = None, units: str | None = None) -> ViewData:
    """A folder of OBJs, one sequence in name order (numbers by value); names with ``body`` / ``prior`` are the body
    / the prior; in ``up`` axis and ``units`` (default: as garsim's metadata in the first OBJ says, else Z-up m)."""
    from garsim.geometry.io import load_mesh, natural_order

    p = Path(path)
    files = natural_order(q for q in p.iterdir() if q.suffix.lower() == ".obj")  # frame_2 before frame_10
    if not files:
        raise ValueError(f"{p}: no .obj files in the folder")
    groups: dict[str, list[Path]] = {}
    for q in files:
        groups.setdefault(_FRAME_NUMBER.sub("", q.stem), []).append(q)
    roles: dict[str, list[tuple[str, list[Path]]]] = {"garment": [], "body": [], "prior": []}
    for stem, qs in groups.items():
        low = stem.lower()
        roles["body" if "body" in low else "prior" if "prior" in low else "garment"].append((stem, qs))
    for role, entries in roles.items():
        if len(entries) > 1:
            names = ", ".join(stem for stem, _ in entries)
            raise ValueError(
                f"{p}: the folder holds several {role} meshes ({names}), not one sequence; "
                "view one file, or put one sequence per folder"
            )
    if not roles["garment"]:
        raise ValueError(f"{p}: no garment OBJs (only body/prior files)")

    def read(entries: list[tuple[str, list[Path]]]) -> tuple[np.ndarray, np.ndarray] | None:
        if not entries:
            return None
        stem, paths = entries[0]
        meshes = [load_mesh(q) for q in paths]
        sizes = {len(v) for v, _ in meshes}
        if len(sizes) > 1:
            raise ValueError(
                f"{p}: the '{stem}' OBJs differ in vertex count {sorted(sizes)}; a sequence shares one mesh"
            )
        return to_internal(np.stack([v for v, _ in meshes]), *axes), meshes[0][1]

    axes = _obj_axes(roles["garment"][0][1][0], up, units)
    garment = read(roles["garment"])
    assert garment is not None
    frames, faces = garment
    body, prior = read(roles["body"]), read(roles["prior"])
    if body is not None and len(body[0]) == 1:
        body = (np.repeat(body[0], len(frames), axis=0), body[1])
    if body is not None and len(body[0]) != len(frames):
        raise ValueError(f"{p}: {len(frames)} garment OBJs but {len(body[0])} body OBJs")
    return ViewData(
        frames,
        faces,
        body_frames=None if body is None else body[0],
        body_faces=None if body is None else body[1],
        prior_frames=None if prior is None else prior[0],
        name=p.name,
    )


def load_usd(path: str | Path) -> ViewData:
    """A USD stage: the mesh named ``Garment`` (else the first mesh) and ``Body`` if there is one (as
    :mod:`garsim.export` writes them), their time-sampled or skinned points converted from the stage's upAxis and
    metersPerUnit to Z-up metres, one frame per time code (:mod:`garsim.geometry.usd_stage`)."""
    from garsim.geometry.usd_stage import mesh_frames, open_stage, to_z_up_metres

    p = Path(path)
    stage, prims = open_stage(p)
    names: dict[str, Any] = {}
    for prim in prims:
        names.setdefault(prim.GetName(), prim)
    garment = names.get("Garment", prims[0])
    frames, faces = mesh_frames(stage, garment, p.name)
    body = None
    if "Body" in names and names["Body"] != garment:
        body = mesh_frames(stage, names["Body"], p.name)
    if body is not None and len(body[0]) == 1 < len(frames):  # a body held still
        body = (np.broadcast_to(body[0], (len(frames), *body[0].shape[1:])), body[1])
    elif body is not None and len(body[0]) != len(frames):
        raise ValueError(f"{p.name}: the Body has {len(body[0])} frames, the Garment {len(frames)}")
    return ViewData(
        to_z_up_metres(stage, frames),
        faces,
        body_frames=None if body is None else to_z_up_metres(stage, body[0]),
        body_faces=None if body is None else body[1],
        fps=float(stage.GetTimeCodesPerSecond()),
        name=p.name,
    )


def _obj_axes(obj: Path, up: str | None, units: str | None) -> tuple[str, str]:
    """(up, units) of OBJ-based input: as given, else as the garsim metadata line of ``obj`` says (``input_up``,
    ``input_units``: what ``garsim animate`` wrote), else Z-up metres."""
    from garsim.geometry.io import read_obj_metadata

    meta = read_obj_metadata(obj) if (up is None or units is None) and obj.is_file() else {}
    return up or str(meta.get("input_up", "z")), units or str(meta.get("input_units", "m"))


def load_view_data(path: str | Path, up: str | None = None, units: str | None = None) -> ViewData:
    """Read any input of ``garsim view`` (see the module doc). ``up`` and ``units`` describe a .pc2, OBJ or other
    mesh file (default: garsim's metadata in the OBJ, else Z-up metres); glTF, USD and .npz carry their own."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if p.is_dir():
        return load_obj_folder(p, up, units)
    ext = p.suffix.lower()
    if ext in (".glb", ".gltf"):
        return load_gltf(p)
    if ext == ".npz":
        return load_npz(p)
    if ext in USD_EXTENSIONS:
        return load_usd(p)
    if ext == ".pc2":
        from garsim.export import read_pc2
        from garsim.geometry.io import load_mesh

        frames, _, _ = read_pc2(p)
        obj = p.with_suffix(".obj")
        if not obj.exists():
            raise FileNotFoundError(f"{p}: the PC2 needs its mesh beside it ({obj.name})")
        axes = _obj_axes(obj, up, units)
        faces = load_mesh(obj)[1]
        body_pc2 = p.with_name(f"{p.stem}_body.pc2")
        body = None
        if body_pc2.exists() and body_pc2.with_suffix(".obj").exists():
            body = (to_internal(read_pc2(body_pc2)[0], *axes), load_mesh(body_pc2.with_suffix(".obj"))[1])
        return ViewData(
            to_internal(frames, *axes),
            faces,
            body_frames=None if body is None else body[0],
            body_faces=None if body is None else body[1],
            name=p.name,
        )
    from garsim.geometry.io import load_mesh

    v, f = load_mesh(p)
    axes = _obj_axes(p, up, units) if ext == ".obj" else (up or "z", units or "m")
    return ViewData(to_internal(v, *axes)[None], f, name=p.name)


# ----------------------------------------------------------------------------- the viewer


def colored_glb(vertices: np.ndarray, faces: np.ndarray, rgb: np.ndarray) -> bytes:
    """A one-mesh GLB with per-vertex colours (float RGB in [0, 1]), smooth normals, double-sided."""
    from garsim.export.gltf import _ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER, _Builder, _glb

    b = _Builder()
    attributes = {
        "POSITION": b.add(vertices.astype(np.float32), "VEC3", _ARRAY_BUFFER, bounds=True),
        "NORMAL": b.add(vertex_normals(vertices.astype(np.float64), faces).astype(np.float32), "VEC3", _ARRAY_BUFFER),
        "COLOR_0": b.add(np.clip(rgb, 0.0, 1.0).astype(np.float32), "VEC3", _ARRAY_BUFFER),
    }
    indices = b.add(faces.astype(np.uint32).ravel(), "SCALAR", _ELEMENT_ARRAY_BUFFER)
    doc = {
        "asset": {"version": "2.0", "generator": "garsim.view"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "garment", "mesh": 0}],
        "meshes": [
            {
                "name": "garment",
                "primitives": [{"attributes": attributes, "indices": indices, "mode": 4, "material": 0}],
            }
        ],
        "materials": [
            {
                "name": "garment",
                "doubleSided": True,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.85,
                },
            }
        ],
        "accessors": b.accessors,
        "bufferViews": b.buffer_views,
        "buffers": [{"byteLength": b.offset}],
    }
    return _glb(doc, b.blob())


class Viewer:
    """The viser scene and GUI for one :class:`ViewData`; ``show(k)`` displays frame k."""

    def __init__(self, data: ViewData, server: Any) -> None:
        self.data = data
        self.server = server
        self.frame = 0
        self._lock = threading.RLock()
        self._stop = threading.Event()
        corr = data.correction()
        self.correction = corr
        # colour scale: 0 .. the 99th percentile of the correction over the whole sequence (at least 1 mm)
        self.vmax = max(float(np.percentile(corr, 99)), 1e-3) if corr is not None else 1.0

        scene, gui = server.scene, server.gui
        scene.set_up_direction("+z")
        lo, hi = data.frames[0].min(axis=0), data.frames[0].max(axis=0)
        if data.body_frames is not None:
            lo = np.minimum(lo, data.body_frames[0].min(axis=0))
            hi = np.maximum(hi, data.body_frames[0].max(axis=0))
        center = 0.5 * (lo + hi)
        dist = 1.6 * float(max(hi - lo)) + 0.5
        server.initial_camera.look_at = tuple(float(x) for x in center)
        server.initial_camera.position = (float(center[0]) + 0.35 * dist, float(center[1]) - dist, float(center[2]))
        scene.add_grid("/ground", width=4.0, height=4.0, position=(float(center[0]), float(center[1]), float(lo[2])))

        t = data.num_frames
        gui.add_markdown(
            f"**{data.name or 'garsim'}**: {t} frame{'s' * (t != 1)}, {data.frames.shape[1]} garment vertices"
        )
        self.slider = gui.add_slider("frame", min=0, max=max(t - 1, 1), step=1, initial_value=0, disabled=t < 2)
        self.play = gui.add_checkbox("play", initial_value=False, disabled=t < 2)
        self.fps = gui.add_number("fps", initial_value=float(round(data.fps, 3)), min=1.0, max=120.0, step=1.0)
        self.show_garment = gui.add_checkbox("garment", initial_value=True)
        self.show_body = gui.add_checkbox("body", initial_value=True) if data.body_frames is not None else None
        self.show_prior = self.color_by_correction = None
        self.legend = None
        if corr is not None:
            self.show_prior = gui.add_checkbox("show prior (not prediction)", initial_value=False)
            self.color_by_correction = gui.add_checkbox("colour: |prediction - prior|", initial_value=True)
            self.legend = gui.add_markdown("")

        self.body = None
        if data.body_frames is not None:
            self.body = scene.add_mesh_simple(
                "/body", data.body_frames[0], data.body_faces, color=BODY_RGB, side="double"
            )
        self.garment: Any = None
        self._render_garment()

        self.slider.on_update(lambda _: self.show(int(self.slider.value)))
        for handle in (self.show_garment, self.show_body, self.show_prior, self.color_by_correction):
            if handle is not None:
                handle.on_update(lambda _: self.show(self.frame))
        self._player = threading.Thread(target=self._play_loop, name="garsim-view-play", daemon=True)
        self._player.start()

    # -- drawing
    def garment_vertices(self, k: int) -> np.ndarray:
        use_prior = self.show_prior is not None and bool(self.show_prior.value)
        return (self.data.prior_frames if use_prior else self.data.frames)[k]  # type: ignore[index]

    def garment_colors(self, k: int) -> np.ndarray:
        n = self.data.frames.shape[1]
        if self.correction is None or self.color_by_correction is None or not self.color_by_correction.value:
            return np.tile(np.asarray(GARMENT_RGB, dtype=np.float32), (n, 1))
        from matplotlib import colormaps

        return colormaps["viridis"](np.clip(self.correction[k] / self.vmax, 0.0, 1.0))[:, :3].astype(np.float32)

    def _render_garment(self) -> None:
        k = self.frame
        glb = colored_glb(self.garment_vertices(k), self.data.faces, self.garment_colors(k))
        self.garment = self.server.scene.add_glb("/garment", glb, visible=bool(self.show_garment.value))
        if self.legend is not None and self.correction is not None:
            c = self.correction[k]
            self.legend.content = (
                f"correction at frame {k}: mean {1000 * c.mean():.1f} mm, max "
                f"{1000 * c.max():.1f} mm; colour scale 0 (dark) .. {1000 * self.vmax:.1f} mm "
                "(yellow)"
            )

    def show(self, k: int) -> None:
        """Display frame ``k`` (clamped) with the current toggles."""
        with self._lock:
            self.frame = int(np.clip(k, 0, self.data.num_frames - 1))
            self._render_garment()
            if self.body is not None and self.show_body is not None:
                self.body.vertices = self.data.body_frames[self.frame]  # type: ignore[index]
                self.body.visible = bool(self.show_body.value)

    def _play_loop(self) -> None:
        while not self._stop.is_set():
            if self.play.value and self.data.num_frames > 1:
                t0 = time.perf_counter()
                self.slider.value = (int(self.slider.value) + 1) % self.data.num_frames
                fps = float(self.fps.value) if self.fps.value else 30.0
                self._stop.wait(max(1.0 / max(fps, 1.0) - (time.perf_counter() - t0), 0.0))
            else:
                self._stop.wait(0.05)

    # -- lifetime
    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        host = self.server.get_host()
        return f"http://{'127.0.0.1' if host in ('0.0.0.0', '') else host}:{self.port}"

    def stop(self) -> None:
        self._stop.set()
        self._player.join(timeout=2.0)
        self.server.stop()


def _import_viser() -> Any:
    try:
        import viser
    except ImportError:
        raise ViewerUnavailable(VIEWER_NEEDS) from None
    return viser


def serve(
    path: str | Path,
    host: str = "127.0.0.1",
    port: int = 8080,
    block: bool = True,
    up: str | None = None,
    units: str | None = None,
) -> Viewer:
    """Serve ``path`` in the browser at http://host:port (the next free port if taken) -> the :class:`Viewer`.

    ``block=True`` runs until Ctrl-C, then stops the server; ``block=False`` returns at once (call
    ``viewer.stop()``; ``viewer.server`` is the ``viser.ViserServer``). ``up``, ``units``: as :func:`load_view_data`.
    """
    data = load_view_data(path, up, units)  # bad input fails before a server starts
    viser = _import_viser()
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:
        viewer = Viewer(data, server)
    except BaseException:
        server.stop()
        raise
    if block:
        print(f"garsim view: {data.name} ({data.num_frames} frames) at {viewer.url}  (Ctrl-C to stop)", flush=True)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        finally:
            viewer.stop()
    return viewer


BROWSERS: tuple[str, ...] = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
"""Executables :func:`screenshot` looks for (``GARSIM_CHROMIUM`` names another)."""


def find_browser() -> str | None:
    """A headless-capable Chromium on this machine (``$GARSIM_CHROMIUM`` first), or None."""
    import os
    import shutil

    for name in (os.environ.get("GARSIM_CHROMIUM"), *BROWSERS):
        if name and (path := shutil.which(name)):
            return path
    return None


_CDP_IDS = itertools.count(1)


def _cdp(ws: Any, method: str, params: dict | None = None) -> dict:
    """One DevTools protocol call: send, then skip events until its answer."""
    call = next(_CDP_IDS)
    ws.send(json.dumps({"id": call, "method": method, "params": params or {}}))
    while True:
        msg = json.loads(ws.recv())
        if msg.get("id") == call:
            if "error" in msg:
                raise RuntimeError(f"{method}: {msg['error'].get('message', msg['error'])}")
            return msg.get("result", {})


def screenshot(
    url: str,
    path: str | Path,
    width: int = 1280,
    height: int = 800,
    ready_text: str | None = "garment vertices",
    settle: float = 3.0,
    timeout: float = 120.0,
    browser: str | None = None,
) -> Path:
    """Load ``url`` (a running viewer) in headless Chromium with software WebGL (SwiftShader), wait until the page
    shows ``ready_text`` (viser's panel has arrived) and ``settle`` seconds more (meshes decoded and drawn), close
    notifications, wait until two captures a second apart agree (or ``timeout``), and write a ``width`` x ``height``
    PNG to ``path``. Nothing is downloaded; without a Chromium (``apt-get install chromium``) this raises
    :class:`ViewerUnavailable`. Driven through the DevTools protocol with ``websockets`` (a viser dependency)."""
    import base64
    import os
    import shutil
    import socket
    import subprocess
    import tempfile
    import urllib.request

    from websockets.sync.client import connect

    from garsim.atomic import atomic_write_bytes

    exe = browser or find_browser()
    if exe is None:
        raise ViewerUnavailable(
            "no Chromium found for the screenshot: apt-get install chromium (or set GARSIM_CHROMIUM)"
        )
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    profile = tempfile.mkdtemp(prefix="garsim-chromium-")
    args = [
        exe,
        "--headless=new",
        f"--remote-debugging-port={port}",
        f"--user-data-dir={profile}",
        f"--window-size={width},{height}",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--hide-scrollbars",
        "--no-first-run",
        "--no-default-browser-check",
        "--disable-extensions",
        "--disable-background-networking",
        "about:blank",
    ]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        args.insert(1, "--no-sandbox")  # Chromium refuses to run as root with its sandbox
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + timeout
    try:
        ws_url = None
        while ws_url is None:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{exe} did not start its DevTools endpoint (exit status {proc.poll()})")
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=2) as r:
                    pages = [t for t in json.load(r) if t.get("type") == "page"]
                ws_url = pages[0]["webSocketDebuggerUrl"] if pages else None
            except OSError:
                pass
            if ws_url is None:
                time.sleep(0.2)
        with connect(ws_url, max_size=None, open_timeout=30) as ws:
            _cdp(
                ws,
                "Emulation.setDeviceMetricsOverride",
                {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
            )
            _cdp(ws, "Page.navigate", {"url": url})
            check = f"document.body !== null && document.body.innerText.includes({json.dumps(ready_text or '')})"
            while not _cdp(ws, "Runtime.evaluate", {"expression": check}).get("result", {}).get("value"):
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{url} did not show {ready_text!r} within {timeout:.0f} s")
                time.sleep(0.25)
            time.sleep(settle)
            close = (
                "document.querySelectorAll('.mantine-Notification-closeButton, [class*=Notification] button')"
                ".forEach(b => b.click())"
            )
            _cdp(ws, "Runtime.evaluate", {"expression": close})
            # then until two captures a second apart agree: software WebGL on busy cores can take longer than
            # ``settle`` to decode and draw the meshes (a test's capture once showed the empty grid)
            data, previous = None, None
            while data is None or (data != previous and time.monotonic() < deadline):
                time.sleep(0.5 if data is None else 1.0)
                previous, data = data, _cdp(ws, "Page.captureScreenshot", {"format": "png"})["data"]
        return atomic_write_bytes(path, base64.b64decode(data))
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        shutil.rmtree(profile, ignore_errors=True)
