"""Roll a policy out over whole episodes and summarise them in the result schema.

Every evaluation of the project goes through :func:`rollout` and :func:`summarize`:
``evaluate``, Brax's trainers' final evaluation, the robustness sweeps, the naturalness
metrics and the rating study's videos. DDPG's in-training evaluation is compiled into
its epoch but reports the same :func:`mjx_hands.contract.evaluation_metrics`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from mjx_hands import contact_profile, contract, shadow_hand


def as_policy(policy: Callable[[jax.Array], jax.Array]) -> jax.tree_util.Partial:
    """``policy`` as a pytree whose bound arguments are data, not constants.

    A ``jax.tree_util.Partial(apply, params)`` (what the learners' ``load_policy``
    return) passes ``params`` into the compiled step as arguments: every policy of one
    program (the seeds of a grid, a study's runs) shares one compile. Any other callable
    is wrapped as it is and compiles once per object.
    """
    return policy if isinstance(policy, jax.tree_util.Partial) else jax.tree_util.Partial(policy)


@functools.lru_cache(maxsize=8)
def compiled_rollout(single, reset=None, extra=None):
    """The jitted (reset, step(state, policy), per-state record) of :func:`rollout`, kept
    per (env, reset, extra): a sweep that rolls out chunk after chunk, policy after
    policy, compiles once per policy function (its parameters are arguments)."""
    reset = jax.jit(reset or jax.vmap(single.reset))
    step = jax.jit(lambda s, policy: jax.vmap(single.step)(s, policy(s.obs)))
    per_state = jax.jit(
        jax.vmap(lambda s: single.pose(s.pipeline_state) | (extra(s) if extra else {}))
    )
    return reset, step, per_state


EVAL_SEED = 12345
"""Seed of ``evaluate``'s episodes unless told otherwise (and of an export's)."""


def episode_keys(seed: int, num_episodes: int) -> jax.Array:
    """(num_episodes, 2) reset keys of the evaluation episodes of ``seed``."""
    return jax.random.split(jax.random.PRNGKey(seed), num_episodes)


def rollout(
    single,
    policy,
    keys: jax.Array,
    reset: Callable[..., Any] | None = None,
    reset_args: tuple = (),
    extra: Callable[[Any], dict[str, jax.Array]] | None = None,
) -> dict[str, np.ndarray]:
    """Run one whole episode of ``single`` per key (no restarts) under ``policy``
    (observations (n, observation_size) -> actions; see :func:`as_policy`).

    Args:
      keys: (n, 2) one reset key per episode (:func:`episode_keys`).
      reset: (keys (n, 2), *reset_args) -> batched initial ``State``; default
        ``single.reset`` vmapped. Robustness sweeps pass ``single.reset_with`` vmapped and
        the target's tilts and speeds as ``reset_args`` (data: one compile for all).
      extra: single ``State`` -> {name: array}, recorded at every step as ``name``
        (T+1, n, ...) beside the rest (e.g. hand points for the naturalness metrics).

    Returns reward (T, n) and success (T, n), T the episode length; for the hand
    environments also contacts (T, n, 15), the sensor readings, qpos (T+1, n, nq),
    mocap_pos (T+1, n, nmocap, 3), mocap_quat (T+1, n, nmocap, 4) for rendering, and
    the last step's ``pose/<name>`` metrics (n,).
    """
    reset, step, per_state = compiled_rollout(single, reset, extra)
    policy = as_policy(policy)
    state = reset(keys, *reset_args)
    sensors = [f"contact/{n}" for n in shadow_hand.CONTACT_SENSORS]
    has_contacts = all(k in state.metrics for k in sensors)
    record = {key: [] for key in ("reward", "success", "contacts")}

    def keep(state):  # host copies only: whole mjx.Data per step would pile up on device
        for key, value in per_state(state).items():
            record.setdefault(key, []).append(np.asarray(value))

    keep(state)
    for _ in range(single.episode_length):
        state = step(state, policy)
        keep(state)
        record["reward"].append(np.asarray(state.reward))
        record["success"].append(np.asarray(state.info["success"]))
        if has_contacts:
            record["contacts"].append(np.stack([np.asarray(state.metrics[k]) for k in sensors], -1))
    out = {key: np.stack(values) for key, values in record.items() if values}
    # The last step's pose metrics (n,): the final pose errors of the result schema.
    out |= {
        k: np.asarray(v) for k, v in state.metrics.items() if k.startswith(contract.POSE_PREFIX)
    }
    return out


def summarize(single, trajectory: dict[str, np.ndarray]) -> tuple[dict, dict | None]:
    """(metrics, contact profile or None) of a :func:`rollout`: the training's evaluation
    metrics (:func:`contract.evaluation_metrics`: success at some step and at the last
    step, mean return, final pose errors) and, for the hand environments,
    :func:`contact_profile.summarize` of the sensor readings."""
    final = {k: v for k, v in trajectory.items() if k.startswith(contract.POSE_PREFIX)}
    arrays = contract.evaluation_metrics(
        trajectory["reward"], (trajectory["success"] > 0.5).astype(np.float32), final
    )
    metrics = {k: float(v) for k, v in arrays.items()}
    if "contacts" not in trajectory:
        return metrics, None
    groups = np.asarray(single.params.success_groups[0])
    return metrics, contact_profile.summarize(trajectory["contacts"], groups)
