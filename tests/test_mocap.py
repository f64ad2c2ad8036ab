"""Demonstrations: the authors' release (when present beside the repo), the project's
synthetic files, and the loader's errors. CPU only, a few seconds."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from conftest import real_data_or_skip

from mjx_hands import hand_kinematics, mocap, synthetic_demos, tasks
from mjx_hands.shadow_hand import HAND_JOINTS, HAND_POINTS

COUNTS = {"handshake": 10, "handclap": 9, "et": 5}
FF = HAND_POINTS.index("fftip")


@pytest.fixture(scope="module")
def real():
    root = real_data_or_skip()
    return {t: mocap.load_optitrack(t, root) for t in mocap.TASKS}


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
    for task in mocap.TASKS:
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
    for task, demos in synthetic.items():
        assert len(demos) >= 5
        for i, d in enumerate(demos):
            d.validate()
            assert (d.task, d.source, d.name) == (task, "synthetic", f"{task}/synthetic/{i:02d}")
            assert 1.5 <= d.num_frames / d.fps <= 3.0
            assert d.contact_begin / d.fps >= 1.0 and d.contact_end == d.num_frames - 1
            start = np.linalg.norm(d.actor_points[0, 0] - d.actor_points[d.contact_begin, 0])
            assert 0.29 < start < 0.46


def test_synthetic_files_match_regeneration(synthetic):
    for task in mocap.TASKS:
        with np.load(mocap.SYNTHETIC_PATH / f"{task}.npz", allow_pickle=False) as stored:
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
    for task in mocap.TASKS:
        pos_r, rot_r = _contact_pose(real[task])
        pos_s, rot_s = _contact_pose(synthetic[task])
        assert np.linalg.norm(pos_r - pos_s) < 0.03, task
        assert np.degrees(mocap.rotation_angle(rot_r, rot_s)) < 20, task


# ------------------------------------------------------------------------------ errors
def _fake_release(root: Path, task: str = "handshake", frames: int = 40) -> Path:
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
        "joint_angles_human": np.zeros((frames - 1, 20)),
        "joint_angles_robot": np.zeros((frames - 1, 20)),
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
