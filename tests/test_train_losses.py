"""Losses of Eq. 3-7 against hand-computed values on two triangles."""

import math

import numpy as np
import pytest
import torch
from torch_geometric.data import Batch

from garsim.geometry.mesh import directed_edges, face_pairs
from garsim.model.graph import GarmentGraph
from garsim.train.losses import (
    LossWeights,
    collision_loss,
    direction_loss,
    fold_loss,
    garsim_loss,
    l2_loss,
    laplacian_loss,
    normal_consistency_loss,
)

# two triangles sharing edge (1, 2); vertex 3 lifted by 1 -> a fold along the shared edge
V = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]])
F = np.array([[0, 1, 2], [1, 3, 2]])


def _graph():
    g = GarmentGraph(
        num_nodes=4,
        pos=V.clone(),
        prior=V.clone(),
        target=V + torch.tensor([[0.0, 0, 0], [0, 0, 0.3], [0, 0, 0], [0.4, 0, 0]]),
        pinned=torch.tensor([True, False, False, False]),
        edge_index=torch.from_numpy(directed_edges(F)),
        faces=torch.from_numpy(F),
        face_pairs=torch.from_numpy(face_pairs(F)),
        col_body=torch.tensor([[0.0, 0, -0.001], [5.0, 5, 5]]),
        col_normal=torch.tensor([[0.0, 0, 1], [0.0, 0, 1]]),
        col_batch=torch.zeros(2, dtype=torch.long),
        name="two_triangles",
    )
    return g


def test_l2_pinned_and_free():
    g = _graph()
    val = l2_loss(V, g.target, g.pinned, torch.zeros(4, dtype=torch.long), 1, beta=0.4)
    # free vertices 1,2,3 errors 0.3, 0, 0.4 -> mean 0.7/3; pinned vertex 0 error 0
    assert val.item() == pytest.approx(0.6 * 0.7 / 3 + 0.4 * 0.0)
    pinned_err = l2_loss(V + torch.tensor([0.0, 2, 0]), V, g.pinned, torch.zeros(4, dtype=torch.long), 1)
    assert pinned_err.item() == pytest.approx(0.6 * 2 + 0.4 * 2)


def test_uniform_laplacian_hand_value():
    g = _graph()
    val = laplacian_loss(V, g.edge_index, torch.zeros(4, dtype=torch.long), 1).item()
    # neighbours: 0:{1,2} 1:{0,2,3} 2:{0,1,3} 3:{1,2}
    l0 = np.linalg.norm([0, 0, 0] - np.mean([[1, 0, 0], [0, 1, 0]], axis=0))
    l1 = np.linalg.norm([1, 0, 0] - np.mean([[0, 0, 0], [0, 1, 0], [1, 1, 1]], axis=0))
    l2 = np.linalg.norm([0, 1, 0] - np.mean([[0, 0, 0], [1, 0, 0], [1, 1, 1]], axis=0))
    l3 = np.linalg.norm([1, 1, 1] - np.mean([[1, 0, 0], [0, 1, 0]], axis=0))
    assert val == pytest.approx((l0 + l1 + l2 + l3) / 4, rel=1e-6)


def test_normal_consistency_hand_value():
    g = _graph()
    val = normal_consistency_loss(V, g.faces, g.face_pairs, torch.zeros(4, dtype=torch.long), 1).item()
    n1 = np.array([0, 0, 1.0])
    n2 = np.cross([0, 1, 1], [-1, 1, 0])  # (3-1) x (2-1)
    n2 = n2 / np.linalg.norm(n2)
    assert val == pytest.approx(1 - n1 @ n2, rel=1e-6)  # = 1 - 1/sqrt(3)
    assert val == pytest.approx(1 - 1 / math.sqrt(3), rel=1e-6)
    flat = V.clone()
    flat[3, 2] = 0
    assert normal_consistency_loss(
        flat, g.faces, g.face_pairs, torch.zeros(4, dtype=torch.long), 1
    ).item() == pytest.approx(0, abs=1e-7)


