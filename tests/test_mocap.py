"""Demonstrations: the authors' release (when present beside the repo), the project's
synthetic files, and the loader's errors. CPU only, a few seconds."""

from __future__ import annotations

import dataclasses
import functools
import itertools
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from conftest import real_data_or_skip
from hypothesis import event, given, settings
from hypothesis import strategies as st

from mjx_hands import hand_kinematics, mocap, synthetic_demos, tasks
from mjx_hands.shadow_hand import HAND_JOINTS, HAND_POINTS

COUNTS = {"handshake": 10, "handclap": 9, "et": 5}
FF = HAND_POINTS.index("fftip")


@pytest.fixture(scope="module")
def real():
    root = real_data_or_skip()
    return {t: mocap.load_optitrack(t, root) for t in tasks.RELEASE_TASKS}


@pytest.fixture(scope="module")
def synthetic():
    return {t: mocap.load_demonstrations(t, source="synthetic") for t in mocap.TASKS}


def _mean_rotation(r: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(r.mean(0))
    return u @ vt


def _contact_pose(demos):
    pos = np.array([d.actor_points[d.contact_begin, 0] for d in demos])
    rot = np.array([d.actor_palm_rot[d.contact_begin] for d in demos])
    return pos.mean(0), _mean_rotation(rot)


# ------------------------------------------------------------------------- real data
def test_real_loads_with_schema_and_ranges(real):
    lower, upper = hand_kinematics.joint_range()
    for task, demos in real.items():
        assert len(demos) == COUNTS[task]
        for i, d in enumerate(demos):
            d.validate()
            assert d.task == task and d.source == "optitrack"
            assert d.name == f"{task}/optitrack/{i:02d}"
            assert d.fps == mocap.DEFAULT_FPS
            assert d.contact_end == d.num_frames - 1
            for joints in (d.actor_joints, d.target_joints):
                assert np.all(joints >= lower) and np.all(joints <= upper)
            assert np.all(d.actor_joints[:, HAND_JOINTS.index("THJ0")] <= 0)  # sign flipped
            np.testing.assert_allclose(d.target_points[:, 0], 0.0, atol=1e-12)
            np.testing.assert_allclose(
                d.target_frames[:, 0], np.broadcast_to(np.eye(3), (d.num_frames, 3, 3))
            )
            rot = d.actor_palm_rot
            np.testing.assert_allclose(
                rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-9
            )


def test_approach_start_moves_only_windows_that_begin_together():
    # Palms 0.5 m apart, approaching from frame 100 to 200 (to 0.2 m), together until 260.
    distance = np.concatenate([np.full(100, 0.5), np.linspace(0.5, 0.2, 100), np.full(60, 0.2)])
    # A window that starts together at 220 begins where the palms were 0.2 m farther apart.
    start = mocap.approach_start(distance, 220, 250)
    assert start < 220 and distance[start] > 0.2 + mocap.APPROACH_FAR
    assert distance[start + 1] <= 0.2 + mocap.APPROACH_FAR + 1e-12  # the last such frame
    # One that starts during the approach, far enough out, stays.
    assert mocap.approach_start(distance, 110, 250) == 110
    # Never before `first` (e.g. the previous demonstration): none far enough since -> as is.
    assert mocap.approach_start(distance, 220, 250, first=180) == 220


def test_real_palms_approach_and_touch(real):
    # Approach: palm-centre distance falls towards contact (the hand clap's release
    # windows start at the clap; the loader moves them back to the approach).
    real_data_or_skip()
    for task in tasks.RELEASE_TASKS:
        for d in real[task]:
            dist = np.linalg.norm(d.actor_points[:, 0], axis=-1)
            assert dist[0] > dist[d.contact_begin] + 0.05, d.name
    # Contact: handshake palms close; handshake and clap palms a palm thickness apart
    # along the target's palm normal (-y); E.T. index tips together.
    for d in real["handshake"]:
        window = d.actor_points[d.contact_begin :, 0]
        assert np.linalg.norm(window, axis=-1).max() < 0.15, d.name
    for d in real["handshake"] + real["handclap"]:
        normal_gap = -d.actor_points[d.contact_begin, 0, 1]
        assert 0.0 < normal_gap < 0.06, d.name
        assert d.actor_palm_rot[d.contact_begin, 1, 1] < -0.9, d.name  # palms face each other
    for d in real["handclap"]:
        assert np.linalg.norm(d.actor_points[d.contact_begin, 0]) < 0.25, d.name
    for d in real["et"]:
        tips = np.linalg.norm(
            d.actor_points[d.contact_begin, FF] - d.target_points[d.contact_begin, FF]
        )
        assert tips < 0.03, d.name


def test_real_clap_demonstrations_begin_with_their_approach(real):
    root = real_data_or_skip()
    from mjx_hands import reward_params as rp

    for d in real["handclap"]:
        dist = np.linalg.norm(d.actor_points[:, 0], axis=-1)
        closest = int(np.argmin(dist[: d.contact_end + 1]))
        assert closest / d.fps > 0.75, d.name  # >= 0.75 s of approach before the clap
        assert rp.imitation_length(d) >= 25, d.name  # imitated over >= 1 s, was 3-11 steps
    # Handshake and E.T. windows already begin with the approach: the rule leaves the
    # rows the authors trained on as the release has them.
    for task in ("handshake", "et"):
        plain = mocap.load_optitrack(task, root, approach=False)
        for d, p in zip(real[task], plain):
            if int(d.name[-2:]) in tasks.spec(task).authors_demos:
                assert d.num_frames == p.num_frames, d.name


def test_real_fingertip_order_and_calibration():
    root = real_data_or_skip()
    measured, modelled = mocap.calibration_samples(root)
    cal = mocap.fit_palm_calibration(measured, modelled)
    assert cal.rms < 0.03 and np.all(cal.finger_rms[1:] < 0.03) and cal.finger_rms[0] < 0.05
    # The release's fingertip order (th, ff, mf, rf, lf) fits better than any other order.
    others = [
        mocap.fit_palm_calibration(measured[:, list(p)], modelled).rms
        for p in itertools.permutations(range(5))
        if p != (0, 1, 2, 3, 4)
    ]
    assert cal.rms < 0.95 * min(others)
    # Close to the authors' fixed alignment, with the rigid body ~4-5 cm on the back of the hand.
    assert np.degrees(mocap.rotation_angle(cal.rotation, mocap.ORIGINAL_PALM_ALIGNMENT)) < 30
    assert 0.02 < cal.offset[1] < 0.07
    # The palm contact (independent of the fit, which saw only one hand): with the fitted
    # calibration handshake palms are ~2 cm apart, with the authors' alignment ~5 cm.
    gap = lambda c: np.mean(
        [
            -d.actor_points[d.contact_begin, 0, 1]
            for d in mocap.load_optitrack("handshake", root, calibration=c)
        ]
    )
    assert 0.01 < gap(cal) < 0.035 < gap(mocap.ORIGINAL_CALIBRATION)


def test_real_joint_rows_end_aligned():
    # Row i of the joint arrays is capture frame i + (T - T_joints): the finger-body
    # quaternions' rotation rates correlate with the joint rates at exactly that lag.
    root = real_data_or_skip()
    rel = mocap.read_release("handshake", root)
    q = np.load(root / "handshake_rot_human.npy").reshape(-1, 6, 4)
    r = mocap.quat_xyzw_to_matrix(q)
    bend = np.degrees(mocap.rotation_angle(r[:, 0], r[:, 3]))  # palm vs middle finger
    mf = [HAND_JOINTS.index("MFJ2"), HAND_JOINTS.index("MFJ1")]
    flex = np.abs(rel.target_joints[:, mf]).sum(-1)
    rate = lambda x, lag: np.diff(x)[rel.joint_offset + 10 + lag : -10 + lag]
    corr = {lag: np.corrcoef(rate(flex, 0), rate(bend, lag))[0, 1] for lag in (-1, 0, 1)}
    assert rel.joint_offset == 1
    assert corr[0] > 0.5 and corr[0] > 3 * max(abs(corr[-1]), abs(corr[1]))


def test_real_capture_frame_y_up_becomes_z_up():
    root = real_data_or_skip()
    cal = mocap.estimate_palm_calibration(root)
    rel = mocap.read_release("handshake", root)
    palm_axes = rel.target_rot @ cal.rotation.T  # Shadow palm axes in the sim world
    # Hands hanging at the sides (palms farthest apart): fingers (+z_palm) point down.
    dist = np.linalg.norm(rel.palm_vec, axis=-1)
    rest = dist > np.quantile(dist, 0.9)
    assert palm_axes[rest, 2, 2].mean() < -0.8
    # Handshake contact: thumbs (+x_palm) point up.
    contact = rel.windows[:, 1]
    assert palm_axes[contact, 2, 0].mean() > 0.8
    actor_axes = rel.actor_rot[contact] @ cal.rotation.T
    assert actor_axes[:, 2, 0].mean() > 0.8


def test_real_fps_gives_human_speeds():
    # Peak palm-to-palm approach speed (5-frame smoothing) at the default rate: humans
    # reach at ~0.3-2 m/s. A rate of 60 or 480 Hz would leave that range.
    rel = mocap.read_release("handshake", real_data_or_skip())
    kernel = np.ones(5) / 5
    smooth = np.stack([np.convolve(rel.palm_vec[:, i], kernel, "same") for i in range(3)], -1)
    step = np.linalg.norm(np.diff(smooth, axis=0), axis=-1)  # metres per frame
    peaks = np.array([step[max(c0 - 400, 0) : c0].max() for _, c0, _ in rel.windows])
    speed = peaks * mocap.DEFAULT_FPS
    assert np.all((speed > 0.3) & (speed < 2.0))
    assert np.all(peaks * 480 > 2.0) and np.all(peaks * 60 < 0.4)
    # Handshake hold (palms within 3 cm of their contact distance): human handshakes keep
    # contact 1.96 +- 0.46 s (Frontiers in Robotics and AI 9:758519, 2022).
    dist = np.linalg.norm(rel.palm_vec, axis=-1)
    holds = []
    for _, c0, _ in rel.windows:
        near = dist < dist[c0] + 0.03
        a, b = c0, c0
        while near[a - 1]:
            a -= 1
        while near[b + 1]:
            b += 1
        holds.append((b - a) / mocap.DEFAULT_FPS)
    assert 1.96 - 0.46 < np.median(holds) < 1.96 + 0.46


def test_auto_source_prefers_real_data():
    root = real_data_or_skip()
    demos = mocap.load_demonstrations("et", source="auto", path=root)
    assert demos[0].source == "optitrack" and len(demos) == COUNTS["et"]
    if mocap.REAL_DATA_PATH.resolve() == root.resolve():
        assert mocap.load_demonstrations("et")[0].source == "optitrack"


# ----------------------------------------------------------------------- synthetic data
def test_synthetic_loads(synthetic):
    # Every registered task trains from a fresh clone: designed or imported files.
    for task, demos in synthetic.items():
        assert len(demos) >= 5
        for i, d in enumerate(demos):
            d.validate()
            name = f"{task}/synthetic/{i:02d}"
            if tasks.spec(task).synthetic_takes:  # imported takes' names
                name = name.replace("c/", "c-")
            assert (d.task, d.source, d.name) == (task, "synthetic", name)
            assert 1.5 <= d.num_frames / d.fps <= 3.0
            assert d.contact_begin / d.fps >= 1.0 and d.contact_end == d.num_frames - 1
            start = np.linalg.norm(d.actor_points[0, 0] - d.actor_points[d.contact_begin, 0])
            assert 0.29 < start < 0.46


def test_synthetic_files_match_regeneration(tmp_path):
    # Tasks written as takes regenerate through the importer (synthetic_demos.write_task).
    for task in synthetic_demos.designed_tasks():
        with np.load(mocap.SYNTHETIC_PATH / f"{task}.npz", allow_pickle=False) as stored:
            if tasks.spec(task).synthetic_takes:
                fresh = dict(np.load(synthetic_demos.write_task(task, tmp_path)))
            else:
                fresh = mocap.demos_to_arrays(synthetic_demos.generate_task(task))
            assert set(stored.files) == set(fresh)
            for key, value in fresh.items():
                if value.dtype.kind in "fc":
                    np.testing.assert_allclose(stored[key], value, atol=1e-6, err_msg=key)
                else:
                    np.testing.assert_array_equal(stored[key], value, err_msg=key)


def test_synthetic_generator_is_deterministic():
    a, b = synthetic_demos.generate_task("et", num=2), synthetic_demos.generate_task("et", num=2)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.actor_points, y.actor_points)
        np.testing.assert_array_equal(x.actor_joints, y.actor_joints)


