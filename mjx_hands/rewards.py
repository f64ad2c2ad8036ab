"""The paper's multi-objective reward as small pure ``jnp`` terms.

``r = r_p + r_α + r_c + r_a + r_pI + r_αI`` (Christen et al., ICRA 2019, Sec. III):

* ``r_p  = -Σ_i ω^i_p ||p^i_g - p^i_r||``        goal positions of the actor points
* ``r_α  = -Σ_i ω^i_α |α^i_g - α^i_r|``          goal hand joint angles
* ``r_c  =  Σ_i ω^i_c 1[sensor i touches] + b_c`` required (ω_c > 0) and forbidden
  (ω_c < 0) contacts; ``b_c`` makes the authors' form ``-K_c Σ_required 1[apart]``
* ``r_a  = -Σ_i ω^i_a (a^i)^2``                  control effort
* ``r_pI = -Σ_i ω^i_pI ||p^i_gt - p^i_r||``     imitation of the demo's positions
* ``r_αI = -Σ_i ω^i_αI |α^i_gt - α^i_r|``       imitation of the demo's angles

(the project's ``ω_pI = K_pI ω_p``, ``ω_αI = K_αI ω_α``; the authors' are absolute,
see :class:`mjx_hands.reward_params.RewardWeights`).

Every function accepts any leading batch dimensions (``...``); weights come from
:class:`mjx_hands.reward_params.RewardParams`, where a variant's unused points or
sensors simply have zero weight, so nothing here branches on the variant.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_hands.reward_params import RewardParams

TERMS = (
    "position",
    "angle",
    "contact",
    "action",
    "imitation_position",
    "imitation_angle",
)
"""Keys of :func:`compute_rewards` besides ``"total"`` (logged as ``reward/<term>``)."""


def position_reward(goal_pos: jax.Array, point_pos: jax.Array, w: jax.Array) -> jax.Array:
    """``-Σ_i w_i ||goal_i - point_i||``.

    Args:
      goal_pos: (..., 6, 3) goal positions of the actor points (HAND_POINTS rows).
      point_pos: (..., 6, 3) the agent's palm centre and fingertips.
      w: (..., 6) position weights ω_p.
    Returns:
      (...,)
    """
    return -jnp.sum(w * jnp.linalg.norm(goal_pos - point_pos, axis=-1), axis=-1)


def angle_reward(goal_angles: jax.Array, angles: jax.Array, w: jax.Array) -> jax.Array:
    """``-Σ_i w_i |goal_i - angle_i|``; all (..., 20) in HAND_JOINTS order -> (...,)."""
    return -jnp.sum(w * jnp.abs(goal_angles - angles), axis=-1)


def contact_reward(contacts: jax.Array, w: jax.Array, bias: jax.Array = 0.0) -> jax.Array:
    """``Σ_i w_i c_i + bias``; contacts (..., 15) as 0/1 floats, w (..., 15), bias (...)
    -> (...,). A negative ``w_i`` charges a contact that must not happen; ``bias`` =
    ``-Σ_required w_i`` turns the bonus per contact into the authors' charge per required
    sensor out of contact (a reward <= 0)."""
    return jnp.sum(w * contacts, axis=-1) + bias


def action_reward(action: jax.Array, w: jax.Array) -> jax.Array:
    """``-Σ_i w_i a_i^2``; action and w (..., 24) -> (...,)."""
    return -jnp.sum(w * jnp.square(action), axis=-1)


def imitation_position_reward(
    ref_pos: jax.Array, point_pos: jax.Array, w: jax.Array, active: jax.Array
) -> jax.Array:
    """``-Σ_i ω^i_pI ||p^i_gt - p^i_r||`` while ``active``, else 0.

    Args:
      ref_pos: (..., 6, 3) the demonstration's actor points at this step, on the sim target.
      point_pos: (..., 6, 3) the agent's palm centre and fingertips.
      w: (..., 6) imitation position weights ω_pI (0 when imitation is off).
      active: (...) bool, the step is within the demo's imitation length.
    Returns:
      (...,)
    """
    return jnp.where(active, position_reward(ref_pos, point_pos, w), 0.0)


def imitation_angle_reward(
    ref_angles: jax.Array, angles: jax.Array, w: jax.Array, active: jax.Array
) -> jax.Array:
    """``-Σ_i ω^i_αI |α^i_gt - α^i_r|`` while ``active``, else 0; angles and w (..., 20)."""
    return jnp.where(active, angle_reward(ref_angles, angles, w), 0.0)


def _take(x: jax.Array, index: jax.Array, trail_ndim: int) -> jax.Array:
    """``x[..., index, <trail>]`` with a batched, clipped ``index``.

    Args:
      x: (B..., N, *trail) with ``len(trail) == trail_ndim``.
      index: (B'...) int, broadcastable against B...
    Returns:
      (broadcast(B, B')..., *trail)
    """
    axis = x.ndim - 1 - trail_ndim
    batch = jnp.broadcast_shapes(x.shape[:axis], jnp.shape(index))
    x = jnp.broadcast_to(x, batch + x.shape[axis:])
    idx = jnp.clip(jnp.broadcast_to(index, batch), 0, x.shape[len(batch)] - 1)
    idx = idx.reshape(batch + (1,) * (1 + trail_ndim))
    return jnp.take_along_axis(x, idx, axis=len(batch)).squeeze(len(batch))


def goal_positions(
    target_point_pos: jax.Array,
    target_point_rot: jax.Array,
    j_min: jax.Array,
    offsets: jax.Array,
) -> jax.Array:
    """Place demo offsets on the simulated target hand: ``p^i = p^{j} + R^{j} Δp^i``.

    Args:
      target_point_pos: (..., 6, 3) world positions of the target palm centre and
        fingertips (HAND_POINTS rows).
      target_point_rot: (..., 6, 3, 3) world rotation matrices (body-to-world, MuJoCo
        ``xmat`` reshaped) of the target palm body and the 5 distal bodies.
      j_min: (...) int, the target point the offsets are relative to.
      offsets: (..., 6, 3) offsets Δp in target body ``j_min``'s frame.
    Returns:
      (..., 6, 3) world positions.
    """
    pos = _take(target_point_pos, j_min, 1)  # (..., 3)
    rot = _take(target_point_rot, j_min, 2)  # (..., 3, 3)
    return pos[..., None, :] + jnp.einsum("...ab,...ib->...ia", rot, offsets)


def reference_at(params: RewardParams, step: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The demo's imitation reference at a control step.

    Args:
      params: one demo's params, optionally with leading batch dims on every leaf.
      step: (...) int, control step *of the demonstration* (an episode that starts at
        reference step k0 passes k0 + steps taken).
    Returns:
      offsets (..., 6, 3), angles (..., 20) and ``active`` (...) bool
      (``step < imitation_length``). Steps past the end read the last row.
    """
    step = jnp.asarray(step)
    offsets = _take(params.ref_offsets, step, 2)
    angles = _take(params.ref_angles, step, 1)
    active = (step >= 0) & (step < params.imitation_length)
    return offsets, angles, active


def success(contacts: jax.Array, groups: jax.Array) -> jax.Array:
    """One sensor of every success group in contact.

    Args:
      contacts: (..., 15) 0/1 readings.
      groups: (..., G, 15) bool, row g the sensors of group g; an empty row is satisfied.
    Returns:
      (...) bool.
    """
    groups = groups.astype(bool)
    touching = (contacts[..., None, :] > 0.5) & groups
    return jnp.all(jnp.any(touching, axis=-1) | ~jnp.any(groups, axis=-1), axis=-1)


def compute_rewards(
    params: RewardParams,
    step: jax.Array,
    *,
    hand_points: jax.Array,
    target_points: jax.Array,
    target_frames: jax.Array,
    hand_angles: jax.Array,
    contacts: jax.Array,
    action: jax.Array,
) -> dict[str, jax.Array]:
    """All reward terms and their sum for one step.

    Args:
      params: one demo's params (leaves optionally batched like the inputs).
      step: (...) int, control step of the demonstration (see :func:`reference_at`).
      hand_points: (..., 6, 3) agent palm centre + fingertips, world frame.
      target_points: (..., 6, 3) target palm centre + fingertips, world frame.
      target_frames: (..., 6, 3, 3) target palm body + distal bodies, body-to-world.
      hand_angles: (..., 20) agent hand joint angles, HAND_JOINTS order.
      contacts: (..., 15) 0/1 contact indicators, CONTACT_SENSORS order.
      action: (..., 24) the controls just applied.
    Returns:
      ``{term: (...)}`` for ``TERMS`` and ``"total"``.
    """
    goal = goal_positions(target_points, target_frames, params.j_min, params.goal_offsets)
    ref_offsets, ref_angles, active = reference_at(params, step)
    ref_pos = goal_positions(target_points, target_frames, params.j_min, ref_offsets)
    terms = {
        "position": position_reward(goal, hand_points, params.w_position),
        "angle": angle_reward(params.goal_angles, hand_angles, params.w_angle),
        "contact": contact_reward(contacts, params.w_contact, params.contact_bias),
        "action": action_reward(action, params.w_action),
        "imitation_position": imitation_position_reward(
            ref_pos, hand_points, params.w_imitation_position, active
        ),
        "imitation_angle": imitation_angle_reward(
            ref_angles, hand_angles, params.w_imitation_angle, active
        ),
    }
    terms["total"] = sum(terms[t] for t in TERMS)
    return terms