def test_fold_term_hand_value_and_gradient():
    """``fold_loss``: |chord of the prediction's fold - the simulation's| (chord 2 sin(θ/2) of the dihedral angle θ);
    zero for a prediction folded as deeply as the simulation, even where its fold lies elsewhere; its gradient
    deepens a fold that is too shallow."""
    g = _graph()
    one = torch.zeros(4, dtype=torch.long)
    flat = V.clone()
    flat[3, 2] = 0
    theta = math.acos(1 / math.sqrt(3))  # the fold of V (test_normal_consistency_hand_value)
    val = fold_loss(flat, V, g.faces, g.face_pairs, one, 1).item()
    assert val == pytest.approx(2 * math.sin(theta / 2), rel=1e-5)
    mirrored = V.clone()
    mirrored[3, 2] = -1  # folded the other way, as deep: no fold-depth error
    assert fold_loss(mirrored, V, g.faces, g.face_pairs, one, 1).item() == pytest.approx(0, abs=1e-5)
    shallow = V.clone()
    shallow[3, 2] = 0.5
    shallow.requires_grad_(True)
    fold_loss(shallow, V, g.faces, g.face_pairs, one, 1).sum().backward()
    assert shallow.grad[3, 2] < 0  # descending lifts vertex 3: a deeper fold


def test_fold_term_of_a_paired_group_adds_the_fold_differences_between_its_fabrics():
    """Two members of one paired group, one predicted flat (fold error -c), one exact (0): each also pays its error's
    distance to the group's mean error (c/2); ungrouped graphs (pair -1) pay only their own error."""
    two = torch.tensor([0, 0, 0, 0, 1, 1, 1, 1])
    faces = torch.cat([torch.from_numpy(F), torch.from_numpy(F) + 4])
    pairs_ = torch.from_numpy(face_pairs(np.concatenate([F, F + 4])))
    flat = V.clone()
    flat[3, 2] = 0
    pred, target = torch.cat([flat, V]), torch.cat([V, V])
    c = 2 * math.sin(math.acos(1 / math.sqrt(3)) / 2)
    grouped = fold_loss(pred, target, faces, pairs_, two, 2, pair=torch.tensor([0, 0]))
    torch.testing.assert_close(grouped, torch.tensor([1.5 * c, 0.5 * c]), rtol=1e-5, atol=1e-6)
    alone = fold_loss(pred, target, faces, pairs_, two, 2, pair=torch.tensor([-1, -1]))
    torch.testing.assert_close(alone, torch.tensor([c, 0.0]), rtol=1e-5, atol=1e-6)


def test_collision_hinge_hand_value():
    g = _graph()
    eps = 0.004
    pred = torch.tensor([[0.0, 0, -0.01], [0.1, 0, 0.0], [0.0, 0.1, 0.02], [5.0, 5, 4.0]])
    val = collision_loss(pred, g.col_body, g.col_normal, torch.zeros(4, dtype=torch.long), g.col_batch, 1, eps).item()
    # signed offsets along +z to the nearest body vertex: -0.009, 0.001, 0.021, -1.0
    expected = (max(eps + 0.009, 0) + max(eps - 0.001, 0) + 0 + max(eps + 1.0, 0)) / 4
    assert val == pytest.approx(expected, rel=1e-5)


def test_total_is_weighted_sum_and_per_graph_mean():
    g1, g2 = _graph(), _graph()
    g2.target = g2.target + 1.0
    b = Batch.from_data_list([g1, g2])
    w = LossWeights()
    pred = b.pos.clone().requires_grad_(True)
    total, terms = garsim_loss(pred, b, w, use_collision=True)
    assert terms["l2"].shape == (2,)
    manual = w.l2 * terms["l2"] + w.sm * terms["sm"] + w.nc * terms["nc"] + w.col * terms["col"]
    torch.testing.assert_close(terms["total"], manual)
    assert total.item() == pytest.approx(manual.mean().item())
    total.backward()
    assert torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0
    assert terms["sm"][0] == terms["sm"][1] and terms["l2"][1] > terms["l2"][0]
    folded = LossWeights(fold=0.5)
    total_f, terms_f = garsim_loss(b.pos, b, folded, use_collision=True)
    assert terms_f["fold"].shape == (2,) and "fold" not in terms
    torch.testing.assert_close(terms_f["total"], manual + 0.5 * terms_f["fold"])


def test_collision_fraction_by_hand():
    """Two graphs: a flat body patch with +Z normals; vertices below it count as inside."""
    import torch
    from torch_geometric.data import Data

    from garsim.train.losses import collision_fraction

    body = torch.tensor([[0.0, 0, 0], [1.0, 0, 0], [0.0, 0, 0]])
    normals = torch.tensor([[0.0, 0, 1], [0.0, 0, 1], [0.0, 0, 1]])
    pred = torch.tensor([[0.0, 0, 0.1], [0.0, 0, -0.1], [1.0, 0, -0.01], [1.0, 0, 0.2], [0.0, 0, -0.5]])
    data = Data(
        pos=pred,
        batch=torch.tensor([0, 0, 0, 0, 1]),
        col_body=body,
        col_normal=normals,
        col_batch=torch.tensor([0, 0, 1]),
        num_nodes=5,
        num_graphs=2,
    )
    np.testing.assert_allclose(collision_fraction(pred, data).numpy(), [0.5, 1.0])