def test_synthetic_contacts_hold(synthetic):
    for d in synthetic["handshake"] + synthetic["handclap"]:
        c = d.contact_begin
        assert 0.01 < -d.actor_points[c, 0, 1] < 0.04 and d.actor_palm_rot[c, 1, 1] < -0.9
    for d in synthetic["et"]:
        c = d.contact_begin
        assert np.linalg.norm(d.actor_points[c, FF] - d.target_points[c, FF]) < 0.02
    for d in synthetic["handshake"]:  # fingers close during the approach
        assert (
            d.actor_joints[d.contact_begin, HAND_JOINTS.index("RFJ2")]
            > d.actor_joints[0, HAND_JOINTS.index("RFJ2")] + 0.2
        )


def test_synthetic_contact_poses_match_real_data(real, synthetic):
    # The hand-designed contacts lie within 3 cm / 20 deg of the recordings' mean actor
    # palm pose at contact_begin (real per-demonstration spread: 1-2 cm, 5-10 deg).
    for task in tasks.RELEASE_TASKS:
        pos_r, rot_r = _contact_pose(real[task])
        pos_s, rot_s = _contact_pose(synthetic[task])
        assert np.linalg.norm(pos_r - pos_s) < 0.03, task
        assert np.degrees(mocap.rotation_angle(rot_r, rot_s)) < 20, task


