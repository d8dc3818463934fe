"""A body given as two meshes with one topology (canonical + target), for users of any body model."""

from __future__ import annotations

import numpy as np

from garsim.bodies.base import BodyModel, PosedBody
from garsim.geometry.io import MeshError, validate_mesh


def _as_arrays(mesh: object, faces: object | None, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Vertices (and faces, if the input carries them) from a trimesh object or an array."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):  # trimesh.Trimesh (or anything alike)
        return np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if mesh is None:
        raise ValueError(f"{name} is None; pass a (V, 3) vertex array or a trimesh.Trimesh")
    return np.asarray(mesh), (None if faces is None else np.asarray(faces))


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
        self._canonical, self._faces = validate_mesh(can, face_array, "canonical mesh")
        self._target, _ = validate_mesh(tgt, face_array, "target mesh")
        if len(self._canonical) != len(self._target):
            raise MeshError(
                f"canonical mesh has {len(self._canonical)} vertices but target has {len(self._target)}; "
                "both must share one topology (same vertex count and order)"
            )

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