def test_direction_and_magnitude_terms_by_hand():
    """Displacements r: v1 +0.3 z, v3 +0.4 x (v0, v2 do not move). Directions along r cost 0; v3's
    direction orthogonal to r costs 0.4 (1 - 0) / 0.7; opposite costs 2 x 0.4 / 0.7; identity rotation.
    Magnitudes equal to |r| cost 0; v1's 0.1 too long adds 0.1 / 4 (mean over the four vertices)."""
    g = _graph()
    g.rot = torch.eye(3)[None]
    batch = torch.zeros(4, dtype=torch.long)
    m = torch.tensor([0.0, 0.3, 0.0, 0.4])
    along = torch.tensor([[1.0, 0, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0]])
    assert direction_loss(along, m, g, batch, 1).item() == pytest.approx(0.0, abs=1e-7)
    ortho = along.clone()
    ortho[3] = torch.tensor([0.0, 1, 0])
    assert direction_loss(ortho, m, g, batch, 1).item() == pytest.approx(0.4 / 0.7)
    opposite = along.clone()
    opposite[3] = -opposite[3]
    assert direction_loss(opposite, m, g, batch, 1).item() == pytest.approx(0.8 / 0.7)
    longer = m + torch.tensor([0.0, 0.1, 0.0, 0.0])
    assert direction_loss(along, longer, g, batch, 1).item() == pytest.approx(0.1 / 4)
    # the body frame: a 90° turn about z maps the world x displacement of v3 to body-frame y
    g.rot = torch.tensor([[[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]])
    assert direction_loss(ortho, m, g, batch, 1).item() == pytest.approx(0.0, abs=1e-7)
    # a local rotation (GarSimConfig.local_rotation) turns the decoded vector: a 90° turn about z at v3 wants the
    # decoder's direction along -y for its world +x displacement
    g.rot = torch.eye(3)[None]
    g.local_rot = torch.eye(3).repeat(4, 1, 1)
    g.local_rot[3] = torch.tensor([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    turned = along.clone()
    turned[3] = torch.tensor([0.0, -1, 0])
    assert direction_loss(turned, m, g, batch, 1).item() == pytest.approx(0.0, abs=1e-7)
    del g.local_rot
    _, terms = garsim_loss(g.target, g, LossWeights(dir=0.5), direction=opposite, magnitude=m)
    expected = 0.5 * 0.8 / 0.7 + 0.01 * terms["sm"].item() + 1e-4 * terms["nc"].item()
    assert terms["total"].item() == pytest.approx(expected)


def test_nearest_in_graph_indexes_each_body_once():
    """Two graphs' bodies, queried twice (two training steps): the right per-graph nearest indices, and each body's
    KD-tree is built once (the second step finds both in the training cache)."""
    from garsim.train.losses import _BODY_TREES, nearest_in_graph

    _BODY_TREES.clear()
    refs = np.array([[0.0, 0, 0], [1, 0, 0], [10, 0, 0], [11, 0, 0]])
    ref_graph = np.array([0, 0, 1, 1])
    points = np.array([[0.9, 0, 0], [0.1, 0, 0], [0.2, 0, 0]])  # the last belongs to graph 1: nearest is [10, 0, 0]
    point_graph = np.array([0, 0, 1])
    for _ in range(2):
        np.testing.assert_array_equal(nearest_in_graph(points, point_graph, refs, ref_graph, 2), [1, 0, 2])
    assert len(_BODY_TREES) == 2


def test_relative_l2_divides_each_graph_by_its_priors_error():
    """``LossWeights.relative``: graph 1's prior is off by 0.7/4 m on average (mean over all four vertices), graph
    2's by 0.01 m (floored at a quarter of the reference): each L2 term weighs reference / that error in the total."""
    g1, g2 = _graph(), _graph()
    g2.target = g2.prior + torch.tensor([0.0, 0.0, 0.01])
    b = Batch.from_data_list([g1, g2])
    pred = b.target + 0.02  # every vertex 0.02 * sqrt(3) off
    _, plain = garsim_loss(pred, b, LossWeights())
    _, rel = garsim_loss(pred, b, LossWeights(relative=0.2))
    torch.testing.assert_close(rel["l2"], plain["l2"])  # the reported term stays the mean error
    factor = torch.tensor([0.2 / (0.7 / 4), 0.2 / 0.05])
    torch.testing.assert_close(rel["total"] - plain["total"], (factor - 1.0) * plain["l2"])
