"""Partner models: the target hand as a person would present it (issue "partner").

Orientation: yaw, pitch and roll drawn per episode from given ranges, checked against a
NumPy transcription of the rotation and against an untilted reset of the same episode."""

from __future__ import annotations

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from tiny import HAND_GROUP, hand_cli_args

from mjx_hands import env as env_lib
from mjx_hands import spatial, train_config

HALF = (0.5, 0.3, 0.2)  # yaw, pitch, roll half-ranges, radians
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0], np.float32)


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def yaw_pitch_roll(turn: np.ndarray) -> np.ndarray:
    """(yaw, pitch, roll) of R = R_z(yaw) R_y(pitch) R_x(roll), |pitch| < pi/2."""
    return np.array(
        [
            np.arctan2(turn[1, 0], turn[0, 0]),
            -np.arcsin(np.clip(turn[2, 0], -1, 1)),
            np.arctan2(turn[2, 1], turn[2, 2]),
        ]
    )


def test_yaw_pitch_roll_is_the_numpy_rotation():
    rng = np.random.default_rng(0)
    for yaw, pitch, roll in rng.uniform(-1.2, 1.2, (8, 3)):
        quat = env_lib.yaw_pitch_roll_quat(yaw, pitch, roll)
        want = rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)
        np.testing.assert_allclose(np.asarray(spatial.quat_to_mat(quat)), want, atol=2e-6)
        np.testing.assert_allclose(yaw_pitch_roll(want), [yaw, pitch, roll], atol=1e-9)


@pytest.fixture(scope="module")
def turning_env():
    """A handshake env (native physics, compiles in seconds) whose target hand turns."""
    env = env_lib.make_env(
        "handshake", mocap_source="synthetic", physics="native", target_orientation_range=HALF
    )
    return env, jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.reset_with))


def test_the_orientation_partner_draws_within_its_ranges_and_the_goals_turn_with_it(
    turning_env,
):
    env, reset, reset_with = turning_env
    keys = jax.random.split(jax.random.PRNGKey(4), 512)
    ep = reset(keys).info["episode"]
    nominal = np.asarray(env.target_rot)
    turns = np.asarray(ep.target_rot) @ nominal.T
    angles = np.stack([yaw_pitch_roll(t) for t in turns])  # (512, 3)
    half = np.asarray(HALF)
    assert np.all(np.abs(angles) <= half + 1e-4)
    # Uniform on +-half: E|x| = half / 2 (standard error ~ 1.3 % of half at n = 512).
    np.testing.assert_allclose(np.abs(angles).mean(0), half / 2, rtol=0.08)
    assert np.all(np.abs(angles).max(0) > 0.95 * half)
    # The same episodes untilted: the palm stays, the goals turn about it.
    flat = reset_with(keys, jnp.broadcast_to(IDENTITY, (512, 4)), None).info["episode"]
    pos = np.asarray(ep.target_pos)
    np.testing.assert_allclose(pos, np.asarray(flat.target_pos), atol=1e-6)
    goals = np.asarray(ep.goal_points) - pos[:, None]
    flat_goals = np.asarray(flat.goal_points) - pos[:, None]
    np.testing.assert_allclose(goals, np.einsum("nij,nkj->nki", turns, flat_goals), atol=3e-5)


def test_the_orientation_partner_is_checked_and_recorded(tmp_path):
    with pytest.raises(ValueError, match="three half-ranges in \\[0, pi\\]"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(target_orientation_range=(0.1, -0.2, 0.0)))
    with pytest.raises(ValueError, match="both turn the target: give one"):
        env_lib.HandInteractionEnv(
            env_lib.EnvConfig(target_orientation_range=HALF, target_rotation_noise=0.1)
        )
    config = train_config.TrainConfig(
        env=env_lib.EnvConfig(target_orientation_range=HALF), run_dir=str(tmp_path)
    )
    assert config.env.target_orientation_range == HALF
    data = json.loads(json.dumps(train_config.config_to_json(config)))
    back = train_config.config_from_json(data)
    assert back == train_config.resolved(config) and hash(back)  # a tuple again
    assert dataclasses.replace(back.env, target_orientation_range=None) != back.env


@pytest.fixture(scope="module")
def clean_and_noisy():
    """The same handshake env without and with 5 mm sensing noise (native physics)."""
    make = lambda noise: env_lib.make_env(
        "handshake", mocap_source="synthetic", physics="native", target_position_noise=noise
    )
    return make(0.0), make(0.005)


def test_sensing_noise_moves_every_target_quantity_of_the_observation_by_one_error(
    clean_and_noisy,
):
    clean, noisy = clean_and_noisy
    keys = jax.random.split(jax.random.PRNGKey(5), 512)
    a = jax.jit(jax.vmap(clean.reset))(keys)
    b = jax.jit(jax.vmap(noisy.reset))(keys)
    # The physics and the reward see the true hand; only the observation differs.
    np.testing.assert_array_equal(a.pipeline_state.qpos, b.pipeline_state.qpos)
    diff = np.asarray(b.obs) - np.asarray(a.obs)
    # The project observation's blocks (env._observation): qpos 28, qvel 28, contacts 15,
    # points - target 18, goals - points 18, imitation 18, target - palm 18, phase 2.
    blocks = np.split(diff, np.cumsum([28, 28, 15, 18, 18, 18, 18]), axis=1)
    joints, velocities, contacts, relative, goals, imitation, target, phase = blocks
    error = target.reshape(512, 6, 3)[:, 0]  # (512, 3) one error per episode
    for block in (joints, velocities, contacts, phase):
        np.testing.assert_array_equal(block, 0.0)
    np.testing.assert_allclose(target.reshape(512, 6, 3), error[:, None].repeat(6, 1), atol=2e-6)
    np.testing.assert_allclose(relative.reshape(512, 6, 3), -error[:, None].repeat(6, 1), atol=2e-6)
    np.testing.assert_allclose(goals.reshape(512, 6, 3), error[:, None].repeat(6, 1), atol=2e-6)
    imitation = imitation.reshape(512, 6, 3)  # zero where the imitation phase is over
    assert np.all((np.abs(imitation - error[:, None]) < 2e-6) | (imitation == 0))
    # The error's statistics: mean 0, std 5 mm per axis (standard error ~3 % at n = 512).
    np.testing.assert_allclose(error.mean(0), 0.0, atol=0.0007)
    np.testing.assert_allclose(error.std(0), 0.005, rtol=0.1)
    # A new error every step, from the episode's own key.
    state = jax.jit(jax.vmap(noisy.step))(b, jnp.zeros((512, 24)))
    again = np.asarray(state.obs)[:, -20:-2].reshape(512, 6, 3)[:, 0]
    clean_next = jax.jit(jax.vmap(clean.step))(a, jnp.zeros((512, 24)))
    step_error = again - np.asarray(clean_next.obs)[:, -20:-2].reshape(512, 6, 3)[:, 0]
    assert np.abs(step_error - error).max() > 1e-3


