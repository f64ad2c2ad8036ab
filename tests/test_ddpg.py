"""DDPG: replay buffer, Bellman targets, learning on a pure-JAX task, multi-device."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_hands.agents.ddpg import DDPG, DDPGConfig, losses, replay
from mjx_hands.point_reach import PointReach, make_point_reach

POINT_CONFIG = DDPGConfig(
    hidden_sizes=(64, 64),
    batch_size=128,
    replay_capacity=20_000,
    min_replay_size=640,
    unroll_length=5,
    updates_per_iteration=10,
    iterations_per_epoch=20,
    action_l2=0.05,  # the authors' 1.0 suits the hand reward's scale, not this task's
)


def _transitions(start: int, n: int) -> replay.Transition:
    """n distinguishable transitions numbered from ``start`` (obs 3, action 2)."""
    ids = np.arange(start, start + n, dtype=np.float32)
    return replay.Transition(
        obs=np.stack([ids, ids + 0.1, ids + 0.2], -1),
        action=np.stack([-ids, -ids - 0.5], -1),
        reward=ids * 10,
        discount=(ids % 2).astype(np.float32),
        next_obs=np.stack([ids + 1, ids + 1.1, ids + 1.2], -1),
        last=(ids % 3 == 0).astype(np.float32),
    )


def test_replay_keeps_inserted_transitions_and_wraps_oldest_first():
    example = jax.tree.map(lambda x: x[0], _transitions(0, 1))
    buffer = replay.create(5, example)
    buffer = replay.insert(buffer, _transitions(0, 3))
    assert int(buffer.size) == 3 and int(buffer.position) == 3
    np.testing.assert_array_equal(buffer.data.reward[:3], [0, 10, 20])

    buffer = replay.insert(buffer, _transitions(3, 4))  # ids 3..6; 5 and 6 wrap to slots 0, 1
    assert int(buffer.size) == 5 and int(buffer.position) == 2
    expected_ids = np.array([5, 6, 2, 3, 4], np.float32)
    want = _transitions(0, 7)
    for field in ("obs", "action", "reward", "discount", "next_obs"):
        np.testing.assert_array_equal(
            getattr(buffer.data, field), getattr(want, field)[expected_ids.astype(int)], field
        )


def test_replay_samples_only_filled_slots_uniformly():
    example = jax.tree.map(lambda x: x[0], _transitions(0, 1))
    buffer = replay.insert(replay.create(100, example), _transitions(0, 10))
    batch = replay.sample(buffer, jax.random.PRNGKey(0), 20_000)
    ids = np.asarray(batch.reward) / 10
    assert set(np.unique(ids)) == set(range(10))  # never an empty slot
    counts = np.bincount(ids.astype(int), minlength=10)
    assert counts.min() > 1700 and counts.max() < 2300  # ~2000 each
    # Every sampled row is one whole transition, fields kept together.
    np.testing.assert_allclose(np.asarray(batch.obs)[:, 0], ids)
    np.testing.assert_allclose(np.asarray(batch.next_obs)[:, 0], ids + 1)


def test_replay_rejects_oversized_insert():
    example = jax.tree.map(lambda x: x[0], _transitions(0, 1))
    with pytest.raises(ValueError, match="capacity 4"):
        replay.insert(replay.create(4, example), _transitions(0, 5))


def test_critic_target_matches_bellman_equation():
    rng = np.random.default_rng(0)
    reward, next_q = rng.normal(size=64), rng.normal(size=64)
    discount = (rng.random(64) > 0.3).astype(np.float64)
    got = losses.critic_target(
        jnp.asarray(reward), jnp.asarray(discount), jnp.asarray(next_q), 0.99
    )
    np.testing.assert_allclose(got, reward + 0.99 * discount * next_q, rtol=1e-5, atol=1e-6)
    clipped = losses.critic_target(
        jnp.asarray(reward), jnp.asarray(discount), jnp.asarray(next_q), 0.99, clip=(-0.5, 0.0)
    )
    np.testing.assert_allclose(
        clipped, np.clip(reward + 0.99 * discount * next_q, -0.5, 0.0), rtol=1e-5, atol=1e-6
    )


@pytest.mark.parametrize("capacity", [400, 45], ids=["no_wrap", "wrapped"])
def test_n_step_samples_match_a_walk_through_each_environments_steps(capacity):
    """replay.sample_n_step against a NumPy walk: rewards summed with γ^k up to the step
    that ends an episode (an auto-reset follows it in the same environment's rows),
    bootstrap γ^m after a truncation, none after a termination."""
    rng = np.random.default_rng(7)
    envs, steps_per_insert, inserts, n, gamma = 3, 4, 6, 3, 0.9
    total = steps_per_insert * inserts
    reward = rng.normal(size=(total, envs)).astype(np.float32)
    last = rng.random((total, envs)) < 0.3
    terminated = last & (rng.random((total, envs)) < 0.5)  # the others: truncated
    step_id = np.broadcast_to(np.arange(total)[:, None], (total, envs)).astype(np.float32)
    env_id = np.broadcast_to(np.arange(envs)[None], (total, envs)).astype(np.float32)
    obs = np.stack([step_id, env_id, np.zeros_like(step_id)], -1)
    data = replay.Transition(
        obs=obs, action=np.zeros((total, envs, 2), np.float32), reward=reward,
        discount=(~terminated).astype(np.float32), next_obs=obs + 1000.0,
        last=last.astype(np.float32),
    )
    buffer = replay.create(capacity, jax.tree.map(lambda x: x[0, 0], data))
    for i in range(inserts):  # step-major rows, as the trainer inserts
        rows = slice(i * steps_per_insert, (i + 1) * steps_per_insert)
        chunk = jax.tree.map(lambda x, rows=rows: x[rows].reshape((-1,) + x.shape[2:]), data)
        buffer = replay.insert(buffer, chunk)
    got = replay.sample_n_step(buffer, jax.random.PRNGKey(0), 2000, n, gamma, envs)
    first_kept = total - int(buffer.size) // envs  # the oldest step still in the buffer
    seen = set()
    for obs_row, r, d, next_obs in zip(got.obs, got.reward, got.discount, got.next_obs):
        g, e = int(obs_row[0]), int(obs_row[1])
        seen.add((g, e))
        assert first_kept <= g <= total - n  # its n - 1 successors are written
        expected, m = 0.0, n
        for k in range(n):
            expected += gamma**k * reward[g + k, e]
            if last[g + k, e]:
                m = k + 1
                break
        np.testing.assert_allclose(r, expected, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(d, gamma ** (m - 1) * (not terminated[g + m - 1, e]), rtol=1e-6)
        np.testing.assert_allclose(next_obs, obs[g + m - 1, e] + 1000.0)
    assert len(seen) == envs * (total - n + 1 - first_kept)  # every valid start is drawn


def test_trainer_stores_each_environments_next_step_one_env_count_later():
    """The layout sample_n_step relies on: in the trainer's buffer, row i + num_envs is
    the same environment's next step unless row i ended its episode."""
    envs = 8
    config = dataclasses.replace(POINT_CONFIG, iterations_per_epoch=3, min_replay_size=10_000)
    algo = DDPG(make_point_reach(envs, episode_length=5), config, episode_length=5)
    state, _ = algo.run_epoch(algo.init(jax.random.PRNGKey(0)))
    data = jax.tree.map(lambda x: np.asarray(x)[0, 0], state.buffer.data)
    size = int(np.asarray(state.buffer.size)[0, 0])
    assert size == 3 * config.unroll_length * envs
    follows = data.last[: size - envs] == 0
    np.testing.assert_array_equal(
        data.next_obs[: size - envs][follows], data.obs[envs:size][follows]
    )
    assert follows.sum() > 0 and (~follows).sum() > 0  # episodes of 5 steps end inside


def test_c51_projection_matches_a_loop_over_atoms():
    """losses.categorical_projection against the textbook loop (Bellemare et al. 2017)."""
    rng = np.random.default_rng(11)
    batch, atoms, v_min, v_max = 64, 11, -10.0, 10.0
    support = np.linspace(v_min, v_max, atoms)
    probs = rng.dirichlet(np.ones(atoms), batch)
    reward = rng.normal(0, 6, batch)  # some shifted returns fall beyond the support
    discount = 0.95 * (rng.random(batch) > 0.2)  # 0: a termination, all mass at r
    reward[:4] = [2.0, -10.0, 10.0, 37.0]  # exactly on atoms, and beyond v_max
    got = losses.categorical_projection(
        jnp.asarray(probs), jnp.asarray(reward), jnp.asarray(discount), jnp.asarray(support)
    )
    delta = (v_max - v_min) / (atoms - 1)
    want = np.zeros((batch, atoms))
    for i in range(batch):
        for j in range(atoms):
            tz = min(max(reward[i] + discount[i] * support[j], v_min), v_max)
            b = (tz - v_min) / delta
            lo, hi = int(np.floor(b)), int(np.ceil(b))
            if lo == hi:
                want[i, lo] += probs[i, j]
            else:
                want[i, lo] += probs[i, j] * (hi - b)
                want[i, hi] += probs[i, j] * (b - lo)
    np.testing.assert_allclose(got, want, atol=1e-5)
    np.testing.assert_allclose(np.asarray(got).sum(-1), 1.0, atol=1e-5)  # mass kept


def test_twin_critics_target_takes_the_smaller_target_q_and_sum_their_errors():
    """losses.critic_loss with a two-critic ensemble against a NumPy transcription."""
    rng = np.random.default_rng(1)
    n = 32
    batch = replay.Transition(
        obs=rng.normal(size=(n, 3)).astype(np.float32),
        action=rng.uniform(-1, 1, (n, 2)).astype(np.float32),
        reward=rng.normal(size=n).astype(np.float32),
        discount=(rng.random(n) > 0.2).astype(np.float32),
        next_obs=rng.normal(size=(n, 3)).astype(np.float32),
        last=np.zeros(n, np.float32),
    )
    w_actor = rng.normal(size=(3, 2)).astype(np.float32)
    w_critic = rng.normal(size=(2, 5)).astype(np.float32)  # two linear critics on [obs, act]
    actor = lambda p, obs: jnp.tanh(obs @ p)
    critics = lambda p, obs, act: jnp.concatenate([obs, act], -1) @ p.T  # -> (batch, 2)
    ensemble = lambda p, obs, act: critics(p, obs, act).T  # (2, batch)
    online = w_critic + 0.1
    loss, (metrics, _) = losses.critic_loss(
        online, w_actor, w_critic, batch, actor_apply=actor, critic_apply=ensemble, gamma=0.9
    )
    next_a = np.tanh(batch.next_obs @ w_actor)
    next_q = (np.concatenate([batch.next_obs, next_a], -1) @ w_critic.T).min(-1)
    target = batch.reward + 0.9 * batch.discount * next_q
    q = np.concatenate([batch.obs, batch.action], -1) @ online.T  # (batch, 2)
    expected = ((q - target[:, None]) ** 2).mean(0).sum()
    np.testing.assert_allclose(loss, expected, rtol=1e-5)
    np.testing.assert_allclose(metrics["target_q"], target.mean(), rtol=1e-5, atol=1e-6)


def test_target_policy_smoothing_noise_is_clipped():
    action = jnp.asarray(np.linspace(-1, 1, 4000).reshape(2000, 2), jnp.float32)
    key = jax.random.PRNGKey(3)
    got = np.asarray(losses.smoothed_action(action, key, noise=5.0, noise_clip=0.3))
    eps = np.clip(5.0 * np.asarray(jax.random.normal(key, action.shape)), -0.3, 0.3)
    np.testing.assert_allclose(got, np.clip(np.asarray(action) + eps, -1, 1), atol=1e-6)
    assert np.abs(got - np.asarray(action)).max() <= 0.3 + 1e-6
    assert (np.abs(eps) == 0.3).mean() > 0.9  # sigma 5 hits the clip almost always


def test_delayed_actor_updates_once_per_interval():
    """With actor_update_interval 4 the actor's optimiser counts a quarter of the critic's
    updates; the default updates both every step."""
    for interval in (1, 4):
        config = dataclasses.replace(
            POINT_CONFIG, actor_update_interval=interval, updates_per_iteration=8,
            iterations_per_epoch=2, min_replay_size=160, twin_critics=True,
            target_policy_noise=0.2,
        )
        algo = DDPG(make_point_reach(16), config, episode_length=20)
        state, _ = algo.run_epoch(algo.init(jax.random.PRNGKey(0)))
        learner = jax.tree.map(lambda x: np.asarray(x)[0, 0], state.learner)
        critic_count = int(learner.critic_opt_state[0].count)
        actor_count = int(learner.actor_opt_state[0].count)
        assert critic_count == int(learner.updates) > 0
        assert actor_count == critic_count // interval
        # Two critics, initialised apart.
        kernel = jax.tree.leaves(learner.critic_params)[-1]
        assert kernel.shape[0] == 2 and not np.allclose(kernel[0], kernel[1])


def test_invalid_td3_options_are_refused():
    with pytest.raises(ValueError, match="actor_update_interval must divide"):
        DDPGConfig(updates_per_iteration=10, actor_update_interval=3)
    with pytest.raises(ValueError, match="twin_critics does not combine with batch_norm"):
        DDPGConfig(twin_critics=True, batch_norm=True)


def test_collected_transitions_bootstrap_truncation_but_not_termination():
    """A truncated step keeps discount 1 and its true last observation; a terminal step 0."""
    n, length = 6, 4
    env = make_point_reach(n, episode_length=length, terminate_on_success=True)
    algo = DDPG(env, POINT_CONFIG, episode_length=length)
    learner = jax.tree.map(lambda x: x[0], algo.init(jax.random.PRNGKey(0)).learner)  # (1, ...)
    state = env.reset(jax.random.PRNGKey(1))
    episode = state.info["episode"]
    # Envs 0-1: one step from the goal (terminate); 2-3: at their last step (truncate);
    # 4-5: mid-episode, far from the goal.
    pos = np.array(state.pipeline_state)
    goal = np.asarray(episode.goal)
    pos[:2] = goal[:2] + 0.15  # one full step lands on the goal
    pos[4:] = np.clip(goal[4:] + 1.5, -3, 3)
    steps = np.array([0, 0, length - 1, length - 1, 0, 0], np.int32)
    state = state.replace(
        pipeline_state=jnp.asarray(pos),
        obs=jax.vmap(PointReach._obs)(jnp.asarray(pos), episode.goal),
        info=state.info | {"episode": episode.replace(step=jnp.asarray(steps))},
    )
    stats = jax.tree.map(lambda x: x[0], algo.init(jax.random.PRNGKey(0)).stats)
    # A deterministic action towards the goal (replace the explorer for this check).
    toward = jnp.clip((episode.goal - state.pipeline_state) / 0.2, -1, 1)
    algo._explore = lambda learner, obs, rng: toward
    one_member = lambda tree: jax.tree.map(lambda x: x[None], tree)  # a population of one
    (next_state, _), (transition, finished) = jax.jit(algo._env_step)(
        learner, (one_member(state), stats), jax.random.PRNGKey(2)[None]
    )
    next_state, transition, finished = jax.tree.map(
        lambda x: x[0], (next_state, transition, finished)
    )
    np.testing.assert_array_equal(transition.discount, [0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(finished["done"], [1, 1, 1, 1, 0, 0])
    true_next = jax.vmap(PointReach._obs)(jnp.asarray(pos) + 0.2 * toward, episode.goal)
    np.testing.assert_allclose(transition.next_obs, true_next, atol=1e-6)
    np.testing.assert_allclose(transition.obs, state.obs)
    # Finished envs restarted: their new observation is not the stored last one.
    restarted = np.abs(np.asarray(next_state.obs) - np.asarray(true_next)).max(-1)
    assert (restarted[:4] > 1e-3).all() and (restarted[4:] < 1e-6).all()


def _episode_return(env, policy, key) -> float:
    """Mean return of ``policy(obs, state)`` over one batch of episodes of ``env``."""
    state = env.reset(key)
    total = 0.0
    for _ in range(env.env.episode_length):
        state = env.step(state, policy(state))
        total += float(state.reward.mean())
    return total


@pytest.mark.slow
@pytest.mark.parametrize(
    "options, epochs",
    [
        ({"twin_critics": True, "target_policy_noise": 0.2, "actor_update_interval": 2}, 12),
        # Uncorrected n-step returns of exploring actions are biased: slower here.
        ({"n_step": 3}, 16),
        ({"num_atoms": 51, "value_range": (-40.0, 5.0)}, 12),
    ],
    ids=["td3", "n_step", "c51"],
)
def test_learner_options_solve_point_reaching(options, epochs):
    config = dataclasses.replace(POINT_CONFIG, **options)
    algo = DDPG(make_point_reach(32), config, episode_length=20)
    state = algo.init(jax.random.PRNGKey(0))
    for _ in range(epochs):
        state, _ = algo.run_epoch(state)
    (evaluation,) = algo.evaluate(state, jax.random.PRNGKey(3))
    assert evaluation["eval/success"] > 0.9, evaluation


@pytest.fixture(scope="module")
def trained_point_reach():
    env = make_point_reach(32)
    algo = DDPG(env, POINT_CONFIG, episode_length=20)
    state = algo.init(jax.random.PRNGKey(0))
    history = []
    for _ in range(12):
        state, metrics = algo.run_epoch(state)
        history.append(metrics[0])
    return algo, state, history


def test_ddpg_solves_point_reaching(trained_point_reach):
    algo, state, history = trained_point_reach
    env = make_point_reach(256)
    key = jax.random.PRNGKey(7)
    oracle = _episode_return(
        env,
        lambda s: jnp.clip((s.info["episode"].goal - s.pipeline_state) / 0.2, -1, 1),
        key,
    )
    idle = _episode_return(env, lambda s: jnp.zeros((256, 2)), key)
    learner = jax.tree.map(lambda x: x[0, 0], state.learner)
    learned = _episode_return(env, lambda s: algo.policy(learner, s.obs), key)
    # Stated target: within 1.0 of the straight-to-goal oracle (idle is ~4x worse).
    assert idle < oracle - 10.0
    assert learned > oracle - 1.0, (learned, oracle, idle)
    (evaluation,) = algo.evaluate(state, jax.random.PRNGKey(3))
    assert evaluation["eval/success"] > 0.9
    assert history[-1]["train/updates"] == 12 * 20 * 10 - 3 * 10  # 3 warm-up iterations
    assert all(np.isfinite(m["sgd/critic_loss"]) for m in history)
    # The env's own metrics are logged per step: reward = -distance here.
    np.testing.assert_allclose(
        history[-1]["env/distance"], -history[-1]["train/reward_per_step"], rtol=1e-5
    )


def test_epochs_compile_once(trained_point_reach):
    algo, _, history = trained_point_reach
    assert len(history) == 12
    assert algo.trace_count == 1


def test_invalid_config_is_refused_with_the_field_named():
    with pytest.raises(ValueError, match="polyak=1.5"):
        DDPGConfig(polyak=1.5)
    with pytest.raises(ValueError, match="batch_size=255 is not divisible"):
        DDPG(
            make_point_reach(4),
            DDPGConfig(batch_size=255),
            episode_length=20,
            devices=jax.local_devices() * 0 + [jax.local_devices()[0]] * 2,
        )


TWO_DEVICE_SCRIPT = textwrap.dedent(
    """
    import jax, numpy as np
    from mjx_hands.agents.ddpg import DDPG
    from mjx_hands.point_reach import make_point_reach
    from tests.test_ddpg import POINT_CONFIG
    assert len(jax.local_devices()) == 2, jax.local_devices()
    algo = DDPG(make_point_reach(16), POINT_CONFIG, episode_length=20)
    state = algo.init(jax.random.PRNGKey(0))
    for _ in range(12):
        state, metrics = algo.run_epoch(state)
    params = jax.tree.leaves(jax.device_get(state.learner.actor_params))
    assert all(np.array_equal(p[0], p[1]) for p in params), "replicas diverged"
    sizes = np.asarray(state.buffer.size)
    assert sizes.shape == (2, 1) and (sizes == sizes[0]).all()
    obs = np.asarray(state.env_state.obs)
    assert not np.allclose(obs[0], obs[1]), "devices run identical envs"
    (result,) = algo.evaluate(state, jax.random.PRNGKey(3))
    print("EVAL", result["eval/success"], result["eval/episode_return"], metrics[0]["train/env_steps"])
    assert result["eval/success"] > 0.9, result
    # A population of two on the same two devices: after an epoch, member 0 (seed 0) is
    # the run alone (later, float rounding grows: Adam turns sign noise on near-zero
    # gradients into learning-rate-sized steps); both members learn.
    alone, _ = algo.run_epoch(algo.init(jax.random.PRNGKey(0)))
    pair = DDPG(make_point_reach(16), POINT_CONFIG, episode_length=20, members=2)
    pop = pair.init(np.stack([np.asarray(jax.random.PRNGKey(s)) for s in (0, 7)]))
    pop, _ = pair.run_epoch(pop)
    first = jax.tree.leaves(jax.device_get(alone.learner.actor_params))
    mine = jax.tree.leaves(jax.device_get(pop.learner.actor_params))
    for a, b in zip(mine, first):
        np.testing.assert_allclose(a[:, 0], b[:, 0], rtol=1e-5, atol=1e-5)
    for _ in range(11):
        pop, _ = pair.run_epoch(pop)
    mine = jax.tree.leaves(jax.device_get(pop.learner.actor_params))
    assert all(np.array_equal(p[0], p[1]) for p in mine), "population replicas diverged"
    assert max(np.abs(p[0, 0] - p[0, 1]).max() for p in mine) > 1e-3  # distinct members
    evals = pair.evaluate(pop, np.stack([np.asarray(jax.random.PRNGKey(3))] * 2))
    assert min(e["eval/success"] for e in evals) > 0.9, evals
    print("POPULATION ok")
    """
)


@pytest.mark.slow
def test_two_cpu_devices_train_in_step(tmp_path):
    env = dict(
        os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    result = subprocess.run(
        [sys.executable, "-c", TWO_DEVICE_SCRIPT],
        cwd=root,
        env=env,
        capture_output=True,
        check=False,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
    assert "EVAL" in result.stdout and "POPULATION ok" in result.stdout


@pytest.mark.slow
def test_batch_norm_option_learns_and_keeps_running_statistics():
    config = dataclasses.replace(POINT_CONFIG, batch_norm=True)
    algo = DDPG(make_point_reach(32), config, episode_length=20)
    state = algo.init(jax.random.PRNGKey(0))
    initial = jax.device_get(state.learner.critic_params["batch_stats"])
    for _ in range(12):
        state, _ = algo.run_epoch(state)
    stats = jax.device_get(state.learner.critic_params["batch_stats"])
    moved = [np.abs(a - b).max() for a, b in zip(jax.tree.leaves(initial), jax.tree.leaves(stats))]
    assert min(moved) > 1e-3  # running means and variances follow the minibatches
    assert algo.evaluate(state, jax.random.PRNGKey(3))[0]["eval/success"] > 0.8
