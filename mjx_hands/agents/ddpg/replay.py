"""A device-resident ring buffer of transitions with uniform sampling.

Insertion writes a batch at ``(position + arange(n)) % capacity`` with one scatter,
so a full buffer is overwritten oldest-first in O(batch) work; under buffer
donation XLA updates the arrays in place. (A queue that shifts its contents to make
room costs O(capacity) per insertion; ``benchmarks/replay.py`` measures both.)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class Transition:
    """One step (leading batch dimensions allowed).

    obs (obs,), action (act,), reward (), discount () = 0 at a true termination and 1
    otherwise (a truncated episode still bootstraps), next_obs (obs,), last () = 1
    when the episode ended with this step (terminated or truncated; the next stored
    step of the environment belongs to a new episode).
    """

    obs: jax.Array
    action: jax.Array
    reward: jax.Array
    discount: jax.Array
    next_obs: jax.Array
    last: jax.Array


@struct.dataclass
class ReplayBuffer:
    """``data`` leaves have shape (capacity, ...); position and size are scalars."""

    data: Transition
    position: jax.Array  # () int32: next slot to write
    size: jax.Array  # () int32: filled slots, <= capacity

    @property
    def capacity(self) -> int:
        return self.data.reward.shape[0]


def create(capacity: int, example: Transition) -> ReplayBuffer:
    """An empty buffer for transitions shaped like ``example`` (one, unbatched)."""
    if capacity <= 0:
        raise ValueError(f"replay capacity must be positive, got {capacity}")
    data = jax.tree.map(
        lambda x: jnp.zeros((capacity,) + jnp.shape(x), jnp.asarray(x).dtype), example
    )
    # Two distinct arrays: one buffer passed twice cannot be donated.
    return ReplayBuffer(data=data, position=jnp.zeros((), jnp.int32), size=jnp.zeros((), jnp.int32))


def insert(buffer: ReplayBuffer, batch: Transition) -> ReplayBuffer:
    """Write ``batch`` (leaves (n, ...), n <= capacity), overwriting the oldest entries."""
    n = batch.reward.shape[0]
    capacity = buffer.capacity
    if n > capacity:
        raise ValueError(f"cannot insert {n} transitions into a buffer of capacity {capacity}")
    index = (buffer.position + jnp.arange(n)) % capacity
    data = jax.tree.map(
        lambda store, x: store.at[index].set(x.astype(store.dtype), unique_indices=True),
        buffer.data,
        batch,
    )
    return ReplayBuffer(
        data=data,
        position=(buffer.position + n) % capacity,
        size=jnp.minimum(buffer.size + n, capacity),
    )


def sample(buffer: ReplayBuffer, rng: jax.Array, batch_size: int) -> Transition:
    """``batch_size`` transitions drawn uniformly (with replacement) from the filled slots."""
    index = jax.random.randint(rng, (batch_size,), 0, jnp.maximum(buffer.size, 1))
    return jax.tree.map(lambda store: store[index], buffer.data)


def sample_n_step(
    buffer: ReplayBuffer,
    rng: jax.Array,
    batch_size: int,
    n: int,
    gamma: float,
    num_envs: int,
) -> Transition:
    """``batch_size`` n-step transitions drawn uniformly from the filled slots.

    The buffer must hold each insertion as ``steps x num_envs`` step-major rows (as the
    trainer inserts them), so the step after row ``i`` of an environment is row
    ``i + num_envs``. From a drawn step the return sums ``γ^k r_k`` over the next ``n``
    steps of its environment, stopping after the step that ends the episode (``last``;
    later rows belong to the next episode, after an auto-reset). The result is a
    ``Transition`` whose ``reward`` is that sum and whose ``discount`` is ``γ^(m-1) d``,
    with ``m`` the steps summed and ``d`` the discount of the last of them (0 at a
    termination, 1 at a truncation or mid-episode), so that the usual target
    ``r + γ · discount · Q'(next_obs)`` is the n-step one; ``next_obs`` is that last
    step's. Steps whose ``n - 1`` successors are not written yet are never drawn.
    """
    capacity = buffer.capacity
    usable = jnp.maximum(buffer.size - (n - 1) * num_envs, 1)
    offset = jax.random.randint(rng, (batch_size,), 0, usable)
    start = (buffer.position - buffer.size + offset) % capacity  # oldest-first ring index
    rows = (start[:, None] + num_envs * jnp.arange(n)) % capacity  # (batch, n)
    steps = jax.tree.map(lambda store: store[rows], buffer.data)  # leaves (batch, n, ...)
    ended_before = jnp.cumsum(steps.last, axis=1) - steps.last  # episode ends before step k
    alive = (ended_before == 0).astype(jnp.float32)  # (batch, n): step k still counts
    powers = gamma ** jnp.arange(n, dtype=jnp.float32)
    reward = jnp.sum(alive * powers * steps.reward, axis=1)
    last_k = jnp.sum(alive, axis=1).astype(jnp.int32) - 1  # index of the last counted step
    pick = lambda x: jnp.take_along_axis(
        x, last_k.reshape((-1,) + (1,) * (x.ndim - 1)), axis=1
    ).squeeze(1)
    first = jax.tree.map(lambda x: x[:, 0], steps)
    return Transition(
        obs=first.obs,
        action=first.action,
        reward=reward,
        discount=pick(steps.discount) * gamma ** last_k.astype(jnp.float32),
        next_obs=pick(steps.next_obs),
        last=pick(steps.last),
    )
