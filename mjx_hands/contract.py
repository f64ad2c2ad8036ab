"""The environment contract: what the batching wrapper, the learners, the run loop and
``evaluate`` rely on. The hand environment (:class:`mjx_hands.env.HandInteractionEnv`)
and the point-reach test task (:class:`mjx_hands.point_reach.PointReach`) both
implement it; nothing downstream asks which one it holds.

An environment is a Brax ``Env`` (``reset(rng) -> State``, ``step(state, action) ->
State``, unbatched) whose states carry the ``info`` entries of :data:`INFO_KEYS`, plus
the few methods of :class:`InteractionEnv`.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
from brax.envs.base import State

INFO_KEYS = {
    "episode": "per-episode pytree with an `rng` (2,) key: BatchedEnv restarts an ended "
    "episode from it (fresh randomisation); the rest is the environment's own",
    "truncation": "() float32, 1 where the episode ended by its time limit (a learner "
    "bootstraps there), 0 on a true termination",
    "success": "() float32, 1 where the task's success rule holds at this step",
}
"""``State.info`` entries every environment sets in ``reset`` and ``step`` (unbatched
shapes). The batching wrapper adds ``terminal_obs`` (the step's observation before an
automatic restart); a trainer may add entries of its own (e.g. ``reward_weights``),
which persist across restarts."""


@runtime_checkable
class InteractionEnv(Protocol):
    """An environment the project's learners, run loop and evaluation accept."""

    episode_length: int
    """Control steps per episode (episodes have a fixed length)."""

    @property
    def observation_size(self) -> int: ...

    @property
    def action_size(self) -> int: ...

    @property
    def backend(self) -> str:
        """Name of the physics ('mjx', 'native', 'jax')."""
        ...

    def reset(self, rng: jax.Array) -> State: ...

    def step(self, state: State, action: jax.Array) -> State: ...

    def reserve(self, worlds: int) -> None:
        """Room for ``worlds`` simulations stepped together (a learner's members x
        environments), called before the programs that step them are traced; a no-op
        where the physics sizes nothing ahead (MuJoCo Warp does)."""
        ...

    def describe(self) -> str:
        """One line for the run's output: the task's data and physics."""
        ...

    def pose(self, pipeline_state: Any) -> dict[str, jax.Array]:
        """The arrays that render a state (e.g. ``qpos``, ``mocap_pos``, ``mocap_quat``);
        empty when the environment has nothing to render."""
        ...

    def variant_for(self, weights: Any) -> Any:
        """The reward variant ``weights`` as arrays for ``info['reward_weights']``
        (population members with different rewards); ValueError where rewards have no
        variants."""
        ...


def missing_info(state: State) -> list[str]:
    """The :data:`INFO_KEYS` that ``state`` lacks (empty when it keeps the contract)."""
    missing = [key for key in INFO_KEYS if key not in state.info]
    if "episode" in state.info and not hasattr(state.info["episode"], "rng"):
        missing.append("episode.rng")
    return missing


POSE_PREFIX = "pose/"
"""``State.metrics`` entries under this prefix (e.g. ``pose/fingertip_goal_distance``,
metres) are reported at the last step of evaluation episodes as ``eval/final_<name>``."""


def evaluation_metrics(
    reward: jax.Array, success: jax.Array, final_metrics: dict[str, jax.Array]
) -> dict[str, jax.Array]:
    """The one result schema of an evaluation, for every learner and for ``evaluate``.

    Args:
      reward: (T, ..., n) rewards of n whole episodes of T steps.
      success: (T, ..., n) the success flag per step.
      final_metrics: ``State.metrics`` at the last step, entries (..., n).
    Returns (...) arrays: ``eval/episode_return`` (mean return), ``eval/success`` (share
    of episodes successful at some step), ``eval/success_final`` (at the last step: the
    headline) and ``eval/final_<name>`` per ``pose/<name>`` metric (NaN-skipping mean:
    diverged episodes have no pose).
    """
    metrics = {
        "eval/episode_return": jnp.sum(reward, axis=0).mean(axis=-1),
        "eval/success": jnp.max(success, axis=0).mean(axis=-1),
        "eval/success_final": jnp.asarray(success[-1]).mean(axis=-1),
    }
    metrics |= {
        f"eval/final_{k.removeprefix(POSE_PREFIX)}": jnp.nanmean(v, axis=-1)
        for k, v in final_metrics.items()
        if k.startswith(POSE_PREFIX)
    }
    return metrics