def test_action_delay_applies_each_action_exactly_its_steps_later():
    env = env_lib.make_env("et", mocap_source="synthetic", physics="native", action_delay=2)
    state = jax.jit(env.reset)(jax.random.PRNGKey(2))
    hold = np.asarray(state.pipeline_state.ctrl)
    step = jax.jit(env.step)
    actions = np.random.default_rng(0).uniform(-1, 1, (5, 24)).astype(np.float32)
    applied = []
    for action in actions:
        state = step(state, jnp.asarray(action))
        applied.append(np.asarray(state.pipeline_state.ctrl))
    np.testing.assert_allclose(applied[0], hold, atol=1e-6)  # the start pose is held
    np.testing.assert_allclose(applied[1], hold, atol=1e-6)
    for k in range(2, 5):  # then each action, two steps late
        np.testing.assert_allclose(applied[k], np.asarray(env.ctrl_for(actions[k - 2])), atol=1e-6)
    with pytest.raises(ValueError, match="action_delay -1 must be a whole number"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(action_delay=-1))
    with pytest.raises(ValueError, match="target_position_noise -0.1 must be a finite number >= 0"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(target_position_noise=-0.1))


def test_a_drawn_action_delay_applies_each_episode_its_own_and_the_recent_actions_are_seen():
    """Delays drawn per episode from [0, 2]: uniform shares, and in each episode every
    action reaches the actuators exactly its episode's steps later (the start pose held
    before); the observation's last 48 entries are the policy's last 2 actions."""
    env = env_lib.make_env(
        "et",
        mocap_source="synthetic",
        physics="native",
        action_delay_range=(0, 2),
        observe_recent_actions=2,
    )
    plain = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    assert env.observation_size == plain.observation_size + 2 * 24
    draws = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(5), 600))
    delays = np.asarray(draws.info["episode"].action_delay)
    np.testing.assert_allclose(np.bincount(delays, minlength=3) / 600, 1 / 3, atol=0.06)
    # Six episodes, at least one of each delay.
    picks = np.concatenate([np.flatnonzero(delays == d)[:2] for d in range(3)])
    state = jax.tree.map(lambda x: x[picks], draws)
    hold = np.asarray(state.pipeline_state.ctrl)  # (6, 24)
    hold_action = np.asarray(jax.vmap(env.action_for)(state.pipeline_state.ctrl))
    np.testing.assert_allclose(np.asarray(state.obs)[:, -48:], np.tile(hold_action, 2), atol=1e-6)
    step = jax.jit(jax.vmap(env.step))
    actions = np.random.default_rng(1).uniform(-1, 1, (5, 6, 24)).astype(np.float32)
    applied, seen = [], []
    for action in actions:
        state = step(state, jnp.asarray(action))
        applied.append(np.asarray(state.pipeline_state.ctrl))
        seen.append(np.asarray(state.obs)[:, -48:].reshape(6, 2, 24))
    for e, delay in enumerate(delays[picks]):
        for k in range(5):
            expected = hold[e] if k < delay else np.asarray(env.ctrl_for(actions[k - delay, e]))
            np.testing.assert_allclose(applied[k][e], expected, atol=1e-6)
            newest_first = [actions[k, e], actions[k - 1, e] if k else hold_action[e]]
            np.testing.assert_allclose(seen[k][e], np.stack(newest_first), atol=1e-6)
    with pytest.raises(ValueError, match=r"action_delay_range \(2, 1\) must be \[low, high\]"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(action_delay_range=(2, 1)))
    with pytest.raises(ValueError, match="action_delay and action_delay_range both"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(action_delay=1, action_delay_range=(0, 2)))
    with pytest.raises(ValueError, match="observe_recent_actions needs the project observation"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(profile="paper", observe_recent_actions=1))


def test_the_action_rate_term_charges_each_change_of_action_and_nothing_else():
    config = {"task": "et", "mocap_source": "synthetic", "physics": "native"}
    plain = env_lib.make_env(**config)
    smooth = env_lib.make_env(**config, action_rate_weight=0.05)
    actions = np.random.default_rng(3).uniform(-1, 1, (6, smooth.action_size)).astype(np.float32)

    def rewards_of(env, key):
        def step(state, action):
            state = env.step(state, action)
            return state, (state.reward, state.metrics)

        state = env.reset(key)
        return env.action_for(state.pipeline_state.ctrl), jax.lax.scan(step, state, actions)[1]

    key = jax.random.PRNGKey(4)
    _, (base, _) = jax.jit(lambda k: rewards_of(plain, k))(key)
    hold, (reward, metrics) = jax.jit(lambda k: rewards_of(smooth, k))(key)
    previous = np.concatenate([np.asarray(hold)[None], actions[:-1]])
    expected = -0.05 * np.sum((actions - previous) ** 2, axis=-1)
    np.testing.assert_allclose(np.asarray(metrics["reward/action_rate"]), expected, rtol=1e-5)
    np.testing.assert_allclose(
        np.asarray(reward) - np.asarray(base), expected, rtol=1e-4, atol=1e-5
    )
    assert "reward/action_rate" not in plain.reset(key).metrics
    with pytest.raises(ValueError, match="action_rate_weight -1.0 must be >= 0"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(action_rate_weight=-1.0))


