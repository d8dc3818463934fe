"""Pose library: joint conventions, limits, limb-through-body rejection, reproducibility, slerp, walk."""

from __future__ import annotations

import math

import numpy as np
import pytest
import roma
import torch

from garsim.bodies import poses as P


@pytest.fixture(scope="module")
def body(anny_body):
    return anny_body


@pytest.fixture(scope="module")
def axes(body):
    return P.hinge_axes(body)


@pytest.fixture(scope="module")
def checker(body):
    return P.LimbCollisionChecker(body)


@pytest.fixture(scope="module")
def dominant(body):
    w, idx = body.skin_weights, body.skin_indices
    return np.array(body.bone_labels)[idx[np.arange(len(w)), w.argmax(axis=1)]]


@pytest.fixture(scope="module")
def sampled(body):
    """200 poses from seed 0, with their joint angles (the expensive part, done once)."""
    sampler = P.PoseSampler(body=body, seed=0, batch_size=64)
    poses, angles = sampler.sample(200, return_angles=True)
    return sampler, poses, angles


def _pose(body, angles, axes):
    vertices, _ = body.pose_batch(P.batched_matrices(P.angles_to_pose(angles, axes)))
    return vertices


def _centroid(vertices, dominant, bone):
    return vertices[..., dominant == bone, :].mean(axis=-2)


