"""DDPG losses (Lillicrap et al. 2016, as configured by the paper's authors).

Critic: squared error to ``y = r + γ · discount · Q'(s', μ'(s'))`` with target
networks μ', Q'; ``discount`` is 0 only at a true termination, so truncated
episodes bootstrap. Actor: ``-Q(s, μ(s)) + λ · mean(μ(s)²)``.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from mjx_hands.agents.ddpg.replay import Transition

Apply = Callable[..., jax.Array]


def critic_target(
    reward: jax.Array,
    discount: jax.Array,
    next_q: jax.Array,
    gamma: float,
    clip: tuple[float, float] | None = None,
) -> jax.Array:
    """Bellman target ``r + γ · discount · Q'``, all (batch,); optionally clipped."""
    target = reward + gamma * discount * next_q
    if clip is not None:
        target = jnp.clip(target, *clip)
    return jax.lax.stop_gradient(target)


def critic_loss(
    critic_params,
    target_actor_params,
    target_critic_params,
    batch: Transition,
    *,
    actor_apply: Apply,
    critic_apply: Apply,
    gamma: float,
    target_clip: tuple[float, float] | None = None,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """Mean squared Bellman error on normalised ``batch`` (leaves (batch, ...))."""
    next_action = actor_apply(target_actor_params, batch.next_obs)
    next_q = critic_apply(target_critic_params, batch.next_obs, next_action)
    target = critic_target(batch.reward, batch.discount, next_q, gamma, target_clip)
    q = critic_apply(critic_params, batch.obs, batch.action)
    loss = jnp.mean(jnp.square(q - target))
    return loss, {"critic_loss": loss, "q": q.mean(), "target_q": target.mean()}


def actor_loss(
    actor_params,
    critic_params,
    obs: jax.Array,
    *,
    actor_apply: Apply,
    critic_apply: Apply,
    action_l2: float,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """``-mean Q(s, μ(s)) + action_l2 · mean(μ(s)²)``; obs (batch, obs) normalised."""
    action = actor_apply(actor_params, obs)
    q = critic_apply(critic_params, obs, action)
    penalty = action_l2 * jnp.mean(jnp.square(action))
    loss = -q.mean() + penalty
    return loss, {"actor_loss": loss, "action_penalty": penalty}


def polyak(target, online, coefficient: float):
    """``coefficient · target + (1 - coefficient) · online`` leaf by leaf."""
    return jax.tree.map(lambda t, o: coefficient * t + (1.0 - coefficient) * o, target, online)