def test_the_motion_partner_draws_each_episodes_speed_from_its_range():
    env = env_lib.make_env(
        "et", mocap_source="synthetic", physics="native", target_speed_range=(0.1, 0.3)
    )
    keys = jax.random.split(jax.random.PRNGKey(6), 512)
    ep = jax.jit(jax.vmap(env.reset))(keys).info["episode"]
    speed = np.linalg.norm(np.asarray(ep.target_velocity), axis=-1)
    assert speed.min() >= 0.1 - 1e-6 and speed.max() <= 0.3 + 1e-6
    np.testing.assert_allclose(speed.mean(), 0.2, atol=0.006)  # SE ~0.0026 at n = 512
    np.testing.assert_allclose(speed.std(), 0.2 / np.sqrt(12), rtol=0.1)
    # A speed given to reset_with (the robustness sweep) still wins.
    given = jax.jit(env.reset_with)(keys[0], None, jnp.float32(0.05)).info["episode"]
    assert np.linalg.norm(np.asarray(given.target_velocity)) == pytest.approx(0.05, abs=1e-6)
    with pytest.raises(ValueError, match="must be \\[low, high\\] m/s"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(target_speed_range=(0.3, 0.1)))


def test_the_observed_target_velocity_is_the_difference_of_observed_palms_over_the_period():
    """A moving, recorded, noisily seen partner: the last 3 observation entries are the
    observed palm's step over the control period (the export's schedule, a separate
    scan, as reference), zeros at the first step; the rest is the observation without it."""
    config = {
        "mocap_source": "synthetic", "physics": "native", "partner": "recorded",
        "target_speed_range": (0.1, 0.3), "target_position_noise": 0.003,
    }  # fmt: skip
    seeing = env_lib.make_env("et", observe_target_velocity=True, **config)
    blind = env_lib.make_env("et", **config)
    assert seeing.observation_size == blind.observation_size + 3
    keys = jax.random.split(jax.random.PRNGKey(8), 4)
    a, b = jax.jit(jax.vmap(seeing.reset))(keys), jax.jit(jax.vmap(blind.reset))(keys)
    schedule = jax.jit(jax.vmap(seeing.partner_schedule))(a)  # the episodes' whole schedule
    seen = np.asarray(schedule["target_pos"])  # (4, T+1, 3) the palm as observed
    np.testing.assert_array_equal(np.asarray(a.obs)[:, -3:], 0.0)
    actions = jnp.asarray(np.random.default_rng(1).uniform(-1, 1, (5, 4, 24)), jnp.float32)
    step_a, step_b = jax.jit(jax.vmap(seeing.step)), jax.jit(jax.vmap(blind.step))
    start = np.asarray(a.info["episode"].target_pos)
    for k, action in enumerate(actions, start=1):
        a, b = step_a(a, action), step_b(b, action)
        np.testing.assert_array_equal(np.asarray(a.obs)[:, :-3], np.asarray(b.obs))
        expected = (seen[:, k] - seen[:, k - 1]) / seeing.config.control_dt
        np.testing.assert_allclose(np.asarray(a.obs)[:, -3:], expected, atol=1e-4)
    # The premise: the true palm moved (0.1-0.3 m/s, and along its recorded path).
    moved = np.linalg.norm(np.asarray(a.info["episode"].target_pos) - start, axis=-1)
    assert np.all(moved > 0.02 * len(actions) * seeing.config.control_dt), moved
    # The exported player builds the same entries from the exported schedule.
    from types import SimpleNamespace

    from mjx_hands import onnx_player

    env = {"observation": "project", "episode_length": seeing.episode_length,
           "control_dt": seeing.config.control_dt, "observe_target_velocity": True}  # fmt: skip
    schedule = {k: np.asarray(v)[0] for k, v in schedule.items()}
    readings = {"points": np.zeros((6, 3), np.float32), "contacts": np.zeros(15, np.float32)}
    played = onnx_player.Player.observation(
        SimpleNamespace(env=env), 5, np.zeros(28), np.zeros(28), readings, schedule
    )
    np.testing.assert_allclose(played[-3:], np.asarray(a.obs)[0, -3:], atol=1e-4)
    with pytest.raises(ValueError, match="observe_target_velocity needs the project observation"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(profile="paper", observe_target_velocity=True))


