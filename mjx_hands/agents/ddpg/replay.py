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
    otherwise (a truncated episode still bootstraps), next_obs (obs,).
    """

    obs: jax.Array
    action: jax.Array
    reward: jax.Array
    discount: jax.Array
    next_obs: jax.Array


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
