"""The smallest hand-task training config that still trains, shared by the tests that
train on the hand: configs that differ only in seeds, run folders and budgets share one
learner and its compiled programs in a process (``training.make_learner``), so these tests
compile once between them when they run in one process (one xdist group)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from mjx_hands import train_config
from mjx_hands.agents.ddpg import DDPGConfig
from mjx_hands.env import BatchedEnv
from mjx_hands.env_config import EnvConfig
from mjx_hands.point_reach import PointReach

HAND_DDPG = DDPGConfig(
    hidden_sizes=(32, 32),
    batch_size=64,
    replay_capacity=2_048,
    min_replay_size=256,
    unroll_length=4,
    updates_per_iteration=4,
    iterations_per_epoch=4,
)

HAND = train_config.TrainConfig(
    env=EnvConfig(task="handshake", mocap_source="synthetic", physics="native"),
    num_envs=16,
    eval_envs=16,
    eval_every=1,
    ddpg=HAND_DDPG,
)

HAND_GROUP = pytest.mark.xdist_group("tiny_hand_learner")
"""Mark of the tests that train :data:`HAND` in one process."""


def hand_config(**overrides) -> train_config.TrainConfig:
    return dataclasses.replace(HAND, **overrides)


def hand_cli_args() -> list[str]:
    """:data:`HAND` as train.py / experiments command-line flags."""
    env = HAND.env
    args = ["--task", env.task, "--mocap-source", env.mocap_source, "--physics", env.physics]
    args += ["--num-envs", str(HAND.num_envs), "--eval-envs", str(HAND.eval_envs)]
    args += ["--eval-every", str(HAND.eval_every)]
    args += ["--ddpg.hidden-sizes", *map(str, HAND_DDPG.hidden_sizes)]
    for name in ("batch_size", "replay_capacity", "min_replay_size", "unroll_length",
                 "updates_per_iteration", "iterations_per_epoch"):  # fmt: skip
        args += [f"--ddpg.{name.replace('_', '-')}", str(getattr(HAND_DDPG, name))]
    return args


# ------------------------------------------------ the pure-JAX point-reach task
POINT_DDPG = DDPGConfig(
    hidden_sizes=(32, 32),
    batch_size=64,
    replay_capacity=4_000,
    min_replay_size=160,
    unroll_length=5,
    updates_per_iteration=4,
    iterations_per_epoch=4,
)


def point_factory(config: train_config.TrainConfig, num_devices: int, env_class=PointReach):
    """The point-reach task's (train, eval, single) environments: ``training``'s
    ``env_factory`` for tests that need the loop, not the hand."""
    single = env_class()
    return (
        BatchedEnv(single, config.num_envs // num_devices),
        BatchedEnv(single, config.eval_envs // num_devices),
        single,
    )


def point_config(run_dir: Path, **overrides) -> train_config.TrainConfig:
    """A small point-reach training config writing to ``run_dir``."""
    base = train_config.TrainConfig(
        num_envs=16, eval_envs=16, epochs=4, eval_every=2, run_dir=str(run_dir), ddpg=POINT_DDPG
    )
    return dataclasses.replace(base, **overrides)
