"""DDPG losses (Lillicrap et al. 2016, as configured by the paper's authors).

Critic: squared error to ``y = r + γ · discount · Q'(s', μ'(s'))`` with target
networks μ', Q'; ``discount`` is 0 only at a true termination, so truncated
episodes bootstrap. Actor: ``-Q(s, μ(s)) + λ · mean(μ(s)²)``. Options of TD3
(Fujimoto et al. 2018): two critics whose minimum makes the target, and a target
action smoothed by clipped noise; and C51's categorical return distribution (Bellemare
et al. 2017) in place of the critic's scalar.

The network being trained runs through a *train apply* ``(variables, *inputs) ->
(output, new_variables)``, which lets batch normalisation use minibatch statistics
and hand back its updated running averages; by default it is the plain apply.
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


def smoothed_action(
    action: jax.Array, rng: jax.Array, noise: float, noise_clip: float
) -> jax.Array:
    """TD3's target policy smoothing: ``clip(a + clip(σ·ε, -c, c), -1, 1)``, ε ~ N(0, 1)."""
    eps = jnp.clip(noise * jax.random.normal(rng, action.shape), -noise_clip, noise_clip)
    return jnp.clip(action + eps, -1.0, 1.0)


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
    critic_train_apply: Apply | None = None,
    smoothing: tuple[jax.Array, float, float] | None = None,
):
    """Squared Bellman error on normalised ``batch`` (leaves (batch, ...)), summed over
    the critics of an ensemble.

    ``critic_apply`` returns (critics, batch) values: one critic is the paper's DDPG;
    with two the target takes their minimum (TD3's clipped double Q). ``smoothing``
    (key, σ, clip) perturbs the target action (:func:`smoothed_action`).
    Returns (loss, (metrics, critic variables after the forward pass)).
    """
    next_action = actor_apply(target_actor_params, batch.next_obs)
    if smoothing is not None:
        next_action = smoothed_action(next_action, *smoothing)
    next_q = critic_apply(target_critic_params, batch.next_obs, next_action).min(axis=0)
    target = critic_target(batch.reward, batch.discount, next_q, gamma, target_clip)
    train_apply = critic_train_apply or _plain(critic_apply)
    q, new_variables = train_apply(critic_params, batch.obs, batch.action)  # (critics, batch)
    loss = jnp.sum(jnp.mean(jnp.square(q - target), axis=-1))
    metrics = {"critic_loss": loss, "q": q[0].mean(), "target_q": target.mean()}
    return loss, (metrics, new_variables)


def categorical_projection(
    next_probs: jax.Array, reward: jax.Array, discount: jax.Array, support: jax.Array
) -> jax.Array:
    """C51's projection of ``r + discount · z`` onto the fixed support (Bellemare et al.).

    Args:
      next_probs: (batch, atoms) probabilities of the next return on ``support``.
      reward: (batch,); discount: (batch,) the factor of the next return (γ · d).
      support: (atoms,) evenly spaced returns from v_min to v_max.
    Returns:
      (batch, atoms): each shifted atom's mass split between its two neighbours on the
      support, in proportion to closeness (all of it to one where it lands exactly);
      returns beyond the support count at its ends.
    """
    v_min, v_max = support[0], support[-1]
    delta = (v_max - v_min) / (support.shape[0] - 1)
    shifted = jnp.clip(reward[:, None] + discount[:, None] * support[None], v_min, v_max)
    b = (shifted - v_min) / delta  # (batch, atoms) fractional index
    lower = jnp.floor(b)
    upper = jnp.ceil(b)
    # Mass to the lower neighbour: (upper - b), or all of it when b sits on an atom.
    to_lower = jnp.where(upper == lower, 1.0, upper - b)
    to_upper = 1.0 - to_lower
    atoms = jnp.arange(support.shape[0])
    onto = lambda index, share: jnp.einsum(
        "ba,bak->bk", next_probs * share, (index[..., None] == atoms).astype(next_probs.dtype)
    )
    return onto(lower, to_lower) + onto(upper, to_upper)


def distributional_critic_loss(
    critic_params,
    target_actor_params,
    target_critic_params,
    batch: Transition,
    *,
    actor_apply: Apply,
    critic_logits: Apply,
    support: jax.Array,
    gamma: float,
    critic_train_apply: Apply | None = None,
    smoothing: tuple[jax.Array, float, float] | None = None,
):
    """Cross-entropy of each critic's return distribution to the projected target
    (C51), summed over the critics; ``critic_logits`` returns (critics, batch, atoms).
    With two critics the target distribution is the one whose mean is smaller.
    Returns (loss, (metrics, critic variables after the forward pass)).
    """
    next_action = actor_apply(target_actor_params, batch.next_obs)
    if smoothing is not None:
        next_action = smoothed_action(next_action, *smoothing)
    next_probs = jax.nn.softmax(critic_logits(target_critic_params, batch.next_obs, next_action))
    next_mean = next_probs @ support  # (critics, batch)
    pick = jnp.argmin(next_mean, axis=0)  # (batch,) the critic with the smaller mean
    chosen = jnp.take_along_axis(next_probs, pick[None, :, None], axis=0)[0]
    target = jax.lax.stop_gradient(
        categorical_projection(chosen, batch.reward, gamma * batch.discount, support)
    )
    train_apply = critic_train_apply or _plain(critic_logits)
    logits, new_variables = train_apply(critic_params, batch.obs, batch.action)
    loss = -jnp.sum(jnp.mean(jnp.sum(target * jax.nn.log_softmax(logits), axis=-1), axis=-1))
    q = jax.nn.softmax(logits[0]) @ support
    metrics = {"critic_loss": loss, "q": q.mean(), "target_q": (target @ support).mean()}
    return loss, (metrics, new_variables)


def actor_loss(
    actor_params,
    critic_params,
    obs: jax.Array,
    *,
    actor_apply: Apply,
    critic_apply: Apply,
    action_l2: float,
    actor_train_apply: Apply | None = None,
):
    """``-mean Q(s, μ(s)) + action_l2 · mean(μ(s)²)``; obs (batch, obs) normalised.
    ``critic_apply`` returns (critics, batch); the first critic drives the actor (TD3).

    Returns (loss, (metrics, actor variables after the forward pass)).
    """
    action, new_variables = (actor_train_apply or _plain(actor_apply))(actor_params, obs)
    q = critic_apply(critic_params, obs, action)[0]
    penalty = action_l2 * jnp.mean(jnp.square(action))
    loss = -q.mean() + penalty
    return loss, ({"actor_loss": loss, "action_penalty": penalty}, new_variables)


def _plain(apply: Apply) -> Apply:
    """A train apply that changes no variables."""
    return lambda variables, *inputs: (apply(variables, *inputs), variables)


def polyak(target, online, coefficient: float):
    """``coefficient · target + (1 - coefficient) · online`` leaf by leaf."""
    return jax.tree.map(lambda t, o: coefficient * t + (1.0 - coefficient) * o, target, online)