# ------------------------------------------------------------- the recorded partner
def _turning_demo(path_recorded: bool, frames: int = 25, fps: float = 50.0):
    """A handshake-like demonstration built from world poses: the target palm turns 30°
    about its z axis and travels 10 cm while the actor's palm closes in; the whole scene
    sits at an arbitrary world pose (which the demonstration must not keep)."""
    from mjx_hands import mocap

    t = np.linspace(0.0, 1.0, frames)
    world = rot_x(0.4) @ rot_y(-0.7)  # where the capture put the pair
    offset = np.array([1.0, -2.0, 0.5])
    target_rot = np.stack([world @ rot_z(np.radians(30) * s) for s in t])
    target_pos = offset + np.stack([0.1 * t, 0.02 * t, 0 * t], 1) @ world.T
    actor_pos = offset + np.stack([0.5 - 0.35 * t, 0.03 + 0 * t, 0.01 * t], 1) @ world.T
    actor_rot = np.broadcast_to(world @ rot_y(np.pi), (frames, 3, 3))
    joints = np.linspace(0.0, 0.4, frames)[:, None] * np.ones(20)
    demo = mocap.build_demonstration(
        task="handshake",
        name="handshake/test/00",
        source="synthetic",
        fps=fps,
        actor_joints=joints,
        target_joints=joints[::-1],
        actor_palm_pos=np.einsum("tji,tj->ti", target_rot, actor_pos - target_pos),
        actor_palm_rot=np.swapaxes(target_rot, 1, 2) @ actor_rot,
        contact_begin=frames - 6,
        contact_end=frames - 1,
        target_palm_rot=target_rot,
        target_palm_pos=target_pos if path_recorded else None,
    )
    return demo, (target_pos, target_rot, actor_pos)


@pytest.mark.parametrize("path_recorded", [True, False])
def test_the_approach_path_is_the_recorded_one_or_the_targets_share_of_the_closing(path_recorded):
    from mjx_hands import partner

    demo, (target_pos, target_rot, actor_pos) = _turning_demo(path_recorded)
    first = target_rot[0]
    pos, rot = partner.approach_path(demo, share=0.3)
    # Rotations: the palm's own turning, in its frame at frame 0.
    np.testing.assert_allclose(rot, first.T @ target_rot, atol=1e-12)
    np.testing.assert_allclose(np.degrees(np.arctan2(rot[-1, 1, 0], rot[-1, 0, 0])), 30, atol=1e-9)
    if path_recorded:
        want = (target_pos - target_pos[0]) @ first
    else:  # 30 % of each change of the palm-to-palm vector, in frame-0 axes
        between = (actor_pos - target_pos) @ first
        want = -0.3 * (between - between[0])
    np.testing.assert_allclose(pos, want, atol=1e-12)
    # The tables: every control step (2 frames at 50 Hz and 25 Hz control), relative to
    # the pose at t_min, past the window's end its last frame.
    t_min = 14
    tables = partner.partner_tables([demo], [t_min], dt=0.04, share=0.3, length=15)
    frames = np.minimum(2 * np.arange(15), demo.num_frames - 1)
    at_min = rot[t_min]
    np.testing.assert_allclose(tables.palm_pos[0], (pos[frames] - pos[t_min]) @ at_min, atol=1e-12)
    np.testing.assert_allclose(tables.palm_rot[0], at_min.T @ rot[frames], atol=1e-9)
    np.testing.assert_allclose(tables.joints[0], demo.target_joints[frames], atol=1e-12)
    np.testing.assert_allclose(tables.palm_pos[0, 7], 0, atol=1e-12)  # step 7 = frame 14


def test_the_target_motion_survives_the_npz_round_trip_and_schema_1_files_still_read(tmp_path):
    from mjx_hands import mocap

    for recorded in (True, False):
        demo, _ = _turning_demo(recorded)
        arrays = mocap.demos_to_arrays([demo])
        assert ("target_palm_pos" in arrays) == recorded
        (back,) = mocap.demos_from_arrays(arrays, "handshake", "synthetic")
        np.testing.assert_allclose(back.target_palm_rot, demo.target_palm_rot, atol=2e-6)
        if recorded:
            np.testing.assert_allclose(back.target_palm_pos, demo.target_palm_pos, atol=1e-6)
        else:
            assert back.target_palm_pos is None
    # A schema-1 file (before the target's motion was stored): a target that never turns.
    old = {k: v for k, v in arrays.items() if not k.startswith("target_palm")}
    (still,) = mocap.demos_from_arrays(
        old | {"schema_version": np.int64(1)}, "handshake", "synthetic"
    )
    np.testing.assert_array_equal(still.target_palm_rot, np.broadcast_to(np.eye(3), (25, 3, 3)))
    with pytest.raises(mocap.MocapError, match="'target_palm_quat' needs schema_version 2"):
        mocap.demos_from_arrays(arrays | {"schema_version": np.int64(1)}, "handshake", "synthetic")
    mixed = [_turning_demo(True)[0], _turning_demo(False)[0]]
    with pytest.raises(mocap.MocapError, match="all record the target palm position or none"):
        mocap.demos_to_arrays(mixed)


@pytest.fixture(scope="module")
def recorded_partner():
    """The authors' handshakes, the recorded partner (native physics), 64 episodes reset
    and stepped 30 control periods with zero actions: every step's target and schedule."""
    from mjx_hands import mocap

    if not mocap.REAL_DATA_PATH.is_dir():
        pytest.skip("the authors' recordings are not beside the repository")
    env = env_lib.make_env(
        "handshake", mocap_source="optitrack", physics="native", partner="recorded"
    )
    steps = 30

    def episode(key):
        state = env.reset(key)

        def step(state, _):
            state = env.step(state, jnp.zeros(env.action_size))
            ep, data = state.info["episode"], state.pipeline_state
            return state, (
                ep.target_pos,
                ep.target_rot,
                ep.target_points,
                ep.target_frames,
                ep.goal_points,
                data.mocap_pos,
                data.mocap_quat,
            )

        _, trace = jax.lax.scan(step, state, None, length=steps)
        return state.info["episode"], trace, env.partner_schedule(state)

    keys = jax.random.split(jax.random.PRNGKey(11), 64)
    first, trace, schedule = jax.jit(jax.vmap(episode))(keys)
    return env, steps, jax.tree.map(np.asarray, (first, trace, schedule))


