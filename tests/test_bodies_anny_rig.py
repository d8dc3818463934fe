"""The Anny rig cached on disk: the same skinning as the body model, rebuilt when damaged, and no torch to read it."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from garsim.bodies import anny_rig as rig_module


def test_cached_rig_is_the_body_models(anny_body, tmp_path, monkeypatch):
    path = tmp_path / "rig.npz"
    monkeypatch.setattr(rig_module, "rig_cache_path", lambda topology="anny": path)
    rig_module.anny_rig.cache_clear()
    try:
        built = rig_module.anny_rig("anny")  # no file: built from AnnyBody and stored
        assert path.is_file()
        rig_module.anny_rig.cache_clear()
        read = rig_module.anny_rig("anny")  # read back from the file
        for a, b in zip(built, read):
            np.testing.assert_array_equal(a, b)
        faces, indices, weights, num_bones, root_weight = read
        np.testing.assert_array_equal(faces, anny_body.faces)
        np.testing.assert_array_equal(indices, anny_body.skin_indices)
        np.testing.assert_array_equal(weights, anny_body.skin_weights)
        assert num_bones == len(anny_body.bone_labels)
        root = [anny_body.bone_labels.index(b) for b in rig_module.ROOT_BONES]
        dense = np.zeros((len(indices), num_bones))
        np.add.at(dense, (np.repeat(np.arange(len(indices)), indices.shape[1]), indices.ravel()), weights.ravel())
        np.testing.assert_allclose(root_weight, dense[:, root].sum(axis=1), atol=1e-12)
        region = rig_module.anny_root_region(len(anny_body.rest_vertices), anny_body.faces)
        pelvis = anny_body.rest_vertices[region]  # a band around the pelvis, clear of the hands
        assert 100 < region.sum() < 400 and np.ptp(pelvis[:, 2]) < 0.25 and np.abs(pelvis[:, 0]).max() < 0.2
        assert rig_module.anny_root_region(100, anny_body.faces) is None
        assert rig_module.match_anny_rig(len(anny_body.rest_vertices), anny_body.faces)[2] == num_bones
        assert rig_module.match_anny_rig(len(anny_body.rest_vertices), anny_body.faces[::-1]) is None
        assert rig_module.match_anny_rig(100, anny_body.faces) is None

        path.write_bytes(path.read_bytes()[:200])  # a damaged cache file is rebuilt, not an error
        rig_module.anny_rig.cache_clear()
        np.testing.assert_array_equal(rig_module.anny_rig("anny")[1], anny_body.skin_indices)
        with np.load(path) as z:
            assert z["skin_indices"].shape == anny_body.skin_indices.shape
    finally:
        rig_module.anny_rig.cache_clear()


def test_mesh_pair_prior_needs_no_torch():
    """Matching a mesh pair against the Anny rig (and the prior of any other mesh) loads neither torch nor Anny."""
    code = (
        "import sys, numpy as np, trimesh\n"
        "from garsim.bodies.prior import mesh_pair_prior\n"
        "b = trimesh.creation.icosphere(subdivisions=2); v, f = np.asarray(b.vertices), np.asarray(b.faces)\n"
        "mesh_pair_prior(v * 1.1, v, v + 0.1, f)\n"
        "sys.exit(any(m in sys.modules for m in ('torch', 'anny', 'warp')))\n"
    )
    assert subprocess.run([sys.executable, "-c", code], timeout=120).returncode == 0


def test_same_quads_accepts_the_other_diagonal_and_nothing_else():
    from garsim.bodies.anny_rig import same_quads

    # a strip of three quads (0 1 5 4), (1 2 6 5), (2 3 7 6), each split on its 0-2 diagonal
    ref = np.array([[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6]] * 40)
    assert same_quads(ref.copy(), ref)
    flipped = ref.copy()
    flipped[2:4] = [[1, 2, 5], [2, 6, 5]]  # the second quad split on its other diagonal: same four vertices
    assert same_quads(flipped, ref) and same_quads(ref, flipped)
    wrong = flipped.copy()
    wrong[3] = [2, 6, 7]  # a vertex the quad does not have
    assert not same_quads(wrong, ref)
    lone = ref.copy()
    lone[2] = [1, 2, 5]  # one triangle changed, not a quad's pair
    assert not same_quads(lone, ref)
    many = ref.copy()
    many[0:4] = [[0, 1, 4], [1, 5, 4], [1, 2, 5], [2, 6, 5]]  # 4 of 240 rows flipped: over the 1% share
    assert not same_quads(many, ref)
    assert not same_quads(ref[:-1], ref)


def test_the_committed_fixture_body_matches_this_machines_anny_rig():
    """The fixture's body was triangulated on another machine (Anny's diagonal choice is float-dependent)."""
    from pathlib import Path

    from garsim.bodies.anny_rig import ANNY_VERTICES, match_anny_rig

    path = next((Path(__file__).parent / "fixtures" / "dataset_v2" / "body_faces").glob("*.npy"))
    assert match_anny_rig(ANNY_VERTICES, np.load(path)) is not None
