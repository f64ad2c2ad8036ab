"""Actor and critic of the paper: three fully connected layers of 256 ReLU units.

Observations reach both networks through a running normaliser (mean/std of every
observation seen in training, clipped), as in the authors' DDPG configuration.
"""

from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import struct


class MLP(nn.Module):
    """ReLU hidden layers, linear output; optional batch or layer norm after each hidden layer.

    With ``batch_norm`` the variables hold a ``batch_stats`` collection: ``train=True``
    normalises by the minibatch (call with ``mutable=['batch_stats']`` to update the
    running averages), ``train=False`` by the running averages.
    """

    hidden_sizes: Sequence[int]
    out_size: int
    layer_norm: bool = False
    batch_norm: bool = False
    batch_axis_name: str | None = None
    """Mapped axis whose devices share minibatch statistics when training (pmap)."""

    @nn.compact
    def __call__(self, x: jax.Array, train: bool = False) -> jax.Array:
        for size in self.hidden_sizes:
            x = nn.Dense(size)(x)
            if self.batch_norm:
                axis = self.batch_axis_name if train else None
                x = nn.BatchNorm(use_running_average=not train, momentum=0.99, axis_name=axis)(x)
            if self.layer_norm:
                x = nn.LayerNorm()(x)
            x = nn.relu(x)
        # Small last layer: initial actions near 0 and Q near 0 keep early updates tame.
        return nn.Dense(self.out_size, kernel_init=nn.initializers.uniform(3e-3))(x)


class Actor(nn.Module):
    """Deterministic policy: normalised observation (..., obs) -> action (..., act) in [-1, 1]."""

    action_size: int
    hidden_sizes: Sequence[int] = (256, 256, 256)
    layer_norm: bool = False
    batch_norm: bool = False
    batch_axis_name: str | None = None

    @nn.compact
    def __call__(self, obs: jax.Array, train: bool = False) -> jax.Array:
        mlp = MLP(
            self.hidden_sizes,
            self.action_size,
            self.layer_norm,
            self.batch_norm,
            self.batch_axis_name,
        )
        return jnp.tanh(mlp(obs, train))


class Critic(nn.Module):
    """Q(s, a): normalised observation (..., obs), action (..., act) -> (...,); with
    ``num_atoms`` > 1 the logits (..., num_atoms) of a categorical return distribution."""

    hidden_sizes: Sequence[int] = (256, 256, 256)
    layer_norm: bool = False
    batch_norm: bool = False
    batch_axis_name: str | None = None
    num_atoms: int = 1

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array, train: bool = False) -> jax.Array:
        x = jnp.concatenate([obs, action], axis=-1)
        mlp = MLP(
            self.hidden_sizes, self.num_atoms, self.layer_norm, self.batch_norm,
            self.batch_axis_name,
        )
        out = mlp(x, train)
        return out[..., 0] if self.num_atoms == 1 else out


@struct.dataclass
class Normalizer:
    """Running mean and variance of observations (Chan et al.'s parallel update).

    Shapes: count (), mean (obs,), m2 (obs,) (sum of squared deviations).
    """

    count: jax.Array
    mean: jax.Array
    m2: jax.Array

    @classmethod
    def create(cls, size: int) -> Normalizer:
        return cls(jnp.zeros((), jnp.float32), jnp.zeros(size), jnp.zeros(size))

    def update(self, batch: jax.Array, axis_name: str | None = None) -> Normalizer:
        """Fold in ``batch`` (..., obs); with ``axis_name`` the batches of all devices."""
        batch = batch.reshape(-1, batch.shape[-1])
        n = jnp.asarray(batch.shape[0], jnp.float32)
        mean = batch.mean(axis=0)
        m2 = jnp.square(batch - mean).sum(axis=0)
        if axis_name is not None:
            # Combine per-device moments exactly: total count, mean, and m2 about it.
            total = jax.lax.psum(n, axis_name)
            global_mean = jax.lax.psum(n * mean, axis_name) / total
            m2 = jax.lax.psum(m2 + n * jnp.square(mean - global_mean), axis_name)
            n, mean = total, global_mean
        count = self.count + n
        delta = mean - self.mean
        new_mean = self.mean + delta * n / count
        new_m2 = self.m2 + m2 + jnp.square(delta) * self.count * n / count
        return Normalizer(count, new_mean, new_m2)

    @property
    def std(self) -> jax.Array:
        var = jnp.where(self.count > 0, self.m2 / jnp.maximum(self.count, 1.0), 1.0)
        return jnp.sqrt(jnp.maximum(var, 1e-4))

    def normalize(self, obs: jax.Array, clip: float) -> jax.Array:
        """(..., obs) -> (..., obs) standardised and clipped to [-clip, clip]."""
        return jnp.clip((obs - self.mean) / self.std, -clip, clip)
