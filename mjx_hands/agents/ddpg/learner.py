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

Population: the trainer holds ``members`` independent runs (an experiment grid's
seeds and reward variants) under one more leading axis, ``vmap``-ed inside the epoch;
their environments step together as one batch. An ordinary run is a population of one.

Multi-host: call ``jax.distributed.initialize()`` before building the trainer and
run the same program on every host. The pmap then spans all hosts' devices (each
host feeds its local ones, with keys folded by ``jax.process_index()``) and the
collectives all-reduce across hosts; sizes in the config are per host. This path
follows JAX's multi-process pmap rules but has not been run on several hosts here.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from mjx_hands import checkpoint
from mjx_hands.agents.ddpg import networks, replay, update
from mjx_hands.agents.ddpg.update import LearnerState
from mjx_hands.agents.population import (
    AXIS,
    Population,
    first_device,
    member,
    per_member,
    stack_members,
)


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
    twin_critics: bool = False
    """Two critics trained on the same target, which takes the smaller of their target
    values (TD3's clipped double Q: against the critic's overestimation); the first
    critic drives the actor."""
    target_policy_noise: float = 0.0
    """Std of Gaussian noise on the target actor's action in the Bellman target (TD3's
    target policy smoothing, 0.2 there; 0: off)."""
    target_noise_clip: float = 0.5
    """The smoothing noise is clipped to ±this."""
    actor_update_interval: int = 1
    """The actor updates with every this many critic updates (TD3's delayed policy
    updates, 2 there); must divide ``updates_per_iteration``."""
    n_step: int = 1
    """Steps of reward summed before bootstrapping (``replay.sample_n_step``: stops at
    an episode's end, bootstraps after a truncation but not a termination)."""
    num_atoms: int = 1
    """1: the critic is a scalar Q (DDPG). More: a C51 distributional critic, a
    categorical distribution over this many returns evenly spaced on ``value_range``
    (51 in C51), trained by cross-entropy to its projected Bellman target; the actor
    follows its mean."""
    value_range: tuple[float, float] = (-100.0, 100.0)
    """(v_min, v_max) of the distributional critic's support: the returns it can
    represent. Fit it to the critic's returns: on the hand clap the mean Q stayed within
    -4..+1, where this default's atoms lie 4.0 apart (benchmarks/results/learners.md)."""

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
            "n_step": self.n_step >= 1,
            "num_atoms": self.num_atoms >= 1,
            "value_range": self.value_range[0] < self.value_range[1],
            "target_policy_noise": self.target_policy_noise >= 0.0,
            "target_noise_clip": self.target_noise_clip >= 0.0,
            "actor_update_interval": self.actor_update_interval > 0
            and self.updates_per_iteration % self.actor_update_interval == 0,
            # Batch statistics of an ensemble's members are not carried: refuse the pair.
            "twin_critics": not (self.twin_critics and self.batch_norm),
            "hidden_sizes": len(self.hidden_sizes) > 0 and all(h > 0 for h in self.hidden_sizes),
        }
        # NaN passes every comparison's negation above: refuse non-finite numbers first.
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            numbers = value if isinstance(value, tuple) else (value,)
            if any(isinstance(x, float) and not math.isfinite(x) for x in numbers):
                checks[field.name] = False
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            values = ", ".join(f"{n}={getattr(self, n)!r}" for n in bad)
            raise ValueError(
                f"invalid DDPG config: {values} (actor_update_interval must divide "
                "updates_per_iteration; twin_critics does not combine with batch_norm)"
                if {"actor_update_interval", "twin_critics"} & set(bad)
                else f"invalid DDPG config: {values}"
            )


@struct.dataclass
class EpisodeStats:
    """Running sums of the episodes in progress, per environment (num_envs,)."""

    episode_return: jax.Array
    episode_success: jax.Array  # 1 once the required contacts all touched this episode


@struct.dataclass
class TrainerState:
    """The whole training state of a population of independent runs (members).

    Every leaf has the leading axes (devices, members): an ordinary run is a
    population of one. ``member(state, i)`` is run ``i`` alone, laid out as a
    population-free state with a leading device axis.
    """

    learner: LearnerState
    env_state: Any  # per member: a batched env state of the per-device num_envs
    buffer: replay.ReplayBuffer
    stats: EpisodeStats
    rng: jax.Array  # (devices, members, 2)
    env_steps: jax.Array  # (devices, members) int32, each device's environment steps so far


