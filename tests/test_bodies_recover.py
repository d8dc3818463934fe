import numpy as np
import pytest

from garsim.bodies.poses import PoseSampler
from garsim.bodies.prior import garment_prior
from garsim.bodies.recover import fit_bone_transforms, recovered_lbs_prior
from garsim.garments.templates import make_garment
from garsim.geometry.skinning import apply_transforms, blended_transforms, dense_weights


def test_rigid_motion_recovered_exactly(anny_body):
    c = anny_body.canonical().vertices.astype(np.float64)
    angle = 0.6
    r = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    t = c @ r.T + [0.2, -0.1, 0.05]
    j = len(anny_body.bone_labels)
    bones = fit_bone_transforms(c, t, anny_body.skin_indices, anny_body.skin_weights, j)
    w = dense_weights(anny_body.skin_indices, anny_body.skin_weights, j)
    np.testing.assert_allclose(apply_transforms(c, blended_transforms(w, bones)), t, atol=1e-4)


@pytest.mark.parametrize("kind", ["skirt", "top"])
def test_recovered_prior_matches_the_true_lbs_prior(anny_body, kind):
    """A client holding only the two meshes gets the training prior to under 1 mm (mean)."""
    c = anny_body.canonical()
    g = make_garment(kind, anny_body, target_vertices=800).vertices
    for pose in PoseSampler(seed=11).sample(2):
        t = anny_body.pose(pose)
        true = garment_prior(anny_body, c, t, g)
        rec = recovered_lbs_prior(
            g, c.vertices, t.vertices, anny_body.skin_indices, anny_body.skin_weights, len(anny_body.bone_labels)
        )
        err = np.linalg.norm(rec - true, axis=1)
        assert err.mean() < 1e-3, err.mean()
        assert np.linalg.norm(true - g, axis=1).mean() > 0.02  # the pose moves the garment


def test_shape_mismatch_is_refused(anny_body):
    c = anny_body.canonical().vertices
    with pytest.raises(ValueError, match="same vertices"):
        fit_bone_transforms(c, c[:-1], anny_body.skin_indices, anny_body.skin_weights, 104)
