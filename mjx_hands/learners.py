"""The learner registry: a learner is one module plus one :class:`LearnerEntry`.

Two kinds of learner:

* **population learners** run in the project's training loop (``training.run``): runs,
  resume, grids of seeds and reward variants as one program, checkpoints, evaluation and
  ``evaluate``. They implement :class:`Learner` and register a ``build`` factory, which
  receives a :class:`LearnerSetup` (the environments and the population) and usually
  reuses ``mjx_hands.agents.population.Population`` for everything but its update rule.
  The project's DDPG is registered under three names (``ddpg``, ``ddpg-ln``, ``td3``)
  with different options.
* **standalone learners** bring their own loop (Brax's SAC and PPO): ``run(config)``
  trains and writes the run folder, ``load_policy(run_dir, config, single)`` reads it.

Every command reads this registry (``--algo``'s choices, resume's checks, grids,
``evaluate``); adding a learner needs its module and a :func:`register` call.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import jax

EPOCH_METRICS = (
    "train/env_steps",
    "train/episodes",
    "train/episode_return",
    "train/success",
    "train/params_finite",
)
"""What every member's :meth:`Learner.run_epoch` metrics hold (the loop logs, shows and
checks them): environment steps so far; episodes ended this epoch and their mean return
and success (the return may be NaN when none ended); 1.0 when every parameter is finite
(else the loop stops the run as diverged). Anything else is logged as it is."""


def check_epoch_metrics(name: str, metrics: dict[str, float]) -> None:
    """A clear error naming what a learner's epoch metrics lack."""
    missing = [k for k in EPOCH_METRICS if k not in metrics]
    if missing:
        raise ValueError(
            f"learner {name!r}: its epoch metrics lack {missing} (see learners.EPOCH_METRICS)"
        )


class Learner(Protocol):
    """What the training loop, resume, grids and ``evaluate`` call on a population
    learner. States are pytrees whose leaves have the leading axes (devices, members)."""

    members: int
    """Runs in the population."""
    num_devices: int
    """Devices the program spans (checkpoints are written with this leading axis)."""
    trace_count: int
    """How often the epoch was traced: 1 after any number of epochs (the loop reports it)."""

    @property
    def state_shapes(self) -> Any:
        """The state's structure (``jax.eval_shape`` of :meth:`init`): what a checkpoint is
        restored into."""

    def init(self, rng: jax.Array) -> Any:
        """A fresh state from one key per member, (members, 2)."""

    def run_epoch(self, state: Any) -> tuple[Any, list[dict[str, float]]]:
        """One epoch; returns the new state and each member's metrics (at least
        :data:`EPOCH_METRICS`)."""

    def evaluate(self, state: Any, rng: jax.Array) -> list[dict[str, float]]:
        """Each member's ``contract.evaluation_metrics`` of its deterministic policy."""

    def checkpoint_tree(self, state: Any, save_replay: bool, index: int = 0) -> dict[str, Any]:
        """What a run's checkpoint holds for member ``index`` (also of abstract states)."""

    def policy_tree(self, state: Any, index: int = 0) -> dict[str, Any]:
        """What its best-policy checkpoint holds (the policy alone)."""

    def from_checkpoint_trees(self, trees: list[dict[str, Any]], fresh: Any) -> Any:
        """The population state of one checkpoint tree per member (``fresh`` fills gaps)."""

    def load_policy(self, ckpt_dir, step: int, verified: bool = False) -> tuple[Any, Any, int]:
        """``(act, params, epoch)`` of the policy a checkpoint folder holds at ``step``:
        ``act(obs) -> action`` for one environment's observation."""


@dataclasses.dataclass(frozen=True)
class LearnerSetup:
    """What the training loop hands a population learner's factory."""

    config: Any  # train_config.TrainConfig of the first member
    train_env: Any  # batched: per-device, per-member envs
    eval_env: Any
    single: Any  # one unbatched environment (sizes, episode length)
    devices: list | None
    members: int
    member_info: dict[str, Any] | None


