"""A small continuous-control task in pure JAX for testing learners quickly.

A point in the plane moves by its action (velocity, clipped to [-1, 1] times
``speed``) and is rewarded by minus its distance to a random goal. It keeps the
environment contract (:mod:`mjx_hands.contract`) like the hand environment, so
:class:`mjx_hands.env.BatchedEnv` batches it and the DDPG trainer runs it unchanged. With ``terminate_on_success`` an episode ends
(a true termination, no bootstrapping) as soon as the point is within
``success_radius`` of the goal.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State
from flax import struct


@struct.dataclass
class PointEpisode:
    rng: jax.Array  # (2,) key of the next episode
    step: jax.Array  # () control steps taken
    goal: jax.Array  # (2,)


class PointReach(Env):
    """Reach a random goal in [-1, 1]² from a random start within ``episode_length`` steps."""

    def __init__(
        self,
        episode_length: int = 20,
        speed: float = 0.2,
        success_radius: float = 0.1,
        terminate_on_success: bool = False,
    ):
        self.episode_length = episode_length
        self.terminate_on_success = terminate_on_success
        self.speed = speed
        self.success_radius = success_radius

    @property
    def observation_size(self) -> int:
        return 4

    @property
    def action_size(self) -> int:
        return 2

    @property
    def backend(self) -> str:
        return "jax"

    def reserve(self, worlds: int) -> None:
        """Pure JAX: nothing to size ahead."""

    def describe(self) -> str:
        return "point reach (pure JAX)"

    def pose(self, pipeline_state) -> dict[str, jax.Array]:
        return {}  # nothing to render

    def variant_for(self, weights):
        raise ValueError("PointReach has no reward variants; members differ in reward")

    def reset(self, rng: jax.Array) -> State:
        rng, k_pos, k_goal = jax.random.split(rng, 3)
        pos = jax.random.uniform(k_pos, (2,), minval=-1.0, maxval=1.0)
        goal = jax.random.uniform(k_goal, (2,), minval=-1.0, maxval=1.0)
        episode = PointEpisode(rng=rng, step=jnp.zeros((), jnp.int32), goal=goal)
        zero = jnp.zeros(())
        return State(
            pipeline_state=pos,
            obs=self._obs(pos, goal),
            reward=zero,
            done=zero,
            metrics={"distance": jnp.linalg.norm(goal - pos)},
            info={"episode": episode, "truncation": zero, "success": zero},
        )

    def step(self, state: State, action: jax.Array) -> State:
        episode = state.info["episode"]
        pos = state.pipeline_state + self.speed * jnp.clip(action, -1.0, 1.0)
        distance = jnp.linalg.norm(episode.goal - pos)
        episode = episode.replace(step=episode.step + 1)
        success = distance < self.success_radius
        truncated = episode.step >= self.episode_length
        terminated = success & self.terminate_on_success
        info = dict(state.info)
        info.update(
            episode=episode,
            truncation=(truncated & ~terminated).astype(jnp.float32),
            success=success.astype(jnp.float32),
        )
        done = (truncated | terminated).astype(jnp.float32)
        return state.replace(
            pipeline_state=pos,
            obs=self._obs(pos, episode.goal),
            reward=-distance,
            done=done,
            metrics=state.metrics | {"distance": distance},  # keep wrappers' entries
            info=info,
        )

    @staticmethod
    def _obs(pos: jax.Array, goal: jax.Array) -> jax.Array:
        return jnp.concatenate([pos, goal - pos])


def make_point_reach(num_envs: int, **kwargs):
    """A :class:`mjx_hands.env.BatchedEnv` of ``num_envs`` point-reach tasks."""
    from mjx_hands.env import BatchedEnv

    return BatchedEnv(PointReach(**kwargs), num_envs)
