"""Jitted, multi-device DDPG: one compiled call per training epoch.

An epoch is ``iterations_per_epoch`` iterations of: ``unroll_length`` steps of every
environment with the exploring policy (``lax.scan``), insertion of those transitions
into the device-resident replay buffer, ``updates_per_iteration`` SGD updates of
critic and actor (``lax.scan``), and one Polyak update of the target networks. The
whole epoch is one ``jax.pmap`` over the local devices: environments, replay
buffer and minibatches are split across devices, parameters are replicated, and
gradients and observation statistics are all-reduced (``axis_name='devices'``).
Nothing crosses between host and device inside an epoch, and the trainer state is
donated, so the buffer is updated in place.

Multi-host: call ``jax.distributed.initialize()`` before building the trainer and
run the same program on every host. The pmap then spans all hosts' devices (each
host feeds its local ones, with keys folded by ``jax.process_index()``) and the
collectives all-reduce across hosts; sizes in the config are per host. This path
follows JAX's multi-process pmap rules but has not been run on several hosts here.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct

from mjx_hands.agents.ddpg import losses, networks, replay

AXIS = "devices"


@dataclasses.dataclass(frozen=True)
class DDPGConfig:
    """DDPG hyperparameters (defaults: the paper's authors' released configuration)."""

    hidden_sizes: tuple[int, ...] = (256, 256, 256)
    """Hidden layers of actor and critic (ReLU)."""
    layer_norm: bool = False
    """LayerNorm after every hidden layer of both networks."""
    batch_norm: bool = False
    """Batch normalisation after every hidden layer of both networks, as in the paper
    (minibatch statistics while training, all-reduced over devices; running averages
    when acting and in the target networks)."""
    actor_learning_rate: float = 1e-3
    """Adam step size of the actor."""
    critic_learning_rate: float = 1e-3
    """Adam step size of the critic."""
    batch_size: int = 256
    """Minibatch size of one SGD update, summed over devices."""
    polyak: float = 0.95
    """Target networks keep this fraction of themselves at every target update."""
    discount: float | None = None
    """γ; None takes 1 - 1/T with T the episode length."""
    action_l2: float = 1.0
    """Weight of the mean squared action penalty in the actor loss."""
    random_action_prob: float = 0.3
    """Probability that an exploration step takes a uniformly random action."""
    noise_scale: float = 0.2
    """Std of the Gaussian noise added to the policy's action when exploring."""
    replay_capacity: int = 1_000_000
    """Transitions kept in the replay buffer, summed over devices."""
    min_replay_size: int = 2_000
    """Transitions (summed over devices) collected before SGD starts."""
    unroll_length: int = 10
    """Environment steps of every environment per iteration."""
    updates_per_iteration: int = 40
    """SGD updates per iteration (the target networks follow once per iteration)."""
    iterations_per_epoch: int = 10
    """Iterations per compiled epoch."""
    normalize_observations: bool = True
    """Standardise observations by running statistics before both networks."""
    observation_clip: float = 5.0
    """Normalised observations are clipped to ±this."""
    target_clip: tuple[float, float] | None = None
    """Optional clip of the Bellman target (e.g. the return's known range)."""

    def __post_init__(self):
        checks = {
            "batch_size": self.batch_size > 0,
            "replay_capacity": self.replay_capacity >= self.batch_size,
            "unroll_length": self.unroll_length > 0,
            "updates_per_iteration": self.updates_per_iteration > 0,
            "min_replay_size": 0 <= self.min_replay_size <= self.replay_capacity,
            "iterations_per_epoch": self.iterations_per_epoch > 0,
            "polyak": 0.0 <= self.polyak <= 1.0,
            "random_action_prob": 0.0 <= self.random_action_prob <= 1.0,
            "noise_scale": self.noise_scale >= 0.0,
            "discount": self.discount is None or 0.0 <= self.discount <= 1.0,
            "actor_learning_rate": self.actor_learning_rate > 0,
            "critic_learning_rate": self.critic_learning_rate > 0,
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            values = ", ".join(f"{n}={getattr(self, n)!r}" for n in bad)
            raise ValueError(f"invalid DDPG config: {values}")


@struct.dataclass
class LearnerState:
    """Everything SGD changes; replicated over devices."""

    actor_params: Any
    critic_params: Any
    target_actor_params: Any
    target_critic_params: Any
    actor_opt_state: Any
    critic_opt_state: Any
    normalizer: networks.Normalizer
    updates: jax.Array  # () int32


@struct.dataclass
class EpisodeStats:
    """Running sums of the episodes in progress, per environment (num_envs,)."""

    episode_return: jax.Array
    episode_success: jax.Array  # 1 once the required contacts all touched this episode


@struct.dataclass
class TrainerState:
    """The whole training state; every leaf has a leading device axis."""

    learner: LearnerState
    env_state: Any
    buffer: replay.ReplayBuffer
    stats: EpisodeStats
    rng: jax.Array
    env_steps: jax.Array  # () int32, this device's environment steps so far


class DDPG:
    """DDPG on a batched Brax-API environment (see ``mjx_hands.env.BatchedEnv``).

    Args:
      env: batched environment holding the *per-device* number of envs; its states
        carry ``info['terminal_obs']``, ``info['truncation']`` and ``info['success']``.
      eval_env: batched environment for evaluation (per-device batch); default ``env``.
      episode_length: control steps per episode (sets γ and the evaluation length).
    """

    def __init__(
        self,
        env,
        config: DDPGConfig = DDPGConfig(),
        *,
        episode_length: int,
        eval_env=None,
        devices: list | None = None,
    ):
        self.env = env
        self.eval_env = eval_env or env
        self.config = config
        self.episode_length = episode_length
        # devices=None: every device of every host (multi-host); else exactly these.
        self._pmap_devices = devices
        self.devices = devices or jax.local_devices()
        self.num_devices = len(self.devices)
        for name in ("batch_size", "replay_capacity", "min_replay_size"):
            if getattr(config, name) % self.num_devices:
                raise ValueError(
                    f"{name}={getattr(config, name)} is not divisible by the "
                    f"{self.num_devices} devices"
                )
        self.gamma = config.discount if config.discount is not None else 1.0 - 1.0 / episode_length
        self.actor = networks.Actor(
            env.action_size, config.hidden_sizes, config.layer_norm, config.batch_norm, AXIS
        )
        self.critic = networks.Critic(
            config.hidden_sizes, config.layer_norm, config.batch_norm, AXIS
        )
        self.actor_opt = optax.adam(config.actor_learning_rate)
        self.critic_opt = optax.adam(config.critic_learning_rate)
        self.trace_count = 0
        """How often the epoch function was traced (1 after any number of epochs)."""
        pmap = functools.partial(jax.pmap, axis_name=AXIS, devices=self._pmap_devices)
        self._init = pmap(self._init_device)
        self._epoch = pmap(self._epoch_device, donate_argnums=0)
        self._evaluate = pmap(self._evaluate_device)
        # Host arrays with a leading device axis -> one shard per device, laid out exactly
        # as the epoch's outputs (same mesh axis name), so jit sees no new input sharding.
        self.to_devices = pmap(lambda tree: tree)

    # ------------------------------------------------------------- networks
    def normalize(self, learner: LearnerState, obs: jax.Array) -> jax.Array:
        if not self.config.normalize_observations:
            return obs
        return learner.normalizer.normalize(obs, self.config.observation_clip)

    def policy(self, learner: LearnerState, obs: jax.Array) -> jax.Array:
        """Deterministic action (..., act) of observations (..., obs)."""
        return self.actor.apply(learner.actor_params, self.normalize(learner, obs))

    def _explore(self, learner: LearnerState, obs: jax.Array, rng: jax.Array) -> jax.Array:
        k_noise, k_random, k_pick = jax.random.split(rng, 3)
        action = self.policy(learner, obs)
        action = jnp.clip(
            action + self.config.noise_scale * jax.random.normal(k_noise, action.shape), -1, 1
        )
        random = jax.random.uniform(k_random, action.shape, minval=-1.0, maxval=1.0)
        pick = jax.random.uniform(k_pick, action.shape[:-1] + (1,)) < self.config.random_action_prob
        return jnp.where(pick, random, action)

    # ------------------------------------------------------------------ init
    def init(self, rng: jax.Array) -> TrainerState:
        """A fresh trainer state from one key; leaves get a leading device axis."""
        rng = jax.random.fold_in(rng, jax.process_index())  # distinct envs on every host
        return self._init(jax.random.split(rng, self.num_devices))

    def _init_device(self, rng: jax.Array) -> TrainerState:
        # Parameters must agree across devices: derive them from a key all devices share.
        shared = jax.random.fold_in(jax.lax.all_gather(rng, AXIS)[0], 0)
        k_actor, k_critic = jax.random.split(shared)
        rng, k_env = jax.random.split(rng)
        obs = jnp.zeros((1, self.env.observation_size))
        act = jnp.zeros((1, self.env.action_size))
        actor_params = self.actor.init(k_actor, obs)
        critic_params = self.critic.init(k_critic, obs, act)
        learner = LearnerState(
            actor_params=actor_params,
            critic_params=critic_params,
            target_actor_params=actor_params,
            target_critic_params=critic_params,
            actor_opt_state=self.actor_opt.init(actor_params),
            critic_opt_state=self.critic_opt.init(critic_params),
            normalizer=networks.Normalizer.create(self.env.observation_size),
            updates=jnp.zeros((), jnp.int32),
        )
        env_state = self.env.reset(k_env)
        example = replay.Transition(
            obs=env_state.obs[0],
            action=jnp.zeros(self.env.action_size),
            reward=jnp.zeros(()),
            discount=jnp.zeros(()),
            next_obs=env_state.obs[0],
        )
        buffer = replay.create(self.config.replay_capacity // self.num_devices, example)
        n = env_state.reward.shape[0]
        stats = EpisodeStats(jnp.zeros(n), jnp.zeros(n))
        return TrainerState(learner, env_state, buffer, stats, rng, jnp.zeros((), jnp.int32))

    # ----------------------------------------------------------------- epoch
    def run_epoch(self, state: TrainerState) -> tuple[TrainerState, dict[str, float]]:
        """One compiled epoch; ``state`` is donated. Returns the new state and host metrics."""
        state, metrics = self._epoch(state)
        return state, {k: float(v[0]) for k, v in jax.device_get(metrics).items()}

    def _epoch_device(self, state: TrainerState):
        self.trace_count += 1  # runs only while tracing: counts compilations
        cfg = self.config

        def iteration(state: TrainerState, _):
            rng, k_unroll, k_sgd = jax.random.split(state.rng, 3)
            (env_state, stats), (transitions, finished) = jax.lax.scan(
                functools.partial(self._env_step, state.learner),
                (state.env_state, state.stats),
                jax.random.split(k_unroll, cfg.unroll_length),
            )
            flat = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), transitions)
            buffer = replay.insert(state.buffer, flat)
            learner = state.learner
            if cfg.normalize_observations:
                learner = learner.replace(normalizer=learner.normalizer.update(flat.obs, AXIS))
            ready = buffer.size * self.num_devices >= cfg.min_replay_size
            learner, sgd_metrics = jax.lax.cond(
                ready,
                lambda learner: self._train(learner, buffer, k_sgd),
                lambda learner: (learner, self._zero_sgd_metrics()),
                learner,
            )
            state = state.replace(
                learner=learner,
                env_state=env_state,
                buffer=buffer,
                stats=stats,
                rng=rng,
                env_steps=state.env_steps + flat.reward.shape[0],
            )
            return state, (finished, sgd_metrics)

        state, (finished, sgd_metrics) = jax.lax.scan(
            iteration, state, None, length=cfg.iterations_per_epoch
        )
        episodes = jax.lax.psum(finished["done"].sum(), AXIS)
        # NaN, not 0, when no episode ended this epoch (epochs shorter than an episode).
        per_episode = lambda x: jnp.where(
            episodes > 0, jax.lax.psum(x.sum(), AXIS) / jnp.maximum(episodes, 1), jnp.nan
        )
        metrics = {
            "train/episodes": episodes,
            "train/episode_return": per_episode(finished["return"]),
            "train/success": per_episode(finished["success"]),
            "train/reward_per_step": jax.lax.pmean(finished["reward"].mean(), AXIS),
            "train/env_steps": jax.lax.psum(state.env_steps, AXIS),
            "train/updates": state.learner.updates,
            "train/replay_size": jax.lax.psum(state.buffer.size, AXIS),
            "train/params_finite": _all_finite(
                (state.learner.actor_params, state.learner.critic_params)
            ).astype(jnp.float32),
        }
        # Environment metrics (reward terms, ...) averaged over the epoch's steps.
        metrics |= {
            f"env/{k}": jax.lax.pmean(v.mean(), AXIS) for k, v in finished["env_metrics"].items()
        }
        # SGD metrics of the epoch's last iteration (the most recent networks).
        metrics |= {k: v[-1].mean() for k, v in sgd_metrics.items()}
        return state, metrics

    def _env_step(self, learner: LearnerState, carry, rng):
        env_state, stats = carry
        action = self._explore(learner, env_state.obs, rng)
        next_state = self.env.step(env_state, action)
        done, truncation = next_state.done, next_state.info["truncation"]
        transition = replay.Transition(
            obs=env_state.obs,
            action=action,
            reward=next_state.reward,
            discount=1.0 - done * (1.0 - truncation),
            next_obs=next_state.info["terminal_obs"],
        )
        episode_return = stats.episode_return + next_state.reward
        episode_success = jnp.maximum(stats.episode_success, next_state.info["success"])
        finished = {
            "done": done,
            "return": episode_return * done,
            "success": episode_success * done,
            "reward": next_state.reward,
            "env_metrics": next_state.metrics,  # e.g. each reward term, per step
        }
        stats = EpisodeStats(episode_return * (1 - done), episode_success * (1 - done))
        return (next_state, stats), (transition, finished)

    def _zero_sgd_metrics(self) -> dict[str, jax.Array]:
        keys = ("critic_loss", "q", "target_q", "actor_loss", "action_penalty")
        zero = jnp.zeros((self.config.updates_per_iteration,))
        return {f"sgd/{k}": zero for k in keys}

    def _train(self, learner: LearnerState, buffer: replay.ReplayBuffer, rng: jax.Array):
        """``updates_per_iteration`` SGD updates, then a Polyak step of the targets."""
        per_device = self.config.batch_size // self.num_devices

        def update(learner: LearnerState, key):
            batch = replay.sample(buffer, key, per_device)
            return self.sgd_step(learner, batch)

        learner, metrics = jax.lax.scan(
            update, learner, jax.random.split(rng, self.config.updates_per_iteration)
        )
        learner = learner.replace(
            target_actor_params=losses.polyak(
                learner.target_actor_params, learner.actor_params, self.config.polyak
            ),
            target_critic_params=losses.polyak(
                learner.target_critic_params, learner.critic_params, self.config.polyak
            ),
        )
        return learner, metrics

    def sgd_step(self, learner: LearnerState, batch: replay.Transition):
        """One critic and one actor update on ``batch`` (leaves (per-device batch, ...))."""
        batch = batch.replace(
            obs=self.normalize(learner, batch.obs), next_obs=self.normalize(learner, batch.next_obs)
        )
        critic_grad, (critic_metrics, critic_vars) = jax.grad(losses.critic_loss, has_aux=True)(
            learner.critic_params,
            learner.target_actor_params,
            learner.target_critic_params,
            batch,
            actor_apply=self.actor.apply,
            critic_apply=self.critic.apply,
            gamma=self.gamma,
            target_clip=self.config.target_clip,
            critic_train_apply=self._train_apply(self.critic),
        )
        actor_grad, (actor_metrics, actor_vars) = jax.grad(losses.actor_loss, has_aux=True)(
            learner.actor_params,
            learner.critic_params,
            batch.obs,
            actor_apply=self.actor.apply,
            critic_apply=self.critic.apply,
            action_l2=self.config.action_l2,
            actor_train_apply=self._train_apply(self.actor),
        )
        critic_grad, actor_grad = jax.lax.pmean((critic_grad, actor_grad), AXIS)
        critic_updates, critic_opt_state = self.critic_opt.update(
            critic_grad, learner.critic_opt_state
        )
        actor_updates, actor_opt_state = self.actor_opt.update(actor_grad, learner.actor_opt_state)
        critic_params = optax.apply_updates(learner.critic_params, critic_updates)
        actor_params = optax.apply_updates(learner.actor_params, actor_updates)
        if self.config.batch_norm:
            # Running averages of the minibatch statistics, the same on every device.
            stats = jax.lax.pmean((critic_vars["batch_stats"], actor_vars["batch_stats"]), AXIS)
            critic_params = critic_params | {"batch_stats": stats[0]}
            actor_params = actor_params | {"batch_stats": stats[1]}
        learner = learner.replace(
            critic_params=critic_params,
            actor_params=actor_params,
            critic_opt_state=critic_opt_state,
            actor_opt_state=actor_opt_state,
            updates=learner.updates + 1,
        )
        metrics = jax.lax.pmean(critic_metrics | actor_metrics, AXIS)
        return learner, {f"sgd/{k}": v for k, v in metrics.items()}

    def _train_apply(self, module):
        """Forward pass in training mode: (variables, *inputs) -> (output, new variables)."""
        if not self.config.batch_norm:
            return None

        def apply(variables, *inputs):
            out, updates = module.apply(variables, *inputs, train=True, mutable=["batch_stats"])
            return out, variables | updates

        return apply

    # ------------------------------------------------------------ evaluation
    def evaluate(self, state: TrainerState, rng: jax.Array) -> dict[str, float]:
        """Deterministic-policy episodes on ``eval_env`` (one per env and device).

        Returns mean episode return, ``success`` (the required contacts all touched at
        some step) and ``success_final`` (they touch at the last step).
        """
        return self.evaluate_learner(state.learner, rng)

    def evaluate_learner(self, learner: LearnerState, rng: jax.Array) -> dict[str, float]:
        """:meth:`evaluate` of a replicated learner (leaves with a leading device axis)."""
        rng = jax.random.fold_in(rng, jax.process_index())
        metrics = self._evaluate(learner, jax.random.split(rng, self.num_devices))
        return {k: float(v[0]) for k, v in jax.device_get(metrics).items()}

    def _evaluate_device(self, learner: LearnerState, rng: jax.Array):
        env = self.eval_env

        def step(env_state, _):
            next_state = env.step(env_state, self.policy(learner, env_state.obs))
            return next_state, (next_state.reward, next_state.info["success"])

        start = env.reset(rng)
        _, (reward, success) = jax.lax.scan(step, start, None, length=self.episode_length)
        return jax.lax.pmean(
            {
                "eval/episode_return": reward.sum(axis=0).mean(),
                "eval/success": success.max(axis=0).mean(),
                "eval/success_final": success[-1].mean(),
            },
            AXIS,
        )


def _all_finite(tree) -> jax.Array:
    leaves = jax.tree.leaves(tree)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))
