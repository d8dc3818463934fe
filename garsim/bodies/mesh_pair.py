"""A body given as two meshes with one topology (canonical + target), for users of any body model."""

from __future__ import annotations

import numpy as np

from garsim.bodies.base import BodyModel, PosedBody


def _as_arrays(mesh: object, faces: object | None, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Vertices (and faces, if the input carries them) from a trimesh object or an array."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):  # trimesh.Trimesh (or anything alike)
        return np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if mesh is None:
        raise ValueError(f"{name} is None; pass a (V, 3) vertex array or a trimesh.Trimesh")
    return np.asarray(mesh), (None if faces is None else np.asarray(faces))


def _check_vertices(v: np.ndarray, name: str) -> np.ndarray:
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"{name} vertices must have shape (V, 3), got {v.shape}")
    if not np.issubdtype(v.dtype, np.number):
        raise ValueError(f"{name} vertices must be numbers, got dtype {v.dtype}")
    if len(v) < 4:
        raise ValueError(f"{name} has {len(v)} vertices; a body mesh needs at least 4")
    if not np.all(np.isfinite(v)):
        bad = int((~np.isfinite(v)).any(axis=1).sum())
        raise ValueError(f"{name} has {bad} vertices with NaN or infinite coordinates; fix or drop them")
    return v.astype(np.float32)


class MeshPairBody(BodyModel):
    """A canonical and a target body mesh with the same vertices and faces, and no rig.

    ``canonical`` and ``target`` are (V, 3) arrays or ``trimesh.Trimesh`` objects (faces are taken
    from them if ``faces`` is not given; two meshes must agree). Skinning weights/indices are None
    and posed bodies carry no transforms, so the LBS prior needs weights from elsewhere. The body
    has exactly one target: ``pose()`` ignores its argument and returns it.
    """

    def __init__(self, canonical: object, target: object, faces: object | None = None) -> None:
        can, can_faces = _as_arrays(canonical, None, "canonical mesh")
        tgt, tgt_faces = _as_arrays(target, None, "target mesh")
        candidates = [f for f in (faces, can_faces, tgt_faces) if f is not None]
        if not candidates:
            raise ValueError("no faces: pass faces=(F, 3) triangles, or trimesh objects that carry them")
        face_array = np.asarray(candidates[0])
        for other in candidates[1:]:
            other = np.asarray(other)
            if other.shape != face_array.shape or not np.array_equal(other, face_array):
                raise ValueError("canonical and target meshes have different faces; both must share one topology")
        self._canonical = _check_vertices(can, "canonical mesh")
        self._target = _check_vertices(tgt, "target mesh")
        if len(self._canonical) != len(self._target):
            raise ValueError(
                f"canonical mesh has {len(self._canonical)} vertices but target has {len(self._target)}; "
                "both must share one topology (same vertex count and order)"
            )
        self._faces = self._check_faces(face_array, len(self._canonical))

    def _check_faces(self, faces: np.ndarray, num_vertices: int) -> np.ndarray:
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise ValueError(f"faces must be a non-empty (F, 3) array of triangles, got shape {faces.shape}")
        if not np.issubdtype(faces.dtype, np.integer):
            if not np.all(np.isfinite(faces)) or not np.all(faces == np.round(faces)):
                raise ValueError("faces must hold integer vertex indices")
        f = faces.astype(np.int64)
        if f.min() < 0 or f.max() >= num_vertices:
            raise ValueError(f"face indices must be in [0, {num_vertices - 1}], found [{f.min()}, {f.max()}]")
        repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
        if repeated.any():
            raise ValueError(f"{int(repeated.sum())} faces repeat a vertex (degenerate triangles); remove them")
        for name, v in (("canonical", self._canonical), ("target", self._target)):
            tri = v[f].astype(np.float64)
            area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
            scale = max(float(np.ptp(v, axis=0).max()), 1e-12)
            flat = area2 <= 1e-12 * scale * scale
            if flat.any():
                raise ValueError(f"{int(flat.sum())} faces of the {name} mesh have zero area (degenerate); remove them")
        return f

    # -- BodyModel -------------------------------------------------------------------------
    @property
    def faces(self) -> np.ndarray:
        return self._faces

    @property
    def rest_vertices(self) -> np.ndarray:
        """The canonical mesh (there is no separate rest pose)."""
        return self._canonical

    @property
    def skin_weights(self) -> None:
        return None

    @property
    def skin_indices(self) -> None:
        return None

    def canonical(self) -> PosedBody:
        """The canonical mesh, without transforms."""
        return PosedBody(vertices=self._canonical.copy(), transforms=None)

    def pose(self, pose: object = None) -> PosedBody:
        """The target mesh, without transforms; ``pose`` is ignored (the pair has one target)."""
        return PosedBody(vertices=self._target.copy(), transforms=None)
