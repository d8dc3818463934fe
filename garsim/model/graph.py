"""Garment graphs as torch_geometric ``Data`` (training, evaluation, the torch model): the arrays of
``garsim.model.inputs.graph_arrays`` as tensors, the collision loss's body points, and batching."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch_geometric.data import Batch, Data

from garsim.data.sample import Sample
from garsim.geometry.mesh import vertex_normals_at
from garsim.geometry.proximity import nearest_vertices
from garsim.model.config import GarSimConfig
from garsim.model.inputs import graph_arrays


class GarmentGraph(Data):
    """A garment graph; knows how to offset its index attributes when batched."""

    def __inc__(self, key: str, value, *args, **kwargs):
        if key in ("edge_index", "faces"):
            return self.num_nodes
        if key == "face_pairs":
            return int(self.faces.shape[0])
        if key == "anchor_index":
            return torch.tensor([[self.num_nodes], [int(self.body_rel.shape[0])]])
        if key == "col_batch":
            return 1
        return 0

    def __cat_dim__(self, key: str, value, *args, **kwargs):
        if key in ("edge_index", "anchor_index"):
            return -1
        return 0


def build_graph(
    sample: Sample,
    config: GarSimConfig | None = None,
    *,
    with_collision: bool = False,
    loss_inputs: bool = True,
    name: str | None = None,
) -> GarmentGraph:
    """One Sample -> a GarmentGraph with every Eq. 2 input (``graph_arrays``) as tensors.

    ``with_collision`` adds the target-body vertices near the garment and their normals
    (``col_body``, ``col_normal``, ``col_batch``) for the collision loss; ``loss_inputs=False``
    (inference) skips the face pairs only the losses need.
    """
    arrays = graph_arrays(sample, config, loss_inputs=loss_inputs, name=name)
    data = GarmentGraph(
        num_nodes=len(arrays["pos"]),
        **{k: torch.from_numpy(v) for k, v in arrays.items()},
        name=name if name is not None else str(sample.meta.get("name", "")),
    )
    if with_collision:
        data.update(collision_body(sample))
    return data


def collision_body(sample: Sample, k: int = 16) -> dict[str, torch.Tensor]:
    """Target-body vertices near the garment (k nearest of each prior/target vertex) and their unit normals."""
    body_t = np.asarray(sample.body_target, dtype=np.float32)
    pts = sample.prior if sample.target is None else np.concatenate([sample.prior, sample.target])
    idx, _ = nearest_vertices(pts, body_t, k=min(k, len(body_t)))  # the body's tree is cached (paired fabrics)
    sel = np.unique(idx.ravel())
    normals = vertex_normals_at(body_t, np.asarray(sample.body_faces, dtype=np.int64), sel)
    return {
        "col_body": torch.from_numpy(body_t[sel].copy()),
        "col_normal": torch.from_numpy(np.ascontiguousarray(normals, dtype=np.float32)),
        "col_batch": torch.zeros(len(sel), dtype=torch.long),
    }


def collate(graphs: Sequence[GarmentGraph]) -> Batch:
    """Batch garment graphs of any sizes/topologies (indices offset per graph)."""
    return Batch.from_data_list(list(graphs))