def test_the_recorded_partner_replays_the_demonstrations_wrist_path_turning_and_fingers(
    recorded_partner,
):
    from mjx_hands import hand_kinematics, partner, reward_params

    env, steps, (first, trace, _) = recorded_partner
    pos, rot, points, frames, goals, _, _ = trace
    length = env.partner_pos.shape[1]
    dt = env.config.control_dt
    checked = 0
    for i in range(0, 64, 4):  # sampled episodes, every 5th step
        demo = env.demos[int(first.demo[i])]
        t_min = int(env.params.t_min_frame[int(first.demo[i])])
        path_pos, path_rot = partner.approach_path(demo, env.config.partner_share)
        for k in range(0, steps, 5):
            row = min(int(first.partner_row[i]) + k + 1, length - 1)
            f = min(row * demo.fps * dt, demo.num_frames - 1)
            lo, s = int(np.floor(f)), f - np.floor(f)
            hi = min(lo + 1, demo.num_frames - 1)

            def lerp(x, lo=lo, hi=hi, s=s):
                return (1 - s) * x[lo] + s * x[hi]

            u, _, vt = np.linalg.svd(lerp(path_rot))
            turned = u @ vt
            at_min = path_rot[t_min].T
            want_rot = first.partner_base_rot[i] @ at_min @ turned
            want_pos = first.partner_base_pos[i] + first.partner_base_rot[i] @ at_min @ (
                lerp(path_pos) - path_pos[t_min]
            )
            np.testing.assert_allclose(rot[i, k], want_rot, atol=2e-5)
            np.testing.assert_allclose(pos[i, k], want_pos, atol=2e-5)
            # The fingers: the recorded angles, by the project's NumPy forward kinematics.
            hand = hand_kinematics.forward_kinematics(lerp(demo.target_joints))
            np.testing.assert_allclose(points[i, k], want_pos + hand.points @ want_rot.T, atol=1e-4)
            # The goals ride with the target: fixed in its closest body's frame.
            j = int(env.params.j_min[int(first.demo[i])])
            local = (goals[i, k] - points[i, k, j]) @ frames[i, k, j]
            np.testing.assert_allclose(
                local, env.params.goal_offsets[int(first.demo[i])], atol=1e-4
            )
            checked += 1
    assert checked == 96
    # It does move: palms travel centimetres and turn degrees over these 1.2 s.
    travel = np.linalg.norm(pos[:, -1] - pos[:, 0], axis=-1)
    assert np.median(travel) > 0.01
    del reward_params


def test_the_recorded_partners_timing_is_drawn_and_its_schedule_is_what_the_physics_saw(
    recorded_partner,
):
    env, steps, (first, trace, schedule) = recorded_partner
    lag = first.partner_row - first.start_step
    low, high = env.config.partner_lag
    clipped = first.partner_row == 0
    assert np.all(((lag >= low) & (lag <= high)) | clipped)
    assert len(set(lag[~clipped].tolist())) >= 8  # 11 values possible, 64 draws
    late = first.start_step > high  # no lag can reach row 0 from there: no clipping bias
    assert late.sum() >= 10 and abs(lag[late].mean()) < 3.5 * 3.2 / np.sqrt(late.sum())
    # The player outside JAX gets the mocap bodies the physics had at every step.
    *_, mocap_pos, mocap_quat = trace
    np.testing.assert_array_equal(schedule["mocap_pos"][:, 1 : steps + 1], mocap_pos)
    np.testing.assert_array_equal(schedule["mocap_quat"][:, 1 : steps + 1], mocap_quat)
    with pytest.raises(ValueError, match="partner_share 1.5 must be in \\[0, 1\\]"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(partner_share=1.5))
    with pytest.raises(ValueError, match="unknown partner 'mirror'"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(partner="mirror"))


def test_the_robust_setup_is_named_recorded_and_its_flags_still_win(tmp_path):
    import tyro

    from mjx_hands import env_config, train_cli

    robust = train_cli.preset_default(["--partners", "robust", "--task", "et", "--preset", "cpu"])
    assert robust.partners == "robust" and robust.env.task == "et"
    for name, value in env_config.ROBUST_PARTNERS.items():
        assert getattr(robust.env, name) == value, name
    static = train_cli.preset_default(["--task", "et", "--preset", "cpu"])
    assert static.env == env_lib.EnvConfig(task="et") and static.partners == "static"
    argv = ["--partners", "robust", "--target-speed-range", "0", "0.1", "--run-dir", str(tmp_path)]
    parsed = tyro.cli(train_config.TrainConfig, default=robust, args=argv)
    assert parsed.env.target_speed_range == (0.0, 0.1)  # the flag over the setup
    assert parsed.env.partner == "recorded"
    back = train_config.config_from_json(
        json.loads(json.dumps(train_config.config_to_json(parsed)))
    )
    assert back == train_config.resolved(parsed)
    mixed = train_cli.preset_default(["--partners", "mixed", "--task", "et", "--preset", "cpu"])
    assert mixed.env == dataclasses.replace(robust.env, partner_model_probability=0.5)
    with pytest.raises(ValueError, match="unknown partners 'wild'"):
        env_config.with_partners(env_lib.EnvConfig(), "wild")


def test_policies_are_scored_against_the_static_partner_whatever_they_trained_with():
    from mjx_hands import env_config

    nominal = env_lib.EnvConfig(task="et", mocap_source="synthetic", physics="native")
    robust = dataclasses.replace(env_config.with_partners(nominal, "robust"), action_delay=2)
    assert robust != nominal
    assert env_config.static_partner(robust) == env_config.static_partner(nominal) == nominal
    # 'static' names one thing everywhere: the static partner, whatever was set before.
    assert env_config.with_partners(robust, "static") == nominal
    assert env_config.with_partners(robust, "robust") == env_config.with_partners(nominal, "robust")
    # Every partner model the config documents is reset (a new one must be added there).
    documented = {
        f.name
        for f in dataclasses.fields(env_lib.EnvConfig)
        if f.name.startswith(("target_rotation", "target_orientation", "target_speed"))
        or f.name
        in (
            "target_position_noise",
            "action_delay",
            "action_delay_range",
            "partner",
            "partner_model_probability",
        )
    }
    assert documented <= set(env_config.STATIC_PARTNER)
    # One scoring environment for both, so every policy of a program shares its compiles.
    assert env_lib.scoring_env(robust) is env_lib.scoring_env(nominal)
    assert env_lib.scoring_env(robust).config == nominal


