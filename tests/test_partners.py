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
from mjx_hands import spatial, train_config, training

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
    config = train_config.TrainConfig(target_orientation_range=HALF, run_dir=str(tmp_path))
    assert training.env_config(config).target_orientation_range == HALF
    data = json.loads(json.dumps(train_config.config_to_json(config)))
    back = train_config.config_from_json(data)
    assert back == train_config.resolved(config) and hash(back)  # a tuple again
    assert dataclasses.replace(back, target_orientation_range=None) != back