class DDPG:
    """DDPG on a batched Brax-API environment (see ``mjx_hands.env.BatchedEnv``), for a
    population of ``members`` independent runs trained together in one compiled epoch.

    Each member has its own networks, optimiser states, normaliser, replay buffer,
    environments and keys; members share only the program. A member's keys come from
    its own seed exactly as a run alone derives them, so member ``i`` of a population
    trains as a population of one with its seed and reward would (the test suite checks
    it). Environments of all members step as one batch (one physics call; on the
    native backend one ``mujoco.rollout``), everything else is ``vmap``-ed over members.

    Args:
      env: batched environment holding the *per-device, per-member* number of envs; its
        states carry ``info['terminal_obs']``, ``info['truncation']``, ``info['success']``.
      eval_env: batched environment for evaluation (per-device, per-member batch);
        default ``env``.
      episode_length: control steps per episode (sets γ and the evaluation length).
      members: runs in the population.
      member_info: entries of each member's environment ``info`` (leaves with a leading
        ``members`` axis), e.g. ``{'reward_weights': ...}``: each member's reward variant
        as data. None keeps what the environment's reset puts there.
    """

    def __init__(
        self,
        env,
        config: DDPGConfig = DDPGConfig(),
        *,
        episode_length: int,
        eval_env=None,
        devices: list | None = None,
        members: int = 1,
        member_info: dict[str, Any] | None = None,
    ):
        self.population = Population(
            env,
            episode_length=episode_length,
            eval_env=eval_env,
            members=members,
            member_info=member_info,
            devices=devices,
        )
        self.env = env
        self.config = config
        self.episode_length = episode_length
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
            config.hidden_sizes, config.layer_norm, config.batch_norm, AXIS, config.num_atoms
        )
        self.support = jnp.linspace(*config.value_range, config.num_atoms)  # C51's returns
        self.actor_opt = optax.adam(config.actor_learning_rate)
        self.critic_opt = optax.adam(config.critic_learning_rate)
        self.model = update.Model(
            config,
            self.actor,
            self.critic,
            self.actor_opt,
            self.critic_opt,
            self.gamma,
            self.support,
            self.num_devices,
        )
        self.trace_count = 0
        """How often the epoch function was traced (1 after any number of epochs)."""
        self._init = self.population.pmap(self._init_device)
        self._epoch = self.population.pmap(self._epoch_device, donate_argnums=0)
        self._evaluate = self.population.evaluation(self.policy)
        self.to_devices = self.population.to_devices

    # The population's layout, read from it (one source: the runner every learner reuses).
    @property
    def eval_env(self):
        return self.population.eval_env

    @property
    def members(self) -> int:
        return self.population.members

    @property
    def member_info(self) -> dict[str, Any] | None:
        return self.population.member_info

    @property
    def devices(self) -> list:
        return self.population.devices

    @property
    def num_devices(self) -> int:
        return self.population.num_devices

    # ------------------------------------------------------------- networks
    def normalize(self, learner: LearnerState, obs: jax.Array) -> jax.Array:
        return self.model.normalize(learner, obs)

    def policy(self, learner: LearnerState, obs: jax.Array) -> jax.Array:
        """Deterministic action (..., act) of one run's learner for observations (..., obs)."""
        return self.model.policy(learner, obs)

    def _explore(self, learner: LearnerState, obs: jax.Array, rng: jax.Array) -> jax.Array:
        return update.explore(self.model, learner, obs, rng)

    # ------------------------------------------------------------------ init
    @functools.cached_property
    def state_shapes(self) -> TrainerState:
        """The trainer state's structure, shapes and dtypes (``jax.eval_shape`` of
        :meth:`init`; traced once per learner, nothing compiled): what a checkpoint is
        restored into."""
        return jax.eval_shape(self.init, jax.random.PRNGKey(0))

    # ----------------------------------------------------------- checkpoint layout
    def checkpoint_tree(
        self, state: TrainerState, save_replay: bool, index: int = 0
    ) -> dict[str, Any]:
        """What a run's checkpoint holds: member ``index`` of the population, leaves with a
        leading device axis (the learner replicated, so device 0's copy). Also for
        abstract (``jax.eval_shape``) states, as the structure to restore into."""
        one = self._member(state, index)
        split = {"env_state": one.env_state, "stats": one.stats, "rng": one.rng}
        split["env_steps"] = one.env_steps
        if save_replay:
            split["buffer"] = one.buffer
        return {"learner": jax.tree.map(first_device, one.learner)} | self._all_rows(split)

    def _member(self, state: TrainerState, index: int) -> TrainerState:
        """Member ``index`` with a leading device axis: abstract, on this process's devices,
        or, across processes, this process's rows on the host."""
        population = self.population
        if not population.distributed or isinstance(
            jax.tree.leaves(state)[0], jax.ShapeDtypeStruct
        ):
            return member(state, index)
        return jax.device_get(population.take_member(state, index))

    def _all_rows(self, tree):
        """Across processes, the device-split leaves of a checkpoint hold every process's
        rows (abstract: their shape; concrete: arrays all processes write together)."""
        population = self.population
        if not population.distributed:
            return tree
        leaves = jax.tree.leaves(tree)
        if isinstance(leaves[0], jax.ShapeDtypeStruct):
            n = population.num_devices
            return jax.tree.map(lambda x: jax.ShapeDtypeStruct((n,) + x.shape[1:], x.dtype), tree)
        return population.global_rows(tree)

    def policy_tree(self, state: TrainerState, index: int = 0) -> dict[str, Any]:
        """What a policy needs (the learner: networks, targets, normaliser); no env or
        buffer."""
        return {"learner": jax.tree.map(first_device, self._member(state, index).learner)}

    def load_policy(self, ckpt_dir, step: int, verified: bool = False):
        """(act, learner, epoch) of the policy a checkpoint folder (a run's ``checkpoints``
        or ``best``) holds at ``step``: ``act`` = :meth:`policy` bound to that learner as
        a ``jax.tree_util.Partial`` (the learner stays data: policies of one program
        share their compiled rollouts).
        Only the learner is read (by path), so checkpoints whose environment state has
        another layout still load; ``verified``: its digest was already checked."""
        tree, meta = checkpoint.restore(
            ckpt_dir, self.policy_tree(self.state_shapes), step, partial=True, verified=verified
        )
        learner = tree["learner"]
        return jax.tree_util.Partial(self.policy, learner), learner, int(meta["epoch"])

    def from_checkpoint_trees(
        self, trees: list[dict[str, Any]], fresh: TrainerState
    ) -> TrainerState:
        """The population state of one :meth:`checkpoint_tree` per member; what a tree
        lacks (a buffer not saved; the episodes in flight when the partner models
        changed) comes from ``fresh``."""
        n = len(self.population.local_rows)
        members = []
        for index, tree in enumerate(trees):
            fresh_member = self._member(fresh, index)
            mine = self.population.own_rows({k: v for k, v in tree.items() if k != "learner"})
            members.append(
                fresh_member.replace(
                    learner=jax.tree.map(
                        lambda x: np.broadcast_to(x, (n,) + x.shape), tree["learner"]
                    ),
                    env_state=mine.get("env_state", fresh_member.env_state),
                    stats=mine["stats"],
                    rng=mine["rng"],
                    env_steps=mine["env_steps"],
                    buffer=mine.get("buffer", fresh_member.buffer),
                )
            )
        # Laid out as the epoch's outputs: any other sharding retraces (and recompiles).
        return self.to_devices(stack_members(members))

    def init(self, rng: jax.Array) -> TrainerState:
        """A fresh trainer state from one key per member: rng (members, 2), or (2,) for a
        population of one. Leaves get the leading axes (devices, members)."""
        return self._init(self.population.device_keys(rng, "init"))

    def _init_learner(self, shared: jax.Array) -> LearnerState:
        k_actor, k_critic = jax.random.split(shared)
        obs = jnp.zeros((1, self.env.observation_size))
        act = jnp.zeros((1, self.env.action_size))
        actor_params = self.actor.init(k_actor, obs)
        if self.config.twin_critics:  # stacked: leaves (2, ...)
            critic_params = jax.vmap(lambda k: self.critic.init(k, obs, act))(
                jax.random.split(k_critic)
            )
        else:
            critic_params = self.critic.init(k_critic, obs, act)
        return LearnerState(
            actor_params=actor_params,
            critic_params=critic_params,
            target_actor_params=actor_params,
            target_critic_params=critic_params,
            actor_opt_state=self.actor_opt.init(actor_params),
            critic_opt_state=self.critic_opt.init(critic_params),
            normalizer=networks.Normalizer.create(self.env.observation_size),
            updates=jnp.zeros((), jnp.int32),
        )

    def _init_device(self, rng: jax.Array) -> TrainerState:
        """rng (members, 2): this device's key of every member."""
        # Parameters must agree across devices: derive them from keys all devices share.
        shared = jax.lax.all_gather(rng, AXIS)[0]
        learner = jax.vmap(lambda k: self._init_learner(jax.random.fold_in(k, 0)))(shared)
        keys = jax.vmap(jax.random.split)(rng)
        rng, k_env = keys[:, 0], keys[:, 1]
        env_state = self.population.reset(self.env, k_env)
        example = replay.Transition(
            obs=env_state.obs[0, 0],
            action=jnp.zeros(self.env.action_size),
            reward=jnp.zeros(()),
            discount=jnp.zeros(()),
            next_obs=env_state.obs[0, 0],
            last=jnp.zeros(()),
        )
        buffer = replay.create(self.config.replay_capacity // self.num_devices, example)
        buffer = jax.tree.map(lambda x: jnp.broadcast_to(x, (self.members,) + x.shape), buffer)
        shape = (self.members, self.population.envs_per_member)
        stats = EpisodeStats(jnp.zeros(shape), jnp.zeros(shape))
        env_steps = jnp.zeros((self.members,), jnp.int32)
        return TrainerState(learner, env_state, buffer, stats, rng, env_steps)

    # ----------------------------------------------------------------- epoch
    def run_epoch(self, state: TrainerState) -> tuple[TrainerState, list[dict[str, float]]]:
        """One compiled epoch; ``state`` is donated. Returns the new state and each
        member's host metrics."""
        state, metrics = self._epoch(state)
        return state, per_member(metrics, self.members)

    def _epoch_device(self, state: TrainerState):
        self.trace_count += 1  # runs only while tracing: counts compilations
        cfg = self.config
        members = self.members

        def iteration(state: TrainerState, _):
            keys = jax.vmap(lambda k: jax.random.split(k, 3))(state.rng)
            rng, k_unroll, k_sgd = keys[:, 0], keys[:, 1], keys[:, 2]
            step_keys = jax.vmap(lambda k: jax.random.split(k, cfg.unroll_length))(k_unroll)
            (env_state, stats), (transitions, finished) = jax.lax.scan(
                functools.partial(self._env_step, state.learner),
                (state.env_state, state.stats),
                jnp.swapaxes(step_keys, 0, 1),
            )
            # (steps, members, envs, ...) -> each member's (steps * envs, ...), step-major.
            flat = jax.tree.map(
                lambda x: jnp.swapaxes(x, 0, 1).reshape((members, -1) + x.shape[3:]), transitions
            )
            buffer = jax.vmap(replay.insert)(state.buffer, flat)
            learner = state.learner
            if cfg.normalize_observations:
                normalizer = jax.vmap(lambda n, obs: n.update(obs, AXIS))(
                    learner.normalizer, flat.obs
                )
                learner = learner.replace(normalizer=normalizer)
            # Every member's buffer fills at the same pace: one unbatched predicate keeps
            # SGD out of the warm-up (a per-member one would run both branches under vmap).
            ready = buffer.size[0] * self.num_devices >= cfg.min_replay_size
            learner, sgd_metrics = jax.lax.cond(
                ready,
                lambda learner: jax.vmap(
                    functools.partial(self._train, num_envs=self.population.envs_per_member)
                )(learner, buffer, k_sgd),
                lambda learner: (learner, update.zero_sgd_metrics(self.model, self.members)),
                learner,
            )
            state = state.replace(
                learner=learner,
                env_state=env_state,
                buffer=buffer,
                stats=stats,
                rng=rng,
                env_steps=state.env_steps + cfg.unroll_length * self.population.envs_per_member,
            )
            return state, (finished, sgd_metrics)

        state, (finished, sgd_metrics) = jax.lax.scan(
            iteration, state, None, length=cfg.iterations_per_epoch
        )
        # finished leaves: (iterations, steps, members, envs); reduce all but members.
        total = lambda x: jax.lax.psum(x.sum(axis=(0, 1, 3)), AXIS)
        mean = lambda x: jax.lax.pmean(x.mean(axis=(0, 1, 3)), AXIS)
        episodes = total(finished["done"])
        # NaN, not 0, when no episode ended this epoch (epochs shorter than an episode).
        per_episode = lambda x: jnp.where(
            episodes > 0, total(x) / jnp.maximum(episodes, 1), jnp.nan
        )
        learner = state.learner
        metrics = {
            "train/episodes": episodes,
            "train/episode_return": per_episode(finished["return"]),
            "train/success": per_episode(finished["success"]),
            "train/reward_per_step": mean(finished["reward"]),
            "train/env_steps": jax.lax.psum(state.env_steps, AXIS),
            "train/updates": learner.updates,
            "train/replay_size": jax.lax.psum(state.buffer.size, AXIS),
            "train/params_finite": jax.vmap(_all_finite)(
                (learner.actor_params, learner.critic_params)
            ).astype(jnp.float32),
        }
        # Environment metrics (reward terms, ...) averaged over the epoch's steps; NaN
        # entries (e.g. pose distances of diverged simulations) are left out.
        nanmean = lambda x: jax.lax.pmean(jnp.nanmean(x, axis=(0, 1, 3)), AXIS)
        metrics |= {f"env/{k}": nanmean(v) for k, v in finished["env_metrics"].items()}
        # SGD metrics of the epoch's last iteration (the most recent networks).
        metrics |= {k: v[-1].mean(axis=-1) for k, v in sgd_metrics.items()}
        return state, metrics

    def _env_step(self, learner: LearnerState, carry, rng: jax.Array):
        """One step of every member's environments. rng (members, 2); leaves of the
        carry and of the outputs have leading axes (members, envs)."""
        env_state, stats = carry
        action = jax.vmap(self._explore)(learner, env_state.obs, rng)
        next_state = self.population.step(self.env, env_state, action)
        done, truncation = next_state.done, next_state.info["truncation"]
        transition = replay.Transition(
            obs=env_state.obs,
            action=action,
            reward=next_state.reward,
            discount=1.0 - done * (1.0 - truncation),
            next_obs=next_state.info["terminal_obs"],
            last=done,
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

    def _train(
        self, learner: LearnerState, buffer: replay.ReplayBuffer, rng: jax.Array, num_envs: int
    ):
        return update.train(self.model, learner, buffer, rng, num_envs)

    def sgd_step(self, learner: LearnerState, batch, noise_key=None, actor: bool = True):
        """:func:`update.sgd_step` with this trainer's model."""
        return update.sgd_step(self.model, learner, batch, noise_key, actor=actor)

    # ------------------------------------------------------------ evaluation
    def evaluate(self, state: TrainerState, rng: jax.Array) -> list[dict[str, float]]:
        """Deterministic-policy episodes on ``eval_env`` (one per env and device), per member.

        rng: one key per member (members, 2), or (2,) for a population of one. Each
        member's metrics: mean episode return, ``success_final`` (the required contacts
        touch at the last step: the headline), ``success`` (they all touched at some
        step) and ``final_<name>`` for the environment's ``pose/<name>`` metrics at the
        last step (e.g. the fingertips' distance to their goals).
        """
        return self.evaluate_learner(state.learner, rng)

    def evaluate_learner(self, learner: LearnerState, rng: jax.Array) -> list[dict[str, float]]:
        """:meth:`evaluate` of a replicated population learner (leaves (devices, members, ...))."""
        return self._evaluate(learner, rng)


def _all_finite(tree) -> jax.Array:
    leaves = jax.tree.leaves(tree)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))