def test_the_mixed_setup_draws_each_partner_model_in_half_the_episodes_independently():
    """Orientation, motion and recorded partner each apply with probability 0.5; an
    episode that skips all three is the static partner's episode, step for step."""
    from mjx_hands import env_config

    config = {"task": "et", "mocap_source": "synthetic", "physics": "native"}
    static = env_lib.make_env(**config)
    mixed = env_lib.HandInteractionEnv(
        env_config.with_partners(env_lib.EnvConfig(**config), "mixed")
    )
    assert mixed.config.partner_model_probability == 0.5 and mixed.config.partner == "recorded"
    steps = 8

    def rollout(env, key):
        def step(state, _):
            state = env.step(state, jnp.zeros(env.action_size))
            ep = state.info["episode"]
            return state, (ep.target_pos, ep.goal_points, state.pipeline_state.mocap_pos)

        state = env.reset(key)
        return state.info["episode"], jax.lax.scan(step, state, None, length=steps)[1]

    keys = jax.random.split(jax.random.PRNGKey(21), 192)
    first, trace = jax.tree.map(np.asarray, jax.jit(jax.vmap(lambda k: rollout(mixed, k)))(keys))
    s_first, s_trace = jax.tree.map(
        np.asarray, jax.jit(jax.vmap(lambda k: rollout(static, k)))(keys)
    )
    turned = ~np.all(np.isclose(first.partner_base_rot, s_first.target_rot, atol=1e-6), (1, 2))
    moves = np.linalg.norm(first.target_velocity, axis=-1) > 0
    replays = first.partner_replays
    flags = np.stack([turned, moves, replays], 1).astype(float)
    n = len(keys)  # binomial SE of a share: 0.036; of the joint shares below: 0.024
    np.testing.assert_allclose(flags.mean(0), 0.5, atol=0.11)
    np.testing.assert_allclose((flags.sum(1) == 0).mean(), 0.125, atol=0.075)
    np.testing.assert_allclose((flags[:, 0] * flags[:, 1]).mean(), 0.25, atol=0.1)
    assert n == 192 and 0 < (flags.sum(1) == 3).sum()
    # Speeds of the moving ones come from the range; the others stand still.
    speed = np.linalg.norm(first.target_velocity, axis=-1)
    assert speed[moves].max() <= 0.25 + 1e-6 and np.all(speed[~moves] == 0)
    # An episode of none of them: the static partner's, every step.
    none = flags.sum(1) == 0
    for got, want in zip(trace, s_trace, strict=True):
        np.testing.assert_allclose(got[none], want[none], atol=1e-5)
    # A replaying partner moves its palm; a held one keeps it, moving only if carried.
    travelled = np.linalg.norm(trace[0][:, -1] - first.target_pos, axis=-1)
    assert np.all(travelled[replays & ~moves] > 0) and np.all(travelled[~replays & ~moves] < 1e-6)
    with pytest.raises(ValueError, match="partner_model_probability 1.5 must be in"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(partner_model_probability=1.5))


@HAND_GROUP
def test_a_curriculum_stage_resumes_a_run_against_the_robust_partners(tmp_path, capsys):
    """``--resume --partners robust``: the next stage of a curriculum. The learner, its
    replay and counters come from the checkpoint; the episodes in flight (whose state has
    the static partner's layout) start afresh against the recorded, turning, moving
    partner, which config.json then records. Without the flag the partner stays."""
    from mjx_hands import env_config, train_cli

    run = tmp_path / "run"
    assert train_cli.main([*hand_cli_args(), "--epochs", "1", "--run-dir", str(run)]) == 0
    assert json.loads((run / "config.json").read_text())["env"]["partner"] == "static"
    capsys.readouterr()
    argv = ["--run-dir", str(run), "--resume", "--partners", "robust", "--epochs", "2"]
    assert train_cli.main(argv) == 0
    assert "resumed from epoch 1" in capsys.readouterr().out
    config = json.loads((run / "config.json").read_text())
    assert config["partners"] == "robust"
    for name, value in env_config.ROBUST_PARTNERS.items():
        assert config["env"][name] == (list(value) if isinstance(value, tuple) else value), name
    rows = (run / "metrics.csv").read_text().splitlines()
    steps = [float(r.split(",")[rows[0].split(",").index("train/env_steps")]) for r in rows[1:]]
    assert steps[-1] == 2 * steps[0]  # the counters went on: the checkpoint was restored
    # And back to the static partner for a last stage.
    argv = ["--run-dir", str(run), "--resume", "--partners", "static", "--epochs", "3"]
    assert train_cli.main(argv) == 0
    config = json.loads((run / "config.json").read_text())
    assert config["env"]["partner"] == "static" and config["env"]["target_speed_range"] is None


