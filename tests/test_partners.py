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