# ------------------------------------------------------------------------------ errors
def _fake_release(
    root: Path, task: str = "handshake", frames: int = 40, joint_offset: int | None = None
) -> Path:
    """A small release of one task: two windows, joint rows end-aligned like the authors'."""
    if joint_offset is None:
        joint_offset = mocap.RELEASE_JOINT_OFFSET[task]
    rng = np.random.default_rng(0)
    q = np.tile([0.0, 0.0, 0.0, 1.0], 6)
    palm = np.array([0.0, 0.0, 0.2]) + rng.normal(0, 0.01, (frames, 3))
    tips = palm[:, None] + rng.normal(0, 0.05, (frames, 5, 3))
    arrays = {
        "interaction_t": np.array([[5, 20, 30], [10, 25, 39]]),
        "distance_array_palms": palm[:, None, None],
        "distance_array_palms_1": np.concatenate([palm[:, None], tips], 1)[:, None],
        "rot_human": np.tile(q, (frames, 1)),
        "rot_robot": np.tile(q, (frames, 1)),
        "joint_angles_human": np.zeros((frames - joint_offset, 20)),
        "joint_angles_robot": np.zeros((frames - joint_offset, 20)),
    }
    for name, value in arrays.items():
        np.save(root / f"{task}_{name}.npy", value)
    return root


