"""The population runner every learner reuses: members x devices of batched environments.

A *population* is ``members`` independent runs (an experiment grid's seeds and reward
variants) trained in one compiled program; an ordinary run is a population of one.
Every leaf of a population state has the leading axes (devices, members). This module
holds what does not depend on the update rule: the member layout (:func:`member`,
:func:`stack_members`), per-member keys, resetting and stepping every member's
environments as one batch, and evaluating a deterministic policy. A learner (DDPG, or a
plug-in registered in ``mjx_hands.learners``) adds its state, its epoch and its
checkpoint layout.

Multi-host (``mjx_hands.cluster``): the pmap spans every process's devices when
``devices`` is None; each process feeds and holds the rows of its own devices
(:attr:`Population.local_rows`), and its keys are its rows of the keys one process with
all the devices would draw, so the layout of devices over processes changes nothing.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from mjx_hands import contract

AXIS = "devices"
"""The pmap axis name of every population program (collectives reduce over it)."""


def member(tree, index: int):
    """Member ``index`` of a population pytree (leaves (devices, members, ...)) ->
    leaves (devices, ...); also for abstract (``jax.eval_shape``) trees."""

    def take(x):
        if isinstance(x, jax.ShapeDtypeStruct):
            return jax.ShapeDtypeStruct(x.shape[:1] + x.shape[2:], x.dtype)
        return x[:, index]

    return jax.tree.map(take, tree)


def stack_members(trees: list):
    """Inverse of :func:`member`: trees with leaves (devices, ...) -> (devices, members, ...)."""
    return jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs], axis=1), *trees)


def first_device(x):
    """Device 0's slice of a replicated leaf; also for abstract (eval_shape) leaves."""
    if isinstance(x, jax.ShapeDtypeStruct):
        return jax.ShapeDtypeStruct(x.shape[1:], x.dtype)
    return x[0]


def per_member(metrics: dict[str, jax.Array], members: int) -> list[dict[str, float]]:
    """Device 0's (members,) metrics -> one dict of floats per member."""
    host = {k: np.asarray(v[0]) for k, v in jax.device_get(metrics).items()}
    return [{k: float(v[i]) for k, v in host.items()} for i in range(members)]