def test_the_exported_player_delays_and_observes_actions_as_the_environment_does(
    tmp_path, monkeypatch
):
    """A policy that observes its last 2 actions, under delays drawn from [0, 2]: the
    native-MuJoCo player (ONNX, no JAX) applies each episode's delay and builds the very
    observations the environment does, step after step."""
    from mjx_hands import export, onnx_player, policies, rollouts

    env_config = env_lib.EnvConfig(
        task="et", mocap_source="synthetic", physics="native",
        action_delay_range=(0, 2), observe_recent_actions=2,
    )  # fmt: skip
    single = env_lib.HandInteractionEnv(env_config)
    weights = jnp.asarray(
        np.random.default_rng(3).normal(0, 0.3, (single.observation_size, 24)), jnp.float32
    )

    def act(obs):  # a deterministic policy whose actions follow what it observes
        return jnp.tanh(obs @ weights)

    config = train_config.preset("cpu", env=env_config)
    loaded = policies.LoadedPolicy(act, None, config, single, 0)
    monkeypatch.setattr(policies, "load_policy", lambda *args, **kwargs: loaded)
    onnx_file = tmp_path / "policy.onnx"
    assert export.main([str(tmp_path), "--onnx", str(onnx_file), "--episodes", "6"]) == 0
    record = json.loads((tmp_path / "policy.json").read_text())
    assert record["observation"][-1]["name"] == "recent_actions"
    assert record["environment"]["action_delay_range"] == [0, 2]
    keys = rollouts.episode_keys(rollouts.EVAL_SEED, 6)
    trajectory = rollouts.rollout(single, act, keys, extra=lambda s: {"obs": s.obs})
    player = onnx_player.Player(tmp_path)
    delays = player.episodes["action_delay"]
    assert set(delays.tolist()) > {0}, delays  # the premise: some episode is delayed
    for i in range(6):
        np.testing.assert_allclose(
            player.play(i)["observations"], trajectory["obs"][:, i], atol=1e-4
        )


# ------------------------------------------------------- how the partner travels
def _nlerp_reference(q0, q1, share):
    """NumPy: normalised linear interpolation of unit quaternions on the shorter arc."""
    q0 = q0 if np.dot(q0, q1) >= 0 else -q0
    q = (1 - share) * q0 + share * q1
    return q / np.linalg.norm(q)


def test_the_mocap_path_interpolates_positions_and_turns_to_the_periods_end():
    from mjx_hands import physics

    rng = np.random.default_rng(3)
    pos0, pos1 = rng.normal(size=(2, 5, 3)).astype(np.float32)
    quat0 = rng.normal(size=(5, 4)).astype(np.float32)
    quat0 /= np.linalg.norm(quat0, axis=-1, keepdims=True)
    quat1 = -quat0 + 0.3 * rng.normal(size=(5, 4)).astype(np.float32)  # the far hemisphere
    quat1 /= np.linalg.norm(quat1, axis=-1, keepdims=True)
    positions, quats = physics.mocap_path((pos0, quat0), (pos1, quat1), 10)
    assert positions.shape == (10, 5, 3) and quats.shape == (10, 5, 4)
    for k in range(10):
        share = (k + 1) / 10
        np.testing.assert_allclose(positions[k], pos0 + share * (pos1 - pos0), atol=1e-6)
        for b in range(5):
            expected = _nlerp_reference(quat0[b], quat1[b], share)
            np.testing.assert_allclose(quats[k, b], expected, atol=1e-5)
    np.testing.assert_array_equal(quats[-1], quat1)  # the period ends where it was placed


TETHERED = """
<mujoco>
  <option timestep="0.004"/>
  <worldbody>
    <body name="plate" mocap="true" pos="0 0 0"><geom type="box" size=".05 .05 .01" contype="0" conaffinity="0"/></body>
    <body name="ball" pos="0 0 0">
      <joint name="x" type="slide" axis="1 0 0" damping="0.5"/>
      <joint name="y" type="slide" axis="0 1 0" damping="0.5"/>
      <joint name="z" type="slide" axis="0 0 1" damping="0.5"/>
      <joint name="turn" type="ball" damping="0.01"/>
      <geom type="sphere" size=".02" mass="0.1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <equality><weld body1="ball" body2="plate" solref="0.02 1"/></equality>
  <actuator><position joint="x" kp="1"/></actuator>
</mujoco>
"""
"""A ball tethered to a mocap plate by a soft weld: where it ends after a period depends
on the path the plate took within it, not only on where the plate ends."""


def _mj_step_reference(m, qpos, qvel, ctrl, poses):
    """C reference of one control period: ``mujoco.mj_step`` per pose in ``poses``
    [(positions, quats)], the mocap bodies set to it before that substep."""
    import mujoco

    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
    for pos, quat in poses:
        d.mocap_pos[:], d.mocap_quat[:] = pos, quat
        mujoco.mj_step(m, d)
    return d.qpos.copy(), d.qvel.copy()


@pytest.fixture(scope="module")
def tethered():
    import mujoco

    m = mujoco.MjModel.from_xml_string(TETHERED)
    start = (np.zeros((1, 3), np.float32), np.array([[1.0, 0, 0, 0]], np.float32))
    turn = np.array([[np.cos(0.2), 0, 0, np.sin(0.2)]], np.float32)  # 0.4 rad about z
    end = (np.array([[0.012, -0.004, 0.006]], np.float32), turn)
    n = 10
    share = lambda k: (k + 1) / n
    glide = [
        (start[0] + share(k) * (end[0] - start[0]), _nlerp_reference(start[1][0], end[1][0], share(k))[None])
        for k in range(n)
    ]  # fmt: skip
    qvel = np.array([0.05, 0.0, -0.02, 0.0, 0.1, 0.0], np.float32)
    return m, start, end, n, {"per_step": [end] * n, "continuous": glide}, qvel


