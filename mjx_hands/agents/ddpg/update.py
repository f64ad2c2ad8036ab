"""DDPG's update rule as pure functions of a :class:`Model` (networks, optimisers and
constants, static under jit) and a run's :class:`LearnerState`: exploring actions, one
SGD step of critic and actor, and an iteration of updates with its Polyak step. The
trainer (``learner.DDPG``) adds the population, the epoch and the checkpoint layout."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct

from mjx_hands.agents.ddpg import losses, networks, replay
from mjx_hands.agents.population import AXIS


@struct.dataclass
class LearnerState:
    """Everything SGD changes for one run; replicated over devices."""

    actor_params: Any
    critic_params: Any
    target_actor_params: Any
    target_critic_params: Any
    actor_opt_state: Any
    critic_opt_state: Any
    normalizer: networks.Normalizer
    updates: jax.Array  # () int32


@dataclasses.dataclass(frozen=True)
class Model:
    """What the update rule computes with: the config, the networks and their optimisers,
    the discount, the distributional critic's support and the devices sharing a batch."""

    config: Any  # DDPGConfig
    actor: networks.Actor
    critic: networks.Critic
    actor_opt: optax.GradientTransformation
    critic_opt: optax.GradientTransformation
    gamma: float
    support: jax.Array  # (num_atoms,) returns of the distributional critic's atoms
    num_devices: int

    def normalize(self, learner: LearnerState, obs: jax.Array) -> jax.Array:
        if not self.config.normalize_observations:
            return obs
        return learner.normalizer.normalize(obs, self.config.observation_clip)

    def policy(self, learner: LearnerState, obs: jax.Array) -> jax.Array:
        """Deterministic action (..., act) of one run's learner for observations (..., obs)."""
        return self.actor.apply(learner.actor_params, self.normalize(learner, obs))

    def critic_outputs(self, critic_params, obs: jax.Array, action: jax.Array) -> jax.Array:
        """Every critic's output for normalised obs (..., obs), action (..., act): Q
        (critics, ...), or a distributional critic's logits (critics, ..., atoms)."""
        if self.config.twin_critics:
            return jax.vmap(lambda p: self.critic.apply(p, obs, action))(critic_params)
        return self.critic.apply(critic_params, obs, action)[None]

    def critic_values(self, critic_params, obs: jax.Array, action: jax.Array) -> jax.Array:
        """Q of every critic, (critics, ...): a distributional critic's mean."""
        out = self.critic_outputs(critic_params, obs, action)
        return jax.nn.softmax(out) @ self.support if self.config.num_atoms > 1 else out

    def train_apply(self, module, ensemble_axis: bool = False):
        """Forward pass in training mode: (variables, *inputs) -> (output, new variables);
        ``ensemble_axis`` adds the critics' leading axis (one critic with batch norm)."""
        if not self.config.batch_norm:
            return None

        def apply(variables, *inputs):
            out, updates = module.apply(variables, *inputs, train=True, mutable=["batch_stats"])
            return (out[None] if ensemble_axis else out), variables | updates

        return apply


def explore(model: Model, learner: LearnerState, obs: jax.Array, rng: jax.Array) -> jax.Array:
    """The exploring action: the policy's plus Gaussian noise, clipped, or with
    probability ``random_action_prob`` a uniformly random one (the paper's DDPG)."""
    k_noise, k_random, k_pick = jax.random.split(rng, 3)
    action = model.policy(learner, obs)
    action = jnp.clip(
        action + model.config.noise_scale * jax.random.normal(k_noise, action.shape), -1, 1
    )
    random = jax.random.uniform(k_random, action.shape, minval=-1.0, maxval=1.0)
    pick = jax.random.uniform(k_pick, action.shape[:-1] + (1,)) < model.config.random_action_prob
    return jnp.where(pick, random, action)