@dataclasses.dataclass(frozen=True)
class RunServices:
    """What the project's loop lends a standalone learner, so that the learner's module
    needs nothing above it (``training.run_services`` makes them)."""

    run_dir: Path
    config_json: dict[str, Any]
    """The run's config.json content."""
    make_envs: Callable[[Any, int], tuple[Any, Any, Any]]
    """``(config, num_devices) -> (train_env, eval_env, single_env)``."""
    metrics_log: Callable[[Path], Any]
    """``run_dir -> `` a metrics.csv / TensorBoard log (``append(row)``, ``rows``, ``close()``)."""
    plot_success: Callable[[list, Path, str], None]
    """``(rows, path, title)``: the success curve."""
    out: Any = None
    """Where progress is printed (None: stdout)."""


@dataclasses.dataclass(frozen=True)
class LearnerEntry:
    """One registered learner (exactly one of ``build`` and ``run``)."""

    name: str
    summary: str
    """One line for ``--help``."""
    build: Callable[[LearnerSetup], Learner] | None = None
    """Population learner: its factory."""
    ddpg_options: dict[str, Any] = dataclasses.field(default_factory=dict)
    """``DDPGConfig`` options over a preset's (the project's DDPG under this name)."""
    run: Callable[[Any, RunServices], dict[str, Any]] | None = None
    """Standalone learner: ``(config, services)`` trains in its own loop, returns the run
    summary."""
    load_policy: Callable[[Any, Any, Any], tuple[Any, Any]] | None = None
    """Standalone learner: ``(run_dir, config, single) -> (act, params)``."""
    across_processes: bool = False
    """Population learner: its checkpoint trees hold every process's rows of the
    device-split state (``Population.take_member`` / ``global_rows`` / ``own_rows``), so
    it trains over several processes (``mjx_hands.cluster``)."""

    def __post_init__(self):
        if (self.build is None) == (self.run is None):
            raise ValueError(f"learner {self.name!r}: give exactly one of build and run")

    @property
    def in_training_loop(self) -> bool:
        """Whether the project's loop trains it (runs, resume, grids)."""
        return self.build is not None


REGISTRY: dict[str, LearnerEntry] = {}


def register(entry: LearnerEntry) -> LearnerEntry:
    """Add ``entry`` (a name may be registered once)."""
    if entry.name in REGISTRY and REGISTRY[entry.name] != entry:
        raise ValueError(f"a learner named {entry.name!r} is already registered")
    REGISTRY[entry.name] = entry
    return entry


def entry(name: str) -> LearnerEntry:
    """The registered learner ``name``; a clear error for an unknown one."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ValueError(
            f"unknown learner {name!r}; expected one of {', '.join(REGISTRY)}"
        ) from None


def loop_learners() -> tuple[str, ...]:
    """Names of the learners the project's training loop trains."""
    return tuple(n for n, e in REGISTRY.items() if e.in_training_loop)


def _ddpg(setup: LearnerSetup) -> Learner:
    from mjx_hands.agents.ddpg import DDPG

    return DDPG(
        setup.train_env,
        setup.config.ddpg,
        episode_length=setup.single.episode_length,
        eval_env=setup.eval_env,
        devices=list(setup.devices) if setup.devices else None,
        members=setup.members,
        member_info=setup.member_info,
    )


def _brax(function: str) -> Callable:
    def call(*args):
        return getattr(importlib.import_module("mjx_hands.brax_agents"), function)(*args)

    return call


register(LearnerEntry("ddpg", "the paper's DDPG", build=_ddpg, across_processes=True))
register(
    LearnerEntry(
        "ddpg-ln",
        "DDPG with LayerNorm in every hidden layer (the evidence's pick)",
        build=_ddpg,
        ddpg_options={"layer_norm": True},
        across_processes=True,
    )
)
register(
    LearnerEntry(
        "td3",
        "DDPG with TD3's clipped double Q, target smoothing, delayed actor, 3-step returns "
        "and LayerNorm (a reference)",
        build=_ddpg,
        ddpg_options={
            "twin_critics": True,
            "target_policy_noise": 0.2,
            "target_noise_clip": 0.5,
            "actor_update_interval": 2,
            "n_step": 3,
            "layer_norm": True,
        },
        across_processes=True,
    )
)
for _name in ("sac", "ppo"):
    register(
        LearnerEntry(
            _name,
            f"Brax's {_name.upper()} on the same environment (its own loop)",
            run=_brax("run"),
            load_policy=_brax("load_policy"),
        )
    )