def test_native_physics_carries_the_mocap_bodies_along_their_path_as_mj_step_does(tethered):
    from mjx_hands import physics

    m, start, end, n, paths, qvel = tethered
    native = physics.NativePhysics(m, n, 0.002, threads=1)
    state = physics.NativeState(
        qpos=jnp.asarray(m.qpos0, jnp.float32), qvel=jnp.asarray(qvel), ctrl=jnp.zeros(1),
        mocap_pos=jnp.asarray(end[0]), mocap_quat=jnp.asarray(end[1]),
        time=jnp.zeros(()), sensordata=jnp.zeros(m.nsensordata),
    )  # fmt: skip
    ended = {
        "per_step": native.step(state, jnp.zeros(1)),
        "continuous": native.step(state, jnp.zeros(1), mocap_from=start),
    }
    for motion, after in ended.items():
        expected, _ = _mj_step_reference(m, m.qpos0, qvel, np.zeros(1), paths[motion])
        np.testing.assert_allclose(np.asarray(after.qpos), expected, atol=1e-6)
    # The premise: the two paths leave the ball in different places.
    gap = np.abs(np.asarray(ended["per_step"].qpos) - np.asarray(ended["continuous"].qpos))
    assert gap.max() > 1e-3, gap


def test_mjx_substeps_carry_the_mocap_bodies_along_their_path_as_mj_step_does(tethered):
    from mujoco import mjx

    from mjx_hands import physics

    m, start, end, n, paths, qvel = tethered
    model = mjx.put_model(m)
    data = mjx.make_data(m).replace(
        qpos=jnp.asarray(m.qpos0, jnp.float32),
        qvel=jnp.asarray(qvel),
        mocap_pos=jnp.asarray(end[0]),
        mocap_quat=jnp.asarray(end[1]),
    )
    run = jax.jit(lambda d, origin: physics.substeps(model, d, n, origin))
    ended = {"per_step": physics.substeps(model, data, n, None), "continuous": run(data, start)}
    for motion, after in ended.items():
        expected, _ = _mj_step_reference(m, m.qpos0, qvel, np.zeros(1), paths[motion])
        # MJX steps in float32 (3e-5 measured on the ball's turn), ten times below the gap.
        np.testing.assert_allclose(np.asarray(after.qpos), expected, atol=1e-4)
    gap = np.abs(np.asarray(ended["per_step"].qpos) - np.asarray(ended["continuous"].qpos))
    assert gap.max() > 1e-3, gap


class _Handed:
    """Wraps a physics' step, keeping each call's ``mocap_from`` (None or positions)."""

    def __init__(self, step):
        self.step, self.origins = step, []

    def __call__(self, state, ctrl, *, mocap_from=None):
        self.origins.append(None if mocap_from is None else np.asarray(mocap_from[0]))
        return self.step(state, ctrl, mocap_from=mocap_from)


@pytest.mark.parametrize("partner", ["static", "recorded"])
def test_the_environment_glides_a_moving_partner_from_the_last_periods_pose(partner, monkeypatch):
    """``partner_motion='continuous'``: every step hands the physics the pose the period
    starts from (the last step's, after reset the placed one) and ends at the same pose
    as per step; a partner that cannot move is never glided."""
    from mjx_hands import env_config

    config = {"mocap_source": "synthetic", "physics": "native", "partner": partner,
              "target_speed": 0.3}  # fmt: skip
    action = jnp.asarray(np.random.default_rng(2).uniform(-1, 1, 24), jnp.float32)
    poses = {}
    for motion in env_config.PARTNER_MOTIONS:
        env = env_lib.make_env("et", partner_motion=motion, **config)
        handed = _Handed(env.physics.step)
        monkeypatch.setattr(env.physics, "step", handed)
        state = env.reset(jax.random.PRNGKey(4))
        trajectory = [np.asarray(state.pipeline_state.mocap_pos)]
        for _ in range(3):
            state = env.step(state, action)
            trajectory.append(np.asarray(state.pipeline_state.mocap_pos))
        poses[motion] = np.stack(trajectory)
        if motion == "per_step":
            assert handed.origins == [None] * 3
        else:  # the origins handed over are the previous steps' poses
            for origin, previous in zip(handed.origins, trajectory[:-1]):
                np.testing.assert_allclose(origin, previous, atol=1e-7)
    np.testing.assert_allclose(poses["per_step"], poses["continuous"], atol=1e-5)
    assert np.abs(poses["continuous"][-1] - poses["continuous"][0]).max() > 0.02  # it moved
    still = env_lib.make_env(
        "et", mocap_source="synthetic", physics="native", partner_motion="continuous"
    )
    handed = _Handed(still.physics.step)
    monkeypatch.setattr(still.physics, "step", handed)
    still.step(still.reset(jax.random.PRNGKey(4)), action)
    assert handed.origins == [None]
    with pytest.raises(ValueError, match="unknown partner_motion 'smooth'"):
        env_lib.HandInteractionEnv(env_lib.EnvConfig(partner_motion="smooth"))


def test_the_player_glides_the_partner_as_the_training_physics_does():
    """The exported player (NumPy, no JAX) carries the partner along the same substep
    poses as ``physics.mocap_path``, and only for a continuous partner that moved."""
    from types import SimpleNamespace

    from mjx_hands import onnx_player, physics

    rng = np.random.default_rng(5)
    start = (rng.normal(size=(5, 3)).astype(np.float32), IDENTITY[None].repeat(5, 0))
    turn = rng.normal(size=(5, 4)).astype(np.float32)
    end = (
        rng.normal(size=(5, 3)).astype(np.float32),
        turn / np.linalg.norm(turn, axis=-1)[:, None],
    )
    positions, quats = physics.mocap_path(start, end, 10)
    for k in range(10):
        pos, quat = onnx_player.glide(start, end, (k + 1) / 10)
        np.testing.assert_allclose(pos, positions[k], atol=1e-6)
        np.testing.assert_allclose(quat, quats[k], atol=1e-6)
    glides = lambda motion, a, b: onnx_player.Player._glides(
        SimpleNamespace(env={"partner_motion": motion}), a, b
    )
    assert glides("continuous", start, end)
    assert not glides("continuous", start, start) and not glides("per_step", start, end)
    assert not onnx_player.Player._glides(SimpleNamespace(env={}), start, end)  # older exports