def _load(root, task="handshake"):
    return mocap.load_optitrack(task, root, calibration=mocap.ORIGINAL_CALIBRATION)


def test_fake_release_loads(tmp_path):
    demos = _load(_fake_release(tmp_path))
    assert [d.num_frames for d in demos] == [26, 30] and demos[1].contact_begin == 15


def test_error_missing_file(tmp_path):
    root = _fake_release(tmp_path)
    (root / "handshake_rot_robot.npy").unlink()
    with pytest.raises(mocap.MocapError, match="handshake_rot_robot.npy"):
        _load(root)


def test_error_wrong_shape(tmp_path):
    root = _fake_release(tmp_path)
    np.save(root / "handshake_joint_angles_robot.npy", np.zeros((39, 19)))
    with pytest.raises(
        mocap.MocapError, match=r"handshake_joint_angles_robot.npy: expected shape \(N, 20\)"
    ):
        _load(root)


def test_error_nan_inside_window(tmp_path):
    root = _fake_release(tmp_path)
    palms = np.load(root / "handshake_distance_array_palms.npy")
    palms[2] = np.nan  # before every window: ignored
    np.save(root / "handshake_distance_array_palms.npy", palms)
    _load(root)
    palms[12] = np.nan
    np.save(root / "handshake_distance_array_palms.npy", palms)
    with pytest.raises(mocap.MocapError, match="distance_array_palms.*frame 12"):
        _load(root)


def test_error_window_out_of_range(tmp_path):
    root = _fake_release(tmp_path)
    np.save(root / "handshake_interaction_t.npy", np.array([[5, 20, 40]]))
    with pytest.raises(mocap.MocapError, match="interaction_t.npy row 0"):
        _load(root)


def test_error_unknown_task_and_source(tmp_path):
    with pytest.raises(mocap.MocapError, match="handshake, handclap, et"):
        mocap.load_demonstrations("highfive")
    with pytest.raises(mocap.MocapError, match="handshake, handclap, et"):
        mocap.load_optitrack("highfive", tmp_path)
    with pytest.raises(mocap.MocapError, match="auto, optitrack, synthetic"):
        mocap.load_demonstrations("et", source="vicon")
    with pytest.raises(mocap.MocapError, match="synthetic_demos"):
        mocap.load_demonstrations("et", source="synthetic", path=tmp_path)
    with pytest.raises(mocap.MocapError, match="mocap folder /nonexistent does not exist"):
        mocap.load_demonstrations("et", path="/nonexistent")


def test_error_validate_names_field(synthetic):
    d = synthetic["et"][0]
    bad = d.actor_points.copy()
    bad[3, 2, 1] = np.nan
    with pytest.raises(mocap.MocapError, match="actor_points"):
        mocap.Demonstration(**{**d.__dict__, "actor_points": bad}).validate()
    with pytest.raises(mocap.MocapError, match="target_frames"):
        mocap.Demonstration(**{**d.__dict__, "target_frames": d.target_frames[:, :5]}).validate()
    with pytest.raises(mocap.MocapError, match="contact_end"):
        mocap.Demonstration(**{**d.__dict__, "contact_end": d.num_frames}).validate()


def test_error_corrupt_synthetic_file(tmp_path):
    arrays = mocap.demos_to_arrays(synthetic_demos.generate_task("handclap", num=1))
    arrays["actor_joints"] = arrays["actor_joints"][:-1]
    np.savez(tmp_path / "handclap.npz", **arrays)
    with pytest.raises(mocap.MocapError, match="actor_joints must have shape"):
        mocap.load_synthetic("handclap", tmp_path)


# ------------------------------------------- strict loaders: damaged, wrong or empty data
def _tiny_arrays(task: str = "handclap") -> dict[str, np.ndarray]:
    """The npz layout of two short demonstrations (6 and 5 frames), float32 like the files."""
    rng = np.random.default_rng(1)
    frames = 11
    quat = np.concatenate([np.ones((frames, 1)), rng.normal(0, 0.1, (frames, 3))], 1)
    palm = np.array([0.05, -0.02, 0.2]) + rng.normal(0, 0.02, (frames, 3))
    return {
        "schema_version": np.int64(mocap.SCHEMA_VERSION),
        "task": np.str_(task),
        "names": np.array([f"{task}/synthetic/00", f"{task}/synthetic/01"]),
        "fps": np.array([120.0, 120.0]),
        "num_frames": np.array([6, 5]),
        "contact_begin": np.array([3, 2]),
        "contact_end": np.array([5, 4]),
        "actor_joints": rng.uniform(-0.2, 0.2, (frames, 20)).astype(np.float32),
        "target_joints": rng.uniform(-0.2, 0.2, (frames, 20)).astype(np.float32),
        "actor_palm_pos": palm.astype(np.float32),
        "actor_palm_quat": (quat / np.linalg.norm(quat, axis=1, keepdims=True)).astype(np.float32),
    }


