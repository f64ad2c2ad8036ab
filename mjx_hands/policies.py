"""Trained policies as a library: the policy a run folder holds, loaded by the learner
that trained it (``mjx_hands.learners``), ready to roll out. ``evaluate``, ``robustness``,
``naturalness`` and the rating study load policies through here."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax

from mjx_hands import checkpoint, learners, run_directory, train_config, training


@dataclasses.dataclass(frozen=True)
class LoadedPolicy:
    """A trained policy, ready to roll out, and what it was trained on."""

    act: Callable[[jax.Array], jax.Array]
    """Deterministic policy: observations (..., observation_size) -> actions
    (..., action_size); jittable, and the same object for as long as it is kept (so
    :func:`mjx_hands.rollouts.rollout` compiles it once)."""
    params: Any
    """The learner's own parameters (DDPG: its ``LearnerState``; Brax: its params)."""
    config: train_config.TrainConfig
    """The run's config, with the evaluation batch asked for."""
    single: Any
    """The run's single (unbatched) environment."""
    epoch: int
    """Epoch of the parameters (Brax's trainers: the last, the only one they keep)."""


def _checkpoint_dir(run_dir: Path, best: bool) -> Path:
    ckpt_dir = run_dir / (run_directory.BEST_DIR if best else "checkpoints")
    if not best and not ckpt_dir.is_dir():
        raise checkpoint.CheckpointError(
            f"{run_dir} holds no trained policy ({ckpt_dir.name}/ missing): give a folder "
            "written by train.py (or a member of an experiment grid)"
        )
    if best and not ckpt_dir.is_dir():
        raise checkpoint.CheckpointError(
            f"{run_dir} has no best policy ({ckpt_dir} missing): it was trained before "
            "train.py kept one, or it never evaluated; evaluate the latest checkpoint instead"
        )
    return ckpt_dir


def _checkpointed_learner(
    run_dir: Path, step: int | None, eval_envs: int | None, best: bool, env_factory=None
):
    """(algo, single env, config, checkpoint folder, step, metadata) of a DDPG run's
    checkpoint, its digest verified; nothing compiled, nothing restored yet."""
    if not run_dir.is_dir():
        raise FileNotFoundError(f"{run_dir}: no such run folder")
    ckpt_dir = _checkpoint_dir(run_dir, best)
    step = checkpoint.resolve_step(ckpt_dir, step)  # the newest intact one when None
    meta = checkpoint.read_metadata(ckpt_dir, step, verified=True)
    config = dataclasses.replace(train_config.config_from_json(meta["config"]), resume=False)
    if eval_envs is not None:
        config = dataclasses.replace(config, eval_envs=eval_envs)
    num_devices = int(meta.get("num_devices", 1))
    devices = jax.local_devices()
    if num_devices != len(devices):
        raise checkpoint.CheckpointError(
            f"{run_dir} was trained on {num_devices} devices; this process has {len(devices)}. "
            f"Run with {num_devices} devices (CPU: XLA_FLAGS=--xla_force_host_platform_device_count="
            f"{num_devices})"
        )
    algo, single = training.make_learner(config, devices=devices, env_factory=env_factory)
    return algo, single, config, ckpt_dir, step, meta


def restore_run(run_dir: Path, step: int | None = None, eval_envs: int | None = None):
    """(algo, checkpoint tree, config, single env) of a DDPG run's whole checkpoint:
    ``learner``, ``env_state`` (leaves with a leading device axis), ..., and ``epoch``;
    nothing compiled. ``eval_envs`` overrides the run's evaluation batch."""
    algo, single, config, ckpt_dir, step, meta = _checkpointed_learner(
        Path(run_dir), step, eval_envs, best=False
    )
    like = algo.state_shapes
    partial = meta.get("contents") == "policy"
    like_tree = (
        algo.policy_tree(like) if partial else algo.checkpoint_tree(like, config.save_replay)
    )
    tree, meta = checkpoint.restore(ckpt_dir, like_tree, step, partial=partial, verified=True)
    return algo, tree | {"epoch": int(meta["epoch"])}, config, single


def run_algo(run_dir: Path) -> str:
    """The learner that trained a run (its config.json's ``algo``; DDPG without one)."""
    path = Path(run_dir) / "config.json"
    return train_config.read_config_json(path).get("algo", "ddpg") if path.is_file() else "ddpg"


def load_policy(
    run_dir: Path,
    step: int | None = None,
    eval_envs: int = 128,
    best: bool = False,
    env_factory=None,
) -> LoadedPolicy:
    """The policy of a run's latest checkpoint (or of ``step``, or with ``best`` the
    best-evaluated one), loaded by the learner that trained it: DDPG from its Orbax
    checkpoints, Brax's SAC and PPO from the parameters they saved at the end.
    ``env_factory``: as :func:`mjx_hands.training.make_learner` (the run's task env by
    default)."""
    run_dir = Path(run_dir)
    algo_name = run_algo(run_dir)  # "ddpg" for a missing folder, which the next step names
    learner = learners.entry(algo_name)
    if not learner.in_training_loop:
        if step is not None or best:
            raise ValueError(
                f"{run_dir} was trained by {algo_name} in its own loop, which keeps only its "
                "final parameters: --step and --best choose among the project loop's "
                "checkpoints"
            )
        config = train_config.config_from_json(
            train_config.read_config_json(run_dir / "config.json")
        )
        config = dataclasses.replace(config, eval_envs=eval_envs, resume=False)
        _, _, single = (env_factory or training.make_envs)(config, 1)
        act, params = learner.load_policy(run_dir, config, single)
        return LoadedPolicy(act, params, config, single, config.epochs)
    algo, single, config, ckpt_dir, step, _ = _checkpointed_learner(
        run_dir, step, eval_envs, best, env_factory
    )
    act, learner, epoch = algo.load_policy(ckpt_dir, step, verified=True)
    return LoadedPolicy(act, learner, config, single, epoch)