class Population:
    """Batched environments of ``members`` runs on ``devices``.

    Args:
      env: batched environment holding the *per-device, per-member* number of envs; its
        states carry ``info['success']`` (see ``mjx_hands.contract``).
      eval_env: batched environment for evaluation (per-device, per-member batch);
        default ``env``.
      episode_length: control steps per episode (the evaluation's length).
      members: runs in the population.
      member_info: entries of each member's environment ``info`` (leaves with a leading
        ``members`` axis), e.g. ``{'reward_weights': ...}``: each member's reward variant
        as data. None keeps what the environment's reset puts there.
      devices: the devices of the pmap; None: every device of every host.
    """

    def __init__(
        self,
        env,
        *,
        episode_length: int,
        eval_env=None,
        members: int = 1,
        member_info: dict[str, Any] | None = None,
        devices: list | None = None,
    ):
        if members < 1:
            raise ValueError(f"a population needs at least one member, got members={members}")
        for key, value in (member_info or {}).items():
            for leaf in jax.tree.leaves(value):
                if np.shape(leaf)[:1] != (members,):
                    raise ValueError(
                        f"member_info[{key!r}] has a leaf of shape {np.shape(leaf)}; expected a "
                        f"leading axis of the {members} members"
                    )
        self.env = env
        self.eval_env = eval_env or env
        self.envs_per_member = int(env.num_envs)
        """Environments of one member on one device (the batched env's ``num_envs``)."""
        self.episode_length = episode_length
        self.members = members
        self.member_info = member_info
        self.pmap_devices = devices
        self.devices = devices or jax.devices()
        """Every device of the pmap, on every process."""
        self.num_devices = len(self.devices)
        me = jax.process_index()
        self.local_rows = np.array([i for i, d in enumerate(self.devices) if d.process_index == me])
        """The rows of the device axis this process holds (all of them for one process)."""
        if np.any(np.diff(self.local_rows) != 1):  # pmap feeds a process's rows as one block
            raise ValueError(
                f"process {me}'s devices are not one block of the pmap's device list "
                f"({[d.id for d in self.devices]}); pass devices grouped by process"
            )
        self.distributed = len(self.local_rows) < self.num_devices
        # Host arrays with a leading device axis -> one shard per device, laid out exactly
        # as a pmap's outputs (same mesh axis name), so jit sees no new input sharding.
        self.to_devices = self.pmap(lambda tree: tree)

    def pmap(self, fn: Callable, **kwargs) -> Callable:
        """``fn`` pmapped over this population's devices with axis :data:`AXIS`."""
        return jax.pmap(fn, axis_name=AXIS, devices=self.pmap_devices, **kwargs)

    def device_keys(self, rng: jax.Array, what: str = "init") -> jax.Array:
        """One key per device and member, (devices, members, 2), from one key per member
        (members, 2) or (2,) for a population of one: distinct on every host, split per
        device as a run alone splits its key."""
        rng = jnp.asarray(rng)
        if rng.ndim == 1:
            rng = rng[None]
        if rng.shape[0] != self.members:
            raise ValueError(f"{what} needs one key per member ({self.members}), got {rng.shape}")
        # fold_in 0 keeps the keys single-process runs drew before processes shared rows.
        rng = jax.vmap(lambda k: jax.random.fold_in(k, 0))(rng)
        keys = jax.vmap(lambda k: jax.random.split(k, self.num_devices))(rng)
        return jnp.swapaxes(keys, 0, 1)[self.local_rows]

    def take_member(self, tree, index: int):
        """Member ``index`` of a population state on the devices (leaves (devices,
        members, ...) -> (devices, ...), this process's rows): a pmap, since arrays split
        over several processes cannot be sliced directly."""
        return self._take(tree, np.int32(index))

    @functools.cached_property
    def _take(self):
        return self.pmap(lambda tree, i: jax.tree.map(lambda x: x[i], tree), in_axes=(0, None))

    def global_rows(self, tree):
        """Host leaves holding this process's rows of the device axis (local devices, ...)
        -> arrays of every process's rows (devices, ...), as the collective checkpoint
        writes them; unchanged for one process."""
        if not self.distributed:
            return tree
        from jax.experimental import multihost_utils
        from jax.sharding import Mesh, PartitionSpec

        mesh = Mesh(np.array(self.devices), (AXIS,))
        return multihost_utils.host_local_array_to_global_array(tree, mesh, PartitionSpec(AXIS))

    def own_rows(self, tree):
        """Inverse of :func:`global_rows` for restored host arrays: (devices, ...) -> this
        process's rows (local devices, ...); unchanged for one process."""
        if not self.distributed:
            return tree
        return jax.tree.map(lambda x: np.asarray(x)[self.local_rows], tree)

    def reset(self, env, keys: jax.Array):
        """Each member's batch of fresh episodes: keys (members, 2) -> leaves (members, n, ...)."""
        state = jax.vmap(env.reset)(keys)
        if self.member_info is None:
            return state
        info = dict(state.info)
        for key, value in self.member_info.items():
            info[key] = jax.tree.map(
                lambda mine, like: jnp.broadcast_to(
                    jnp.asarray(mine, like.dtype)[:, None], like.shape
                ),
                value,
                state.info[key],
            )
        return state.replace(info=info)

    @staticmethod
    def step(env, state, action: jax.Array):
        """Step every member's environments as one batch (one physics call).

        state leaves (members, n, ...), action (members, n, act) -> next state, same layout.
        """
        members, n = action.shape[:2]
        flat = jax.tree.map(lambda x: x.reshape((members * n,) + x.shape[2:]), state)
        stepped = env.step(flat, action.reshape((members * n,) + action.shape[2:]))
        return jax.tree.map(lambda x: x.reshape((members, n) + x.shape[1:]), stepped)

    def evaluation(self, act: Callable[[Any, jax.Array], jax.Array]) -> Callable:
        """A compiled evaluation of the deterministic policy ``act(params, obs) -> action``
        (one member's params, (..., obs) -> (..., act)): ``evaluate(params, rng)`` with
        params leaves (devices, members, ...) and one key per member runs one episode per
        eval env and device and returns each member's ``contract.evaluation_metrics``."""
        run = self.pmap(functools.partial(self._evaluate_device, act))

        def evaluate(params, rng: jax.Array) -> list[dict[str, float]]:
            metrics = run(params, self.device_keys(rng, "evaluate"))
            return per_member(metrics, self.members)

        return evaluate

    def _evaluate_device(self, act, params, rng: jax.Array):
        env = self.eval_env

        def step(env_state, _):
            action = jax.vmap(act)(params, env_state.obs)
            next_state = self.step(env, env_state, action)
            return next_state, (next_state.reward, next_state.info["success"])

        start = self.reset(env, rng)
        final, (reward, success) = jax.lax.scan(step, start, None, length=self.episode_length)
        # reward, success: (steps, members, envs)
        metrics = contract.evaluation_metrics(reward, success, final.metrics)
        return jax.lax.pmean(metrics, AXIS)