def _write_npz(root: Path, arrays: dict, compressed: bool = True, task: str = "handclap") -> Path:
    file = root / f"{task}.npz"
    (np.savez_compressed if compressed else np.savez)(file, **arrays)
    return file


def _assert_same(a: list[mocap.Demonstration], b: list[mocap.Demonstration]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        for field in dataclasses.fields(x):
            np.testing.assert_array_equal(getattr(x, field.name), getattr(y, field.name))


def _assert_plausible(demos: list[mocap.Demonstration], slack: float = 0.0) -> None:
    """Valid demonstrations whose palm positions and joints are inside the documented bounds."""
    lower, upper = hand_kinematics.joint_range()
    assert demos
    for d in demos:
        d.validate()
        assert np.all(np.linalg.norm(d.actor_points[:, 0], axis=-1) <= mocap.POSITION_BOUND + slack)
        for joints in (d.actor_joints, d.target_joints):
            assert np.all(joints >= lower) and np.all(joints <= upper)


# Case 1: damaged archives and members of the wrong type.
@pytest.mark.parametrize("how", ["truncated", "bad_crc", "empty", "garbage"])
def test_error_damaged_npz_names_file(tmp_path, how):
    arrays = _tiny_arrays()
    file = _write_npz(tmp_path, arrays, compressed=False)
    data = file.read_bytes()
    if how == "truncated":
        data = data[: len(data) // 2]
    elif how == "bad_crc":  # one flipped byte inside actor_joints' stored data
        at = data.index(arrays["actor_joints"].tobytes()[:32]) + 8
        data = data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1 :]
    elif how == "empty":
        data = b""
    else:
        data = bytes(range(256)) * 8
    file.write_bytes(data)
    with pytest.raises(mocap.MocapError, match=re.escape(str(file))):
        mocap.load_synthetic("handclap", tmp_path)


@pytest.mark.parametrize(
    "key, value",
    [
        ("schema_version", np.array([1, 1])),
        ("actor_joints", np.full((11, 20), "0.1")),
        ("names", np.array(["handclap/synthetic/00", "handclap/synthetic/01"], dtype=object)),
        ("fps", np.array([120.0, 120.0], dtype=object)),
    ],
)
def test_error_npz_member_type_names_file_and_array(tmp_path, key, value):
    file = _write_npz(tmp_path, {**_tiny_arrays(), key: value})
    with pytest.raises(mocap.MocapError, match=f"{re.escape(str(file))}: .*{key}"):
        mocap.load_synthetic("handclap", tmp_path)


# Case 2: every array's dtype is checked (nothing is converted into wrong angles).
@pytest.mark.parametrize("dtype", [bool, np.int64, "datetime64[s]", str, np.complex128])
def test_error_release_joint_angle_dtype(tmp_path, dtype):
    root = _fake_release(tmp_path)
    file = root / "handshake_joint_angles_robot.npy"
    joints = np.load(file) + 0.5
    if dtype == "datetime64[s]":
        bad = joints.astype(np.int64).astype(dtype)
    elif dtype is np.complex128:
        bad = joints + 0.1j  # the imaginary part would be dropped
    else:
        bad = joints.astype(dtype)
    np.save(file, bad)
    match = f"handshake_joint_angles_robot.npy: .*{re.escape(str(bad.dtype))}.*float"
    with pytest.raises(mocap.MocapError, match=match):
        _load(root)


def test_release_accepts_real_float_dtypes(tmp_path):
    root = _fake_release(tmp_path)
    expected = _load(root)
    for dtype in (np.float32, np.float16, ">f8"):
        for name in ("joint_angles_human", "joint_angles_robot", "rot_robot"):
            file = root / f"handshake_{name}.npy"
            np.save(file, np.load(file).astype(dtype))
        demos = _load(root)
        for d, e in zip(demos, expected):
            np.testing.assert_allclose(d.actor_palm_rot, e.actor_palm_rot, atol=1e-3)


@pytest.mark.parametrize(
    "key, dtype, expected",
    [
        ("actor_joints", np.complex64, "float"),
        ("num_frames", np.float64, "integer"),
        ("names", np.int64, "str"),
        ("fps", bool, "float"),
        ("task", "S9", "str"),
        ("contact_begin", "datetime64[s]", "integer"),
    ],
)
def test_error_npz_member_dtype(tmp_path, key, dtype, expected):
    arrays = _tiny_arrays()
    value = arrays[key]
    value = value.astype(np.int64).astype(dtype) if key == "contact_begin" else value
    value = np.zeros(value.shape, dtype) if key == "names" else value.astype(dtype)
    file = _write_npz(tmp_path, {**arrays, key: value})
    match = f"{re.escape(str(file))}: {key} .*{re.escape(str(value.dtype))}.*{expected}"
    with pytest.raises(mocap.MocapError, match=match):
        mocap.load_synthetic("handclap", tmp_path)


# Case 3: joint rows cannot shift silently against the capture frames.
def test_error_release_joint_rows_cut_short(tmp_path):
    root = _fake_release(tmp_path)
    for side in ("human", "robot"):
        file = root / f"handshake_joint_angles_{side}.npy"
        np.save(file, np.load(file)[:-2])
    with pytest.raises(mocap.MocapError, match=r"joint_angles_human.npy: .*37.*40.*expected 39"):
        _load(root)


def test_error_release_npy_header_claims_fewer_rows(tmp_path):
    root = _fake_release(tmp_path)
    for side in ("human", "robot"):
        file = root / f"handshake_joint_angles_{side}.npy"
        data = file.read_bytes()
        file.write_bytes(data.replace(b"(39, 20)", b"(38, 20)", 1))
    with pytest.raises(mocap.MocapError, match="handshake_joint_angles_human.npy"):
        _load(root)


def test_release_joint_offset_parameter(tmp_path):
    (tmp_path / "a").mkdir()
    root = _fake_release(tmp_path / "a", joint_offset=3)  # a release with 3 frames unjointed
    with pytest.raises(mocap.MocapError, match=r"joint_angles_human.npy: .*expected 39"):
        _load(root)
    assert mocap.read_release("handshake", root, joint_offset=3).joint_offset == 3
    demos = mocap.load_optitrack(
        "handshake", root, calibration=mocap.ORIGINAL_CALIBRATION, joint_offset=3
    )
    assert [d.num_frames for d in demos] == [26, 30]
    # The default calibration reads this task with the given offset too.
    assert len(mocap.load_optitrack("handshake", root, joint_offset=3)) == 2
    (tmp_path / "et").mkdir()
    et = _fake_release(tmp_path / "et", "et")  # E.T.'s default offset is 3
    assert mocap.read_release("et", et).joint_offset == mocap.RELEASE_JOINT_OFFSET["et"] == 3


# Case 4: plausibility bounds, with the numbers in the message.
@pytest.mark.parametrize(
    "name, index, value, match",
    [
        ("distance_array_palms", (12, 0, 0, 0), 1e6, r"frame 12.*got 1e\+06 m, expected 0\.\.3 m"),
        ("distance_array_palms", (12, 0, 0, 0), 1e308, r"frame 12.*got 1e\+308 m"),
        ("joint_angles_robot", (20, 3), 4.0, r"frame 21.*THJ3.*got 4 rad.*3\.14159"),
        ("rot_robot", (15, slice(0, 4)), [0, 0, 0, 0.7], r"frame 15.*got 0\.7, expected 0\.9"),
        ("rot_human", (15, slice(0, 4)), [0, 0, 0, 2.0], r"frame 15.*got 2, expected"),
    ],
)
def test_error_release_implausible_inside_window(tmp_path, name, index, value, match):
    root = _fake_release(tmp_path)
    file = root / f"handshake_{name}.npy"
    array = np.load(file)
    array[index] = value
    np.save(file, array)
    with pytest.raises(mocap.MocapError, match=f"handshake_{name}.npy: .*{match}"):
        _load(root)


def test_release_outside_windows_keeps_dropouts(tmp_path):
    root = _fake_release(tmp_path)
    expected = _load(root)
    for name, index, value in [
        ("rot_robot", (2, slice(0, 4)), 0.0),  # dropout: zero quaternion
        ("rot_human", (3, slice(0, 4)), np.nan),
        ("joint_angles_robot", (1, 4), 1e6),  # frame 2: before every window
    ]:
        file = root / f"handshake_{name}.npy"
        array = np.load(file)
        array[index] = value
        np.save(file, array)
    _assert_same(_load(root), expected)


def test_error_release_implausible_calibration_frame(tmp_path):
    root = _fake_release(tmp_path)
    file = root / "handshake_distance_array_palms_1.npy"
    array = np.load(file)
    array[3, 0, 2] = [1e6, 0.0, 0.0]  # frame 3 enters the calibration fit (lead-in)
    np.save(file, array)
    with pytest.raises(mocap.MocapError, match=r"palms_1.npy: .*frame 3.*got 1e\+06 m"):
        mocap.load_optitrack("handshake", root)


@pytest.mark.parametrize(
    "key, index, value, match",
    [
        ("actor_palm_pos", (7, 2), 1e6, r"row 7.*got 1e\+06 m, expected 0\.\.3 m"),
        ("target_joints", (3, 5), 4.0, r"row 3.*THJ1.*got 4 rad"),
        ("actor_palm_quat", (9,), [0.5, 0.0, 0.0, 0.0], r"row 9.*got 0\.5, expected 0\.9"),
    ],
)
def test_error_npz_implausible_values(tmp_path, key, index, value, match):
    arrays = _tiny_arrays()
    arrays[key][index] = value
    file = _write_npz(tmp_path, arrays)
    with pytest.raises(mocap.MocapError, match=f"{re.escape(str(file))}: {key} .*{match}"):
        mocap.load_synthetic("handclap", tmp_path)


# Case 5: empty inputs.
def test_error_release_without_windows(tmp_path):
    root = _fake_release(tmp_path)
    np.save(root / "handshake_interaction_t.npy", np.zeros((0, 3), np.int64))
    for calibration in (mocap.ORIGINAL_CALIBRATION, None):
        with pytest.raises(mocap.MocapError, match=r"interaction_t.npy: .*got 0 rows"):
            mocap.load_optitrack("handshake", root, calibration=calibration)


def test_error_npz_without_demonstrations(tmp_path):
    arrays = {key: value[:0] if value.ndim else value for key, value in _tiny_arrays().items()}
    file = _write_npz(tmp_path, arrays)
    with pytest.raises(mocap.MocapError, match=f"{re.escape(str(file))}: .*no demonstrations"):
        mocap.load_synthetic("handclap", tmp_path)


def test_error_calibration_frames_all_nonfinite(tmp_path):
    root = _fake_release(_fake_release(tmp_path, "handclap"))
    file = root / "handshake_distance_array_palms_1.npy"
    np.save(file, np.full_like(np.load(file), np.nan))
    with pytest.raises(mocap.MocapError, match="handshake.*handshake_distance_array_palms_1.npy"):
        mocap.load_optitrack("handclap", root)


# Fuzz: any damage gives a MocapError naming the damaged file, or plausible demonstrations
# (unchanged ones where the damage cannot matter); never another exception.
_FUZZ_DTYPES = (
    "bool", "int8", "uint16", "int64", "float16", "float32", "float64", ">f8", "complex128",
    "datetime64[s]", "U6", "S6", "object",
)  # fmt: skip
_FLOATS = (np.nan, np.inf, -np.inf, 0.0, -1.0, 0.5, 3.5, 1e6, 1e308, -1e308, 1e-310)
_INTS = (-1, 0, 1, 5, 39, 40, 2**31, -(2**40))
_STRINGS = ("", "handclap", "et", "x" * 30)


def _accepts(kind: str, dtype: np.dtype) -> bool:
    return {"float": "f", "int": "iu", "str": "U"}[kind].find(dtype.kind) >= 0


def _cast(array: np.ndarray, dtype: str) -> np.ndarray:
    try:
        return array.astype(dtype)
    except (TypeError, ValueError):  # e.g. names -> float: the dtype is what matters
        return np.zeros(array.shape, dtype)


def _reshape(array: np.ndarray, op: str) -> np.ndarray:
    if op == "add_axis":
        return array[None]
    if op == "double":
        return np.stack([array, array])
    if array.ndim == 0:
        return array.reshape(1)
    return {
        "drop_first": lambda a: a[1:],
        "drop_last": lambda a: a[:-1],
        "flatten": lambda a: a.reshape(-1),
        "drop_column": lambda a: a[..., :-1],
    }[op](array)


def _damage_bytes(data: bytes, draw) -> bytes:
    op = draw(st.sampled_from(["truncate", "flip", "append", "empty", "garbage"]))
    at = draw(st.integers(0, max(len(data) - 1, 0)))
    if op == "truncate":
        return data[:at]
    if op == "flip":
        return data[:at] + bytes([data[at] ^ draw(st.integers(1, 255))]) + data[at + 1 :]
    if op == "append":
        return data + draw(st.binary(min_size=1, max_size=64))
    return b"" if op == "empty" else draw(st.binary(max_size=600))


def _mutate(array: np.ndarray, kind: str, draw) -> tuple[np.ndarray, str]:
    """A damaged copy of array and what was done: "dtype-ok", "dtype-bad" or "other"."""
    op = draw(st.sampled_from(["dtype", "value", "shape"]))
    if op == "dtype":
        out = _cast(array, draw(st.sampled_from(_FUZZ_DTYPES)))
        return out, "dtype-ok" if _accepts(kind, out.dtype) else "dtype-bad"
    if op == "shape":
        ops = ["add_axis", "double", "drop_first", "drop_last", "flatten", "drop_column"]
        return _reshape(array, draw(st.sampled_from(ops))), "other"
    out = array.copy()
    values = {"float": _FLOATS, "int": _INTS, "str": _STRINGS}[kind]
    if out.size:
        with np.errstate(over="ignore", invalid="ignore"):
            out.flat[draw(st.integers(0, out.size - 1))] = draw(st.sampled_from(values))
    return out, "other"


_RELEASE_KINDS = {
    "interaction_t": "int",
    "distance_array_palms": "float",
    "distance_array_palms_1": "float",
    "rot_human": "float",
    "rot_robot": "float",
    "joint_angles_human": "float",
    "joint_angles_robot": "float",
}


@functools.cache
def _release_baseline(calibrated: bool) -> list[mocap.Demonstration]:
    with tempfile.TemporaryDirectory() as folder:
        root = _fake_release(Path(folder))
        return mocap.load_optitrack(
            "handshake", root, calibration=None if calibrated else mocap.ORIGINAL_CALIBRATION
        )


@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_fuzz_release_loader(tmp_path_factory, data):
    draw = data.draw
    root = _fake_release(tmp_path_factory.mktemp("release"))
    name = draw(st.sampled_from(sorted(_RELEASE_KINDS)))
    file = root / f"handshake_{name}.npy"
    calibrated = draw(st.booleans())
    array = np.load(file)
    how = draw(st.sampled_from(["array", "bytes", "noop", "outside"]))
    if how == "array":
        array, how = _mutate(array, _RELEASE_KINDS[name], draw)
        np.save(file, array)
    elif how == "bytes":
        file.write_bytes(_damage_bytes(file.read_bytes(), draw))
    elif how == "noop":  # byte order and memory layout do not change the data
        op = draw(st.sampled_from(["byteswap", "fortran"]))
        swapped = array.astype(array.dtype.newbyteorder())
        np.save(file, swapped if op == "byteswap" else np.asfortranarray(array))
    elif name not in ("interaction_t", "distance_array_palms"):
        # Before every window (frames 0-4; joint rows are frames + 1): unused unless the
        # calibration's lead-in reaches it (then it must still be plausible or an error).
        rows = slice(0, 4) if name.startswith("joint") else slice(0, 5)
        array[rows] = draw(st.sampled_from(_FLOATS))
        np.save(file, array)
    try:
        demos = mocap.load_optitrack(
            "handshake", root, calibration=None if calibrated else mocap.ORIGINAL_CALIBRATION
        )
    except mocap.MocapError as err:
        event(f"{how}: MocapError")
        assert how not in ("noop", "outside") or (how == "outside" and calibrated), err
        assert file.name in str(err)
        return
    event(f"{how}: loaded")
    assert how != "dtype-bad", f"{name} accepted as {array.dtype}"
    # The palm centre moves by at most twice the calibration offset from the mocap origin.
    offset = mocap.estimate_palm_calibration(root, ("handshake",)).offset if calibrated else 0
    _assert_plausible(demos, slack=2 * np.linalg.norm(offset) + 1e-9)
    if how == "noop" or (how == "outside" and not calibrated):
        _assert_same(demos, _release_baseline(calibrated))


_NPZ_KINDS = {
    "schema_version": "int",
    "task": "str",
    "names": "str",
    "fps": "float",
    "num_frames": "int",
    "contact_begin": "int",
    "contact_end": "int",
    "actor_joints": "float",
    "target_joints": "float",
    "actor_palm_pos": "float",
    "actor_palm_quat": "float",
}


@functools.cache
def _npz_baseline() -> list[mocap.Demonstration]:
    with tempfile.TemporaryDirectory() as folder:
        _write_npz(Path(folder), _tiny_arrays())
        return mocap.load_synthetic("handclap", folder)


@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_fuzz_npz_loader(tmp_path_factory, data):
    draw = data.draw
    root = tmp_path_factory.mktemp("npz")
    arrays = _tiny_arrays()
    key = draw(st.sampled_from(sorted(_NPZ_KINDS)))
    how = draw(st.sampled_from(["array", "bytes", "noop", "missing", "extra"]))
    compressed = True
    if how == "array":
        arrays[key], how = _mutate(np.asarray(arrays[key]), _NPZ_KINDS[key], draw)
    elif how == "noop":  # storage details that must not change the data
        op = draw(st.sampled_from(["uncompressed", "float64", "byteswap", "reversed"]))
        compressed = op != "uncompressed"
        value = np.asarray(arrays[key])
        if op == "float64" and value.dtype.kind == "f":
            arrays[key] = value.astype(np.float64)
        elif op == "byteswap":
            arrays[key] = value.astype(value.dtype.newbyteorder())
        elif op == "reversed":
            arrays = dict(reversed(arrays.items()))
    elif how == "missing":
        del arrays[key]
    elif how == "extra":
        arrays[f"{key}_extra"] = np.zeros(3)
    file = _write_npz(root, arrays, compressed)
    if how == "bytes":
        file.write_bytes(_damage_bytes(file.read_bytes(), draw))
    try:
        demos = mocap.load_synthetic("handclap", root)
    except mocap.MocapError as err:
        event(f"{how}: MocapError")
        assert how != "noop", err
        assert str(file) in str(err)
        return
    event(f"{how}: loaded")
    assert how not in ("dtype-bad", "missing", "extra"), f"{how} {key} accepted"
    _assert_plausible(demos)
    if how in ("noop", "bytes"):  # zip CRCs: damaged bytes never load as other data
        _assert_same(demos, _npz_baseline())
