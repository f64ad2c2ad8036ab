"""The environment contract (mjx_hands.contract) holds for the hand environment and the
point-reach test task alike: what the learners, run loop and evaluate rely on."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_hands import contract
from mjx_hands.point_reach import make_point_reach


def _check(batched, reset, step) -> dict:
    single = batched.unwrapped
    assert isinstance(single, contract.InteractionEnv)
    assert single.describe() and isinstance(single.describe(), str)
    state = reset(jax.random.PRNGKey(0))
    assert contract.missing_info(state) == []
    state = step(state, jnp.zeros((batched.num_envs, batched.action_size)))
    assert contract.missing_info(state) == []
    assert state.info["terminal_obs"].shape == state.obs.shape  # the wrapper's entry
    for key in contract.INFO_KEYS.keys() - {"episode"}:
        assert state.info[key].shape == (batched.num_envs,), key
    return single.pose(state.pipeline_state)


def test_the_hand_environment_keeps_the_contract(native_handshake_env):
    env, reset, step = native_handshake_env
    pose = _check(env, reset, step)
    assert set(pose) == {"qpos", "mocap_pos", "mocap_quat"}
    assert pose["qpos"].shape == (env.num_envs, env.unwrapped.mj_model.nq)


def test_the_point_reach_task_keeps_the_contract():
    env = make_point_reach(4)
    assert _check(env, jax.jit(env.reset), jax.jit(env.step)) == {}  # nothing renders
    with pytest.raises(ValueError, match="no reward variants"):
        env.unwrapped.variant_for(None)


def test_a_state_without_the_contracts_info_is_named():
    env = make_point_reach(2)
    state = env.reset(jax.random.PRNGKey(0))
    del state.info["success"]
    state.info["episode"] = ()
    assert contract.missing_info(state) == ["success", "episode.rng"]


def test_evaluation_metrics_match_a_numpy_transcription():
    rng = np.random.default_rng(0)
    reward = rng.normal(size=(7, 3, 5))  # (T, members, episodes)
    success = (rng.random((7, 3, 5)) > 0.6).astype(np.float32)
    distance = rng.random((3, 5))
    distance[1, 2] = np.nan  # a diverged episode has no pose
    final = {"pose/fingertip_goal_distance": distance, "reward/total": reward[-1]}
    got = contract.evaluation_metrics(reward, success, final)
    assert set(got) == {
        "eval/episode_return",
        "eval/success",
        "eval/success_final",
        "eval/final_fingertip_goal_distance",
    }
    np.testing.assert_allclose(got["eval/episode_return"], reward.sum(0).mean(-1), rtol=1e-6)
    np.testing.assert_allclose(got["eval/success"], success.any(0).mean(-1))
    np.testing.assert_allclose(got["eval/success_final"], success[-1].mean(-1))
    expected = [np.mean([d for d in row if np.isfinite(d)]) for row in distance]
    np.testing.assert_allclose(got["eval/final_fingertip_goal_distance"], expected, rtol=1e-6)
