"""Anny's skinning (faces, bone indices and weights), cached on disk so that matching a user's mesh pair
against the Anny topology needs neither torch nor Anny's model build (~1-3 s per process otherwise).

The rig is phenotype-independent: it is built once from ``AnnyBody`` and stored under the Anny cache folder
(``$XDG_CACHE_HOME/garsim/anny/rig-<topology>-anny<version>.npz``), keyed by the installed Anny version.
A missing, stale or unreadable cache file is rebuilt; nothing is downloaded.
"""

from __future__ import annotations

import io
import logging
from functools import lru_cache
from pathlib import Path

import numpy as np

ANNY_VERTICES = 13718
"""Vertices of the default 'anny' topology (the only one matched by vertex count)."""

log = logging.getLogger(__name__)


def _anny_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("anny")
    except PackageNotFoundError:  # pragma: no cover - anny is a dependency
        return "unknown"


def rig_cache_path(topology: str = "anny") -> Path:
    """Where the rig of ``topology`` is cached for the installed Anny version."""
    from garsim.paths import anny_cache_dir

    return anny_cache_dir() / f"rig-{topology}-anny{_anny_version()}.npz"


ROOT_BONES = ("root", "pelvis.L", "pelvis.R")
"""Anny's bones above every joint that garsim's poses turn (``bodies.poses``: legs, spine, arms, neck): in every
training sample they stay where the canonical body has them, so the skin they carry places the target body's root."""


def _build(topology: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray]:
    from garsim.bodies.anny import AnnyBody

    body = AnnyBody(topology=topology)
    root = np.isin(body.skin_indices, [body.bone_labels.index(b) for b in ROOT_BONES])
    root_weight = (np.asarray(body.skin_weights, dtype=np.float64) * root).sum(axis=1)
    return body.faces, body.skin_indices, body.skin_weights, len(body.bone_labels), root_weight


def _read(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray] | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            faces, indices, weights = z["faces"], z["skin_indices"], z["skin_weights"]
            num_bones, root_weight = int(z["num_bones"]), z["root_weight"]
    except Exception as exc:  # noqa: BLE001 - truncated (BadZipFile), foreign or partial file: rebuild it
        log.info("rebuilding the Anny rig cache %s (%s)", path, exc)
        return None
    ok = (
        faces.ndim == 2
        and faces.shape[1] == 3
        and indices.shape == weights.shape
        and indices.ndim == 2
        and (indices.size == 0 or 0 <= indices.min() <= indices.max() < num_bones)
        and root_weight.shape == (len(indices),)
    )
    if not ok:
        return None
    return faces.astype(np.int64), indices.astype(np.int64), weights.astype(np.float64), num_bones, root_weight


@lru_cache(maxsize=4)
def anny_rig(topology: str = "anny") -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray]:
    """(faces, skin_indices, skin_weights, num_bones, root_weight) of an Anny topology (phenotype-independent;
    ``root_weight``: each vertex's skinning weight on ``ROOT_BONES``), from the disk cache when present (built from
    ``AnnyBody`` and stored otherwise; a cache without a field is rebuilt)."""
    path = rig_cache_path(topology)
    rig = _read(path) if path.exists() else None
    if rig is not None:
        return rig
    rig = _build(topology)
    faces, indices, weights, num_bones, root_weight = rig
    buf = io.BytesIO()
    np.savez(
        buf,
        faces=faces,
        skin_indices=indices,
        skin_weights=weights,
        num_bones=np.int64(num_bones),
        root_weight=root_weight,
    )
    try:
        from garsim.atomic import atomic_write_bytes

        atomic_write_bytes(path, buf.getvalue())
    except OSError as exc:  # a read-only cache still gives the rig, only slower next time
        log.warning("could not cache the Anny rig at %s: %s", path, exc)
    return rig


def match_anny_rig(num_vertices: int, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Skinning of the Anny topology that ``faces`` belongs to, or None for any other mesh."""
    if num_vertices != ANNY_VERTICES:  # the default 'anny' topology; others are not matched by vertex count
        return None
    rig_faces, indices, weights, num_bones, _ = anny_rig("anny")
    if not same_quads(np.asarray(faces), rig_faces):
        return None
    return indices, weights, num_bones


ROOT_REGION_WEIGHT = 0.2
"""Skinning weight on ``ROOT_BONES`` from which a vertex belongs to the root region: 181 vertices around the pelvis
(Anny's largest such weight is 0.52; at 0.3, 97 vertices). Over v5test's poses they move 2 mm (median, 10 mm at most)
and turn under 3 degrees about the vertical between the canonical and the target body."""


def anny_root_region(num_vertices: int, faces: np.ndarray) -> np.ndarray | None:
    """(V,) bool: the root region (``ROOT_REGION_WEIGHT``) of a body in the Anny topology, or None for any other."""
    if match_anny_rig(num_vertices, faces) is None:
        return None
    return anny_rig("anny")[4] >= ROOT_REGION_WEIGHT


MAX_FLIPPED_SHARE = 0.01
"""Largest share of triangles whose quad may be split along the other diagonal in a matching mesh."""


def same_quads(faces: np.ndarray, reference: np.ndarray) -> bool:
    """Whether ``faces`` is ``reference`` up to quads split along the other diagonal (at most
    ``MAX_FLIPPED_SHARE`` of the triangles). Anny splits each quad on its shorter diagonal, and near-ties fall either
    way with the float arithmetic of the machine (12 of Anny's 27,420 triangles differ between two of ours), so a body
    exported on one machine must still match the rig built on another: the skinning is per vertex, so a flipped
    diagonal changes nothing it needs. A flipped quad is two consecutive rows with the same four vertices."""
    if faces.shape != reference.shape:
        return False
    differ = np.flatnonzero((faces != reference).any(axis=1))
    if len(differ) == 0:
        return True
    if len(differ) > MAX_FLIPPED_SHARE * len(faces) or len(differ) % 2 or np.any(differ[1::2] != differ[0::2] + 1):
        return False
    quads = np.stack([differ[0::2], differ[1::2]], axis=1)  # (Q, 2) row pairs
    mine = faces[quads].reshape(-1, 6)
    theirs = reference[quads].reshape(-1, 6)
    covered = (mine[:, :, None] == theirs[:, None, :]).any(axis=2).all(axis=1)
    covers = (theirs[:, :, None] == mine[:, None, :]).any(axis=2).all(axis=1)
    return bool(np.all(covered & covers))