def _angle_between(r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
    m1 = roma.rotvec_to_rotmat(torch.as_tensor(np.asarray(r1, dtype=np.float64)))
    m2 = roma.rotvec_to_rotmat(torch.as_tensor(np.asarray(r2, dtype=np.float64)))
    return roma.rotmat_geodesic_distance(m1, m2).numpy()


# -- conventions -------------------------------------------------------------------------------
def test_zero_angles_give_the_canonical_t_pose(body, axes):
    np.testing.assert_allclose(_pose(body, {}, axes)[0], body.canonical().vertices, atol=1e-6)


@pytest.mark.parametrize(
    "angle, probe, axis, direction",
    [
        ("hip_flexion", "lowerleg01", 1, -1.0),  # knee goes forward (-Y)
        ("knee_flexion", "foot", 1, +1.0),  # foot goes back (+Y)
        ("shoulder_flexion", "wrist", 1, -1.0),  # hand goes forward
        ("shoulder_elevation", "wrist", 2, +1.0),  # hand goes up
    ],
)
def test_sided_joint_signs_move_vertices_the_right_way(body, axes, dominant, angle, probe, axis, direction):
    can = body.canonical().vertices
    for side in "LR":
        moved = _pose(body, {f"{angle}_{side}": 30.0}, axes)[0]
        delta = _centroid(moved, dominant, f"{probe}.{side}") - _centroid(can, dominant, f"{probe}.{side}")
        assert direction * delta[axis] > 0.05, f"{angle}_{side} moved {probe}.{side} by {delta}"


def test_mirrored_sides_move_mirror_symmetrically(body, axes, dominant):
    can = body.canonical().vertices
    for angle, probe in [("hip_abduction", "lowerleg01"), ("hip_rotation", "toe1-1"), ("elbow_flexion", "wrist")]:
        d = {}
        for side in "LR":
            moved = _pose(body, {f"{angle}_{side}": 30.0}, axes)[0]
            d[side] = _centroid(moved, dominant, f"{probe}.{side}") - _centroid(can, dominant, f"{probe}.{side}")
        np.testing.assert_allclose(d["R"], d["L"] * np.array([-1.0, 1.0, 1.0]), atol=2e-3)
        assert np.linalg.norm(d["L"]) > 0.03
    # Abduction moves the left knee to +X (away from the midline), external rotation the left toes to +X.
    moved = _pose(body, {"hip_abduction_L": 30.0, "hip_rotation_L": 30.0}, axes)[0]
    assert _centroid(moved, dominant, "lowerleg01.L")[0] > _centroid(can, dominant, "lowerleg01.L")[0] + 0.1


def test_elbow_flexion_folds_the_forearm_towards_the_shoulder(body, axes, dominant):
    dist = []
    for e in (-35.0, 0.0, 60.0, 100.0):
        v = _pose(body, {"elbow_flexion_L": e}, axes)[0]
        dist.append(np.linalg.norm(_centroid(v, dominant, "wrist.L") - _centroid(v, dominant, "upperarm01.L")))
    assert np.all(np.diff(dist) < -0.02), dist


def test_spine_and_neck_signs(body, axes, dominant):
    can = body.canonical().vertices
    head0 = _centroid(can, dominant, "head")
    assert (_centroid(_pose(body, {"spine_flexion": 30.0}, axes)[0], dominant, "head") - head0)[1] < -0.1
    assert (_centroid(_pose(body, {"spine_lateral": 20.0}, axes)[0], dominant, "head") - head0)[0] > 0.1
    assert (_centroid(_pose(body, {"neck_flexion": 30.0}, axes)[0], dominant, "head") - head0)[1] < -0.02
    pose = P.angles_to_pose({"spine_twist": 30.0}, axes)
    # The twist is split evenly: each of the five spine bones turns 6 degrees about Z.
    for bone in P.SPINE_BONES:
        np.testing.assert_allclose(pose[bone][0], [0.0, 0.0, math.radians(6.0)], atol=1e-12)


def test_knee_and_elbow_rotate_about_their_hinge_only(axes):
    pose = P.angles_to_pose({"knee_flexion_L": 50.0, "knee_flexion_R": 20.0, "elbow_flexion_L": -30.0}, axes)
    np.testing.assert_allclose(pose["lowerleg01.L"][0], math.radians(50.0) * np.array(axes.knee_l), atol=1e-12)
    np.testing.assert_allclose(
        pose["lowerleg01.R"][0], math.radians(20.0) * np.array(axes.knee_l) * [1, -1, -1], atol=1e-12
    )
    np.testing.assert_allclose(pose["lowerarm01.L"][0], math.radians(-30.0) * np.array(axes.elbow_l), atol=1e-12)


def test_unknown_angle_names_and_bad_limits_are_rejected():
    with pytest.raises(ValueError, match="unknown joint angles"):
        P.angles_to_pose({"hip_flexion": 10.0})
    with pytest.raises(ValueError, match="low <= high"):
        P.JointLimits(knee_flexion=(10.0, 0.0))
    with pytest.raises(ValueError, match="finite degrees"):
        P.JointLimits(neck_twist=(0.0, float("nan")))


# -- collision test ----------------------------------------------------------------------------
def test_checker_accepts_rest_poses_and_flags_limbs_through_the_body(body, axes, checker):
    assert checker.valid(body.canonical().vertices[None])[0]
    assert checker.valid(body.pose(None).vertices[None])[0]  # Anny's A-pose
    bad = {
        "arm across the chest": ({"shoulder_flexion_L": 90.0, "elbow_flexion_L": 100.0}, ("arm.L", "torso")),
        "arms into the hips": ({"shoulder_elevation_L": -95.0, "shoulder_elevation_R": -95.0}, ("arm.R", "torso")),
        "legs crossed": ({"hip_abduction_L": -25.0, "hip_abduction_R": -25.0}, ("leg.L", "leg.R")),
    }
    names = list(bad)
    vertices = _pose(body, P.stack_angles([bad[n][0] for n in names]), axes)
    counts = checker.penetration_counts(vertices)
    for i, name in enumerate(names):
        pair = P.PART_PAIRS.index(bad[name][1])
        assert counts[i, pair] > 10, f"{name}: {dict(zip(P.PART_PAIRS, counts[i]))}"


def test_body_parts_come_from_dominant_bones(checker, dominant):
    assert set(np.unique(checker.part)) == {"torso", "arm.L", "arm.R", "leg.L", "leg.R", "eye"}
    assert np.all(checker.part[dominant == "lowerarm01.L"] == "arm.L")
    assert np.all(checker.part[dominant == "foot.R"] == "leg.R")
    assert np.all(checker.part[dominant == "spine03"] == "torso")
    # Left and right parts are mirror images in size.
    assert (checker.part == "arm.L").sum() == (checker.part == "arm.R").sum()


# -- the sampler -------------------------------------------------------------------------------
def test_200_sampled_poses_have_no_limb_through_the_body(body, checker, sampled):
    sampler, poses, _ = sampled
    assert len(poses) == 200
    assert 0.05 < sampler.acceptance_rate < 1.0  # the test rejected some, and it was not everything
    # Re-pose a slice independently of the sampler's loop and re-check it.
    subset = poses[::5]
    vertices, _ = body.pose_batch(P.batched_matrices(P.stack_poses(subset)))
    assert checker.penetration_counts(vertices).sum() == 0


def test_sampled_poses_respect_the_joint_limits(sampled, axes):
    sampler, poses, angles = sampled
    limits = sampler.limits
    table = {name: np.array([a[name] for a in angles]) for name in P.angle_names()}
    for name, values in table.items():
        lo, hi = P.limit_of(limits, name)
        assert values.min() >= lo and values.max() <= hi, name
        assert values.max() - values.min() > 0.5 * (hi - lo), f"{name} does not span its range"
    # The poses are exactly these angles' rotations: knees turn about their hinge by the sampled angle.
    knee = np.stack([p["lowerleg01.L"] for p in poses])
    np.testing.assert_allclose(knee, np.radians(table["knee_flexion_L"])[:, None] * np.array(axes.knee_l), atol=1e-9)
    assert np.all(np.radians(table["knee_flexion_L"]) >= 0.0)
    # The hip's total rotation is bounded by the sum of its three limits.
    hip_bound = sum(max(abs(x) for x in getattr(limits, f)) for f in ("hip_flexion", "hip_abduction", "hip_rotation"))
    hip_angles = np.linalg.norm(np.stack([p["upperleg01.R"] for p in poses]), axis=1)
    assert np.degrees(hip_angles).max() <= hip_bound + 1e-6
    rebuilt = P.angles_to_pose({k: v[:5] for k, v in table.items()}, axes)
    for bone in P.POSED_BONES:
        np.testing.assert_allclose(rebuilt[bone], np.stack([p[bone] for p in poses[:5]]), atol=1e-12)


def test_sampler_is_reproducible_from_its_seed(body, sampled):
    _, poses, _ = sampled
    again = P.PoseSampler(body=body, seed=0, batch_size=64).sample(10)
    other = P.PoseSampler(body=body, seed=1, batch_size=64).sample(10)
    for a, b in zip(again, poses[:10]):
        assert a.keys() == b.keys()
        for bone in a:
            np.testing.assert_array_equal(a[bone], b[bone])
    assert all(not np.allclose(a["upperleg01.L"], b["upperleg01.L"]) for a, b in zip(other, poses[:10]))


def test_narrow_limits_give_the_t_pose(body):
    zero = P.JointLimits(**{f: (0.0, 0.0) for f in P.JointLimits.__dataclass_fields__})
    poses = P.PoseSampler(body=body, limits=zero, seed=5, batch_size=4).sample(2)
    t_pose = body.t_pose()
    for pose in poses:
        for bone, rotvec in pose.items():
            np.testing.assert_allclose(rotvec, t_pose.get(bone, np.zeros(3)), atol=1e-12)


def test_sample_pose_is_single_and_seeded():
    a = P.sample_pose(np.random.default_rng(7))
    b = P.sample_pose(np.random.default_rng(7))
    assert set(a) == set(P.POSED_BONES) and all(v.shape == (3,) for v in a.values())
    for bone in a:
        np.testing.assert_array_equal(a[bone], b[bone])


# -- sequences ---------------------------------------------------------------------------------
def test_slerp_endpoints_and_midpoint(body, sampled):
    _, poses, _ = sampled
    start, end = body.t_pose(), poses[3]
    frames = P.interpolate_poses(start, end, 5)
    assert len(frames) == 5
    for bone in end:
        np.testing.assert_array_equal(frames[0][bone], start.get(bone, np.zeros(3)))
        np.testing.assert_array_equal(frames[-1][bone], end[bone])
        a, b, mid = frames[0][bone], frames[-1][bone], frames[2][bone]
        total = _angle_between(a, b)
        np.testing.assert_allclose(_angle_between(a, mid), total / 2, atol=1e-9)
        np.testing.assert_allclose(_angle_between(mid, b), total / 2, atol=1e-9)
        quarter = frames[1][bone]
        np.testing.assert_allclose(_angle_between(a, quarter), total / 4, atol=1e-9)
    with pytest.raises(ValueError, match="num_frames must be >= 2"):
        P.interpolate_poses(start, end, 1)


def test_pose_sequence_starts_at_the_t_pose_and_ends_at_the_target(body, sampled):
    _, poses, _ = sampled
    target = poses[0]
    vertices, transforms = P.pose_sequence(body, target, 3)
    assert vertices.shape == (3, body.num_vertices, 3) and transforms.shape == (3, len(body.bone_labels), 4, 4)
    np.testing.assert_allclose(vertices[0], body.canonical().vertices, atol=1e-5)
    np.testing.assert_allclose(vertices[-1], body.pose(target).vertices, atol=1e-5)
    np.testing.assert_allclose(transforms[-1], body.pose(target).transforms, atol=1e-6)
    # The middle frame lies between: its vertices moved part of the way.
    d_mid = np.linalg.norm(vertices[1] - vertices[0], axis=1).max()
    d_end = np.linalg.norm(vertices[2] - vertices[0], axis=1).max()
    assert 0.2 * d_end < d_mid < 0.8 * d_end


def test_walk_cycle_is_periodic_and_counter_phased(body, axes, dominant, checker):
    n = 8
    frames = P.walk_cycle(n, stride=0.6, axes=axes)
    assert len(frames) == n + 1
    for bone in frames[0]:
        np.testing.assert_allclose(frames[n][bone], frames[0][bone], atol=1e-12)
    shifted = P.walk_pose(np.array([0.3, 0.3 + 2 * math.pi]), axes=axes)
    for r in shifted.values():
        np.testing.assert_allclose(r[0], r[1], atol=1e-9)
    assert len(P.walk_cycle(n, include_end=False)) == n
    vertices, _ = body.pose_batch(P.batched_matrices(P.stack_poses(frames)))
    quarter, three_quarters = vertices[n // 4], vertices[3 * n // 4]
    y = lambda v, bone: _centroid(v, dominant, bone)[1]  # noqa: E731
    # At a quarter period the left leg is forward (-Y) and the right leg back; the arms swing opposite.
    assert y(quarter, "lowerleg01.L") < y(quarter, "lowerleg01.R") - 0.2
    assert y(quarter, "wrist.L") > y(quarter, "wrist.R") + 0.1
    assert y(three_quarters, "lowerleg01.L") > y(three_quarters, "lowerleg01.R") + 0.2
    # Half a period later the left and right roles swap (mirror symmetry in X).
    np.testing.assert_allclose(
        quarter[dominant == "foot.L"][:, 1].mean(), three_quarters[dominant == "foot.R"][:, 1].mean(), atol=2e-3
    )
    assert checker.valid(vertices).all()
    with pytest.raises(ValueError, match="stride"):
        P.walk_cycle(8, stride=3.0)


@pytest.mark.parametrize("num_frames", [5, 6, 30])
def test_motion_library_passes_its_keyframes(num_frames):
    """Every motion gives the frames asked for and shows each of its keyframes: all but the walk start standing,
    arms down; the arms reach their raised pose; the turn twists fully to the left, then to the right; the sit ends
    seated (hips and knees bent). Fewer frames than keyframes are refused."""
    from garsim.bodies.poses import MOTIONS, STANDING, motion

    for name in MOTIONS:
        frames = motion(name, num_frames)
        assert len(frames) == num_frames, name
        if name != "walk":
            for bone, r in STANDING.items():
                np.testing.assert_allclose(frames[0][bone], r, atol=1e-12)
    twist = np.array([float(p["spine01"][2]) for p in motion("turn", num_frames)])
    assert twist.max() == pytest.approx(np.radians(5.0), abs=1e-9) and twist.min() == pytest.approx(-twist.max())
    assert np.argmax(twist) < np.argmin(twist)
    raised = max(float(np.linalg.norm(p["upperarm01.L"] - STANDING["upperarm01.L"])) for p in motion("raise_arms", 6))
    assert raised > np.radians(60)
    seated = motion("sit_down", num_frames)[-1]
    assert np.linalg.norm(seated["upperleg01.L"]) > np.radians(70) and np.linalg.norm(seated["lowerleg01.L"]) > 1.0
    with pytest.raises(ValueError, match="at least 5 frames"):
        motion("turn", 3)
    with pytest.raises(ValueError, match="unknown motion"):
        motion("dance", 4)


def test_resample_poses_keeps_keyframes_and_slerps_between():
    from garsim.bodies.poses import resample_poses

    a = {"neck01": np.zeros(3)}
    b = {"neck01": np.array([0.0, 0.0, 0.8])}
    c = {"neck01": np.array([0.4, 0.0, 0.0])}
    out = resample_poses([a, b, c], 5)
    np.testing.assert_allclose([p["neck01"] for p in out[::2]], [a["neck01"], b["neck01"], c["neck01"]], atol=1e-12)
    np.testing.assert_allclose(out[1]["neck01"], [0.0, 0.0, 0.4], atol=1e-12)  # half way, about one axis
    even = resample_poses([a, b, c], 4)  # keyframes on frames 0, 2 (round(1.5)) and 3: the middle one still shown
    np.testing.assert_allclose(even[2]["neck01"], b["neck01"], atol=1e-12)
    assert len(resample_poses([a], 3)) == 3
    with pytest.raises(ValueError, match="at least 3 frames"):
        resample_poses([a, b, c], 2)


def test_read_pose_sequence_formats_agree(tmp_path):
    """Axis-angles, 3x3 and 4x4 matrices in JSON and one array per bone in an .npz read as the same poses; joint
    angles become the pose ``angles_to_pose`` makes."""
    import json

    from garsim.bodies.poses import angles_to_pose, read_pose_sequence, unbatch

    rv = np.array([[0.3, -0.2, 0.1], [0.0, 0.5, 0.0]])
    mats = roma.rotvec_to_rotmat(torch.as_tensor(rv)).numpy()
    homog = np.tile(np.eye(4), (2, 1, 1))
    homog[:, :3, :3] = mats
    (tmp_path / "a.json").write_text(json.dumps([{"neck01": r.tolist()} for r in rv]))
    (tmp_path / "m.json").write_text(json.dumps({"frames": [{"neck01": m.tolist()} for m in mats]}))
    (tmp_path / "h.json").write_text(json.dumps([{"neck01": h.tolist()} for h in homog]))
    np.savez(tmp_path / "a.npz", neck01=rv)
    for name in ("a.json", "m.json", "h.json", "a.npz"):
        got = read_pose_sequence(tmp_path / name)
        np.testing.assert_allclose([p["neck01"] for p in got], rv, atol=1e-9, err_msg=name)
    (tmp_path / "j.json").write_text(json.dumps([{"hip_flexion_L": 30.0}]))
    (frame,) = read_pose_sequence(tmp_path / "j.json")
    for bone, r in unbatch(angles_to_pose({"hip_flexion_L": 30.0}), 0).items():
        np.testing.assert_allclose(frame[bone], r, atol=1e-12)
    (tmp_path / "x.txt").write_text("")
    with pytest.raises(ValueError, match="is .json or .npz"):
        read_pose_sequence(tmp_path / "x.txt")
    np.savez(tmp_path / "ragged.npz", neck01=rv, spine01=rv[:1])
    with pytest.raises(ValueError, match="one row per frame"):
        read_pose_sequence(tmp_path / "ragged.npz")
    (tmp_path / "mixed.json").write_text(json.dumps([{"neck01": [0, 0, 0]}, {"hip_flexion_L": 10}]))
    with pytest.raises(ValueError, match="frame 1 uses other names than frame 0"):
        read_pose_sequence(tmp_path / "mixed.json")
    (tmp_path / "rest.json").write_text(json.dumps([{}, {"hip_flexion_L": 30.0}, {}]))  # {}: every bone at rest
    rest = read_pose_sequence(tmp_path / "rest.json")
    assert rest[0] == {} and rest[2] == {} and set(rest[1]) == set(frame)
    (tmp_path / "latin1.json").write_bytes(b'[{"neck01": [0, 0, 0]}] \xe9')
    with pytest.raises(ValueError, match="latin1.json: not a readable pose file"):
        read_pose_sequence(tmp_path / "latin1.json")


def test_pose_values_out_of_any_range_are_refused_and_beyond_the_limits_warned(tmp_path, caplog):
    """Joint angles past 180 degrees and axis-angles past 2 pi (degrees given as radians) are refused; a joint angle
    inside 180 but beyond ``JointLimits`` (the training poses' range) is read with a warning."""
    import json
    import logging

    from garsim.bodies.poses import read_pose_sequence

    (tmp_path / "wild.json").write_text(json.dumps([{"hip_flexion_L": 30}, {"hip_flexion_L": 400}]))
    with pytest.raises(ValueError, match="frame 1: joint angles are degrees in \\[-180, 180\\]"):
        read_pose_sequence(tmp_path / "wild.json")
    (tmp_path / "deg.json").write_text(json.dumps([{"neck01": [0.0, 45.0, 0.0]}]))
    with pytest.raises(ValueError, match="turns by 45 rad"):
        read_pose_sequence(tmp_path / "deg.json")
    (tmp_path / "far.json").write_text(json.dumps([{"hip_flexion_L": 120.0}]))
    with caplog.at_level(logging.WARNING, logger="garsim.bodies.poses"):
        assert len(read_pose_sequence(tmp_path / "far.json")) == 1
    assert "hip_flexion_L=120 beyond the joint limits" in caplog.text
