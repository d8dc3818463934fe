"""CLOTH3D reader on a tiny synthetic sample folder written in CLOTH3D's format (info.mat, OBJ, .pc16)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io
import trimesh
from scipy.spatial.transform import Rotation

from garsim.data.cloth3d import (
    PC2_HEADER,
    REST_POSE,
    Cloth3DError,
    SmplBodyModel,
    list_garments,
    pc16_info,
    read_cloth3d_sample,
    read_obj,
    read_pc16,
    write_pc16,
)
from garsim.geometry.io import y_up_to_z_up

_SPHERE = trimesh.creation.icosphere(subdivisions=1)
# a "body" standing along SMPL's native up axis (Y): an ellipsoid 0.3 wide, 0.9 tall, root at the origin
NATIVE = (_SPHERE.vertices * np.array([0.3, 0.9, 0.3])).astype(np.float64)


def fake_body(betas: np.ndarray, pose: np.ndarray, trans: np.ndarray, gender: str) -> tuple[np.ndarray, np.ndarray]:
    """Stand-in for SMPL: the native Y-up ellipsoid scaled by 1 + betas[0], rotated by the root axis-angle."""
    assert gender in ("female", "male")
    rot = Rotation.from_rotvec(np.asarray(pose[:3])).as_matrix()
    return (NATIVE * (1.0 + betas[0])) @ rot.T + trans, _SPHERE.faces


T = 4
ZROT = np.pi / 2
BETAS = np.array([0.1] + [0.0] * 9)
# the garment: a ring of 12 vertices around the waist + 12 lower (a tube), Z up, root-relative
_ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
REST_GARMENT = np.concatenate(
    [np.stack([0.4 * np.cos(_ang), 0.4 * np.sin(_ang), np.full(12, z)], 1) for z in (0.0, -0.4)]
)
GARMENT_FACES = np.concatenate(
    [[[i, (i + 1) % 12, 12 + i], [(i + 1) % 12, 12 + (i + 1) % 12, 12 + i]] for i in range(12)]
)
YAWS = np.linspace(0.0, 0.6, T)  # frame t turns the body by YAWS[t] about the up axis


def frame_rotation(t: int) -> np.ndarray:
    """Root rotation of frame t: CLOTH3D's Y-up -> Z-up quarter turn, then a yaw about Z."""
    return Rotation.from_rotvec([0, 0, YAWS[t]]).as_matrix() @ Rotation.from_rotvec([np.pi / 2, 0, 0]).as_matrix()


def write_obj(path: Path, v: np.ndarray, f: np.ndarray) -> None:
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v] + ["vt 0.5 0.5"]
    lines += [f"f {a + 1}/1 {b + 1}/1 {c + 1}/1" for a, b, c in f]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture
def sample_dir(tmp_path: Path) -> Path:
    folder = tmp_path / "train" / "00042"
    folder.mkdir(parents=True)
    poses = np.zeros((72, T))
    poses[:3] = np.stack([Rotation.from_matrix(frame_rotation(t)).as_rotvec() for t in range(T)], 1)
    trans = np.stack([np.array([0.0, 0.1 * t, 1.0]) for t in range(T)], 1)
    info = {
        "poses": poses,
        "shape": BETAS,
        "gender": 1,
        "trans": trans,
        "zrot": ZROT,
        "outfit": {
            "Skirt": {"fabric": "denim", "texture": {"type": "color", "data": np.array([0.2, 0.3, 0.4])}, "gender": 1},
            "Jumpsuit": {"fabric": "silk", "texture": {"type": "color", "data": np.zeros(3)}, "gender": 1},
        },
    }
    scipy.io.savemat(folder / "info.mat", info)
    # the OBJ is stored with zrot applied (as CLOTH3D's rest garments are)
    rz = Rotation.from_rotvec([0, 0, ZROT]).as_matrix()
    write_obj(folder / "Skirt.obj", REST_GARMENT @ rz.T, GARMENT_FACES)
    # cache frames: the garment moving rigidly with the body root, root-relative, un-rotated
    frames = np.stack([REST_GARMENT @ Rotation.from_rotvec([0, 0, YAWS[t]]).as_matrix().T for t in range(T)])
    write_pc16(folder / "Skirt.pc16", frames)
    write_obj(folder / "Jumpsuit.obj", REST_GARMENT, GARMENT_FACES)
    write_pc16(folder / "Jumpsuit.pc16", frames)
    return folder