def zero_sgd_metrics(model: Model, members: int) -> dict[str, jax.Array]:
    """The SGD metrics of an iteration without updates (the replay warm-up)."""
    keys = ("critic_loss", "q", "target_q", "actor_loss", "action_penalty")
    cfg = model.config
    zero = jnp.zeros((members, cfg.updates_per_iteration // cfg.actor_update_interval))
    return {f"sgd/{k}": zero for k in keys}


def train(
    model: Model, learner: LearnerState, buffer: replay.ReplayBuffer, rng: jax.Array, num_envs: int
):
    """``updates_per_iteration`` SGD updates, then a Polyak step of the targets (one
    run); ``num_envs``: this device's environments of the run (the buffer's stride)."""
    cfg = model.config
    per_device = cfg.batch_size // model.num_devices
    smooth = cfg.target_policy_noise > 0

    def update(learner: LearnerState, key, actor: bool = True):
        # Keys split only for the options that need them: the paper's DDPG draws
        # exactly the minibatches it always drew.
        k_batch, k_noise = jax.random.split(key) if smooth else (key, None)
        if cfg.n_step > 1:
            batch = replay.sample_n_step(
                buffer, k_batch, per_device, cfg.n_step, model.gamma, num_envs
            )
        else:
            batch = replay.sample(buffer, k_batch, per_device)
        return sgd_step(model, learner, batch, k_noise, actor=actor)

    keys = jax.random.split(rng, cfg.updates_per_iteration)
    interval = cfg.actor_update_interval
    if interval == 1:
        learner, metrics = jax.lax.scan(update, learner, keys)
    else:
        # Blocks of (interval - 1) critic updates, then one of critic and actor.
        def block(learner: LearnerState, block_keys):
            learner, _ = jax.lax.scan(
                functools.partial(update, actor=False), learner, block_keys[:-1]
            )
            return update(learner, block_keys[-1])

        blocks = keys.reshape((-1, interval) + keys.shape[1:])
        learner, metrics = jax.lax.scan(block, learner, blocks)
    learner = learner.replace(
        target_actor_params=losses.polyak(
            learner.target_actor_params, learner.actor_params, model.config.polyak
        ),
        target_critic_params=losses.polyak(
            learner.target_critic_params, learner.critic_params, model.config.polyak
        ),
    )
    return learner, metrics


def sgd_step(
    model: Model,
    learner: LearnerState,
    batch: replay.Transition,
    noise_key: jax.Array | None = None,
    actor: bool = True,
):
    """One critic update and (with ``actor``) one actor update on ``batch`` (leaves
    (per-device batch, ...)); both gradients are taken at the current parameters.
    ``noise_key`` draws the target policy smoothing noise (when that is on)."""
    cfg = model.config
    batch = batch.replace(
        obs=model.normalize(learner, batch.obs), next_obs=model.normalize(learner, batch.next_obs)
    )
    smoothing = None
    if cfg.target_policy_noise > 0:
        smoothing = (noise_key, cfg.target_policy_noise, cfg.target_noise_clip)
    if cfg.num_atoms > 1:
        critic_loss = functools.partial(
            losses.distributional_critic_loss,
            critic_logits=model.critic_outputs,
            support=model.support,
        )
    else:
        critic_loss = functools.partial(
            losses.critic_loss, critic_apply=model.critic_values, target_clip=cfg.target_clip
        )
    critic_grad, (critic_metrics, critic_vars) = jax.grad(critic_loss, has_aux=True)(
        learner.critic_params,
        learner.target_actor_params,
        learner.target_critic_params,
        batch,
        actor_apply=model.actor.apply,
        gamma=model.gamma,
        critic_train_apply=model.train_apply(model.critic, ensemble_axis=True),
        smoothing=smoothing,
    )
    critic_grad = jax.lax.pmean(critic_grad, AXIS)
    critic_updates, critic_opt_state = model.critic_opt.update(
        critic_grad, learner.critic_opt_state
    )
    critic_params = optax.apply_updates(learner.critic_params, critic_updates)
    metrics = critic_metrics
    if actor:
        actor_grad, (actor_metrics, actor_vars) = jax.grad(losses.actor_loss, has_aux=True)(
            learner.actor_params,
            learner.critic_params,
            batch.obs,
            actor_apply=model.actor.apply,
            critic_apply=model.critic_values,
            action_l2=cfg.action_l2,
            actor_train_apply=model.train_apply(model.actor),
        )
        actor_grad = jax.lax.pmean(actor_grad, AXIS)
        actor_updates, actor_opt_state = model.actor_opt.update(actor_grad, learner.actor_opt_state)
        actor_params = optax.apply_updates(learner.actor_params, actor_updates)
        metrics = metrics | actor_metrics
        if cfg.batch_norm:
            # Running averages of the minibatch statistics, the same on every device.
            stats = jax.lax.pmean((critic_vars["batch_stats"], actor_vars["batch_stats"]), AXIS)
            critic_params = critic_params | {"batch_stats": stats[0]}
            actor_params = actor_params | {"batch_stats": stats[1]}
        learner = learner.replace(actor_params=actor_params, actor_opt_state=actor_opt_state)
    elif cfg.batch_norm:
        stats = jax.lax.pmean(critic_vars["batch_stats"], AXIS)
        critic_params = critic_params | {"batch_stats": stats}
    learner = learner.replace(
        critic_params=critic_params,
        critic_opt_state=critic_opt_state,
        updates=learner.updates + 1,
    )
    metrics = jax.lax.pmean(metrics, AXIS)
    return learner, {f"sgd/{k}": v for k, v in metrics.items()}