def test_pc16_round_trip_and_header(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    frames = rng.uniform(-1.5, 1.5, size=(3, 7, 3))
    path = write_pc16(tmp_path / "x.pc16", frames, start_frame=2.0, sample_rate=0.5)
    raw = path.read_bytes()
    assert raw[:12] == b"POINTCACHE2\0" and len(raw) == 32 + 3 * 7 * 3 * 2
    assert PC2_HEADER.unpack(raw[:32])[1:] == (1, 7, 2.0, 0.5, 3)
    back = read_pc16(path)
    assert back.dtype == np.float32 and back.shape == (3, 7, 3)
    np.testing.assert_array_equal(back, frames.astype(np.float16).astype(np.float32))
    assert np.max(np.abs(back - frames)) <= 1.5 * 2.0**-11  # float16: 11 significant bits
    np.testing.assert_array_equal(read_pc16(path, frames=[2, 0]), back[[2, 0]])
    assert pc16_info(path) == (3, 7)


def test_pc16_errors(tmp_path: Path) -> None:
    path = write_pc16(tmp_path / "x.pc16", np.zeros((4, 5, 3)))
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(Cloth3DError, match="truncated vertex cache.*4 frames x 5 points"):
        read_pc16(path)
    bad = tmp_path / "bad.pc16"
    bad.write_bytes(b"NOTACACHE___" + bytes(20))
    with pytest.raises(Cloth3DError, match="not a Point Cache 2"):
        read_pc16(bad)
    with pytest.raises(Cloth3DError, match="frame 9 out of range"):
        read_pc16(write_pc16(tmp_path / "y.pc16", np.zeros((2, 5, 3))), frames=[9])
    with pytest.raises(Cloth3DError, match="float16 range"):
        write_pc16(tmp_path / "z.pc16", np.full((1, 2, 3), 1e6))


def test_read_obj_keeps_file_order_and_triangulates_quads(tmp_path: Path) -> None:
    p = tmp_path / "q.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n")
    v, f = read_obj(p)
    np.testing.assert_array_equal(v, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    np.testing.assert_array_equal(f, [[0, 1, 2], [0, 2, 3]])


def test_reads_samples_in_garsim_axes(sample_dir: Path) -> None:
    assert list_garments(sample_dir) == ["Skirt", "Jumpsuit"]
    samples = read_cloth3d_sample(sample_dir, "Skirt", body_model=fake_body)
    assert len(samples) == T and [s.meta["frame"] for s in samples] == list(range(T))
    s0 = samples[0]
    assert s0.fabric == "denim" and s0.garment_type == "skirt" and s0.meta["gender"] == "male"
    assert not s0.pinned.any() and s0.pinned.shape == (24,)
    # canonical body: SMPL's native Y-up output turned Z-up by the rest pose's root quarter turn;
    # hand-computed: the native top vertex (0, 0.9 * 1.1, 0) ends up at (0, 0, 0.99)
    top = int(np.argmax(NATIVE[:, 1]))
    assert NATIVE[top, 1] == pytest.approx(0.9)
    np.testing.assert_allclose(s0.body_canonical[top], [0.0, 0.0, 0.99], atol=1e-6)
    np.testing.assert_allclose(s0.body_canonical, y_up_to_z_up(NATIVE * 1.1), atol=1e-6)
    extent = s0.body_canonical.max(0) - s0.body_canonical.min(0)
    assert np.argmax(extent) == 2  # tallest along Z
    # template: the OBJ with its baked-in zrot undone; hand-computed: stored (0, 0.4, 0) -> (0.4, 0, 0)
    np.testing.assert_allclose(s0.garment, REST_GARMENT, atol=1e-5)
    np.testing.assert_allclose(s0.garment[0], [0.4, 0.0, 0.0], atol=1e-5)
    for t, s in enumerate(samples):
        yaw = Rotation.from_rotvec([0, 0, YAWS[t]]).as_matrix()
        np.testing.assert_allclose(s.target, REST_GARMENT @ yaw.T, atol=1e-3)  # float16 cache
        np.testing.assert_allclose(s.body_target, s0.body_canonical @ yaw.T, atol=1e-5)
        # the body moves rigidly, so the rig-free prior is exactly the rigidly moved template
        np.testing.assert_allclose(s.prior, REST_GARMENT @ yaw.T, atol=1e-4)
        assert s.meta["trans"] == pytest.approx([0.0, 0.1 * t, 1.0])


def test_frames_subset_and_world_placement(sample_dir: Path) -> None:
    samples = read_cloth3d_sample(sample_dir, "Skirt", frames=[3, 1], body_model=fake_body, world=True)
    assert [s.meta["frame"] for s in samples] == [3, 1]
    rz = Rotation.from_rotvec([0, 0, ZROT]).as_matrix()
    s = samples[0]
    yaw = Rotation.from_rotvec([0, 0, YAWS[3]]).as_matrix()
    tr = np.array([0.0, 0.3, 1.0])
    # starter kit's absolute placement: (cache + trans) rotated by zrot; the OBJ as stored
    np.testing.assert_allclose(s.target, (REST_GARMENT @ yaw.T + tr) @ rz.T, atol=1e-3)
    np.testing.assert_allclose(s.garment, REST_GARMENT @ rz.T, atol=1e-5)
    np.testing.assert_allclose(s.body_target, (y_up_to_z_up(NATIVE * 1.1) @ yaw.T + tr) @ rz.T, atol=1e-5)
    np.testing.assert_allclose(s.body_canonical, y_up_to_z_up(NATIVE * 1.1) @ rz.T, atol=1e-5)


def test_errors(sample_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(Cloth3DError, match="no garment 'Dress'.*Skirt"):
        read_cloth3d_sample(sample_dir, "Dress", body_model=fake_body)
    with pytest.raises(Cloth3DError, match="'Jumpsuit' has no garsim type"):
        read_cloth3d_sample(sample_dir, "Jumpsuit", body_model=fake_body)
    with pytest.raises(Cloth3DError, match="no info.mat"):
        read_cloth3d_sample(tmp_path, "Skirt", body_model=fake_body)
    with pytest.raises(Cloth3DError, match="frame 7 out of range"):
        read_cloth3d_sample(sample_dir, "Skirt", frames=[7], body_model=fake_body)
    with pytest.raises(Cloth3DError, match="pass model_path="):
        read_cloth3d_sample(sample_dir, "Skirt")
    # vertex count mismatch between OBJ and cache
    write_pc16(sample_dir / "Skirt.pc16", np.zeros((T, 20, 3)))
    with pytest.raises(Cloth3DError, match="20 points but Skirt.obj has 24 vertices"):
        read_cloth3d_sample(sample_dir, "Skirt", body_model=fake_body)
    # truncated cache
    data = np.zeros((T, 24, 3))
    raw = write_pc16(sample_dir / "Skirt.pc16", data).read_bytes()
    (sample_dir / "Skirt.pc16").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(Cloth3DError, match="truncated vertex cache"):
        read_cloth3d_sample(sample_dir, "Skirt", body_model=fake_body)
    # NaN in a frame
    data[2, 5, 1] = np.nan
    header = PC2_HEADER.pack(b"POINTCACHE2\0", 1, 24, 0.0, 1.0, T)
    (sample_dir / "Skirt.pc16").write_bytes(header + data.astype("<f2").tobytes())
    with pytest.raises(Cloth3DError, match="frame 2 contains NaN"):
        read_cloth3d_sample(sample_dir, "Skirt", body_model=fake_body)
    assert len(read_cloth3d_sample(sample_dir, "Skirt", frames=[0, 3], body_model=fake_body)) == 2
    # missing OBJ / cache
    (sample_dir / "Skirt.pc16").unlink()
    with pytest.raises(Cloth3DError, match="Skirt.pc16: vertex cache not found"):
        read_cloth3d_sample(sample_dir, "Skirt", body_model=fake_body)
    (sample_dir / "Skirt.obj").unlink()
    with pytest.raises(Cloth3DError, match="garment OBJ not found"):
        read_cloth3d_sample(sample_dir, "Skirt", body_model=fake_body)


def test_default_smpl_body_gives_clear_errors(sample_dir: Path, tmp_path: Path, monkeypatch) -> None:
    with pytest.raises(Cloth3DError, match="SMPL model files not found in .*SMPL_MALE.pkl.*licensed"):
        read_cloth3d_sample(sample_dir, "Skirt", model_path=tmp_path / "no_such_folder")
    # model files present but smplx missing -> says to pip install smplx (forced, whether or not it is installed)
    models = tmp_path / "models" / "smpl"
    models.mkdir(parents=True)
    (models / "SMPL_MALE.pkl").write_bytes(b"placeholder")
    monkeypatch.setitem(sys.modules, "smplx", None)
    with pytest.raises(Cloth3DError, match="pip install smplx"):
        SmplBodyModel(tmp_path / "models")(BETAS, REST_POSE, np.zeros(3), "male")
