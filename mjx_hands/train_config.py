"""train.py's configuration: the config dataclass, presets, its JSON form, and the rules
for resuming a run and for grouping runs into one population."""

from __future__ import annotations

import dataclasses
import json
import math
import time
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import jax
import tyro

from mjx_hands import checkpoint, learners, profiles, reward_params, tasks
from mjx_hands.agents.ddpg import DDPGConfig
from mjx_hands.brax_agents import PPOConfig, SACConfig
from mjx_hands.env_config import (
    PARTNER_SETUPS,
    EnvConfig,
    reward_weights,
    with_partners,
)


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Train a hand-interaction policy with the project's DDPG learner (``--algo``: the
    paper's, with LayerNorm, or with TD3's additions) or Brax's SAC/PPO for comparison."""

    env: Annotated[EnvConfig, tyro.conf.arg(name="")] = EnvConfig()
    """The environment (``mjx_hands.env_config.EnvConfig``): its fields are the command
    line's ``--task``, ``--profile``, ``--reward``, ``--knobs.*``, ``--mocap*``, partner
    models, ``--physics``, ``--scene.*`` ... Under ``--profile paper`` the learner's sizes
    and budget are the authors' (``mjx_hands.profiles``; 'project' trains ``ddpg-ln``)."""
    algo: str = "ddpg"
    """Learner, by its name in ``mjx_hands.learners``: ddpg (the paper's DDPG), ddpg-ln
    (the same with LayerNorm, the evidence's pick), td3 (TD3's additions and 3-step
    returns, a reference: its 3-step returns hurt the handshake), sac or ppo (Brax's, on
    the same environment), or a registered plug-in."""
    preset: Literal["auto", "cpu", "gpu"] = "auto"
    """Size of the run; auto picks by the device JAX finds."""
    partners: Literal[PARTNER_SETUPS] = "static"
    """The partner models to train against: 'static' (the paper's target hand) or
    'robust' (``env_config.ROBUST_PARTNERS``: the recorded partner, turned up to 35 deg,
    moving up to 0.25 m/s, observed with 2 mm noise; every model in every episode) or
    'mixed' (``env_config.MIXED_PARTNERS``: the same models, each drawn on in half the
    episodes, independently). Partner flags given as well
    (``--partner``, ``--target-speed-range`` ...) override the setup's."""
    num_envs: int = 64
    """Parallel environments (summed over devices)."""
    epochs: int = 100
    """Training epochs (see --ddpg.iterations-per-epoch etc. for an epoch's size)."""
    max_minutes: float | None = None
    """Stop (with a checkpoint) once training has run this long."""
    eval_every: int = 5
    """Evaluate (and checkpoint) every this many epochs."""
    checkpoint_every: int = 1
    """Also checkpoint every this many epochs (a crash loses at most these epochs; the
    CPU preset: 5, as its replay buffer makes a checkpoint cost a third of an epoch)."""
    checkpoint_minutes: float | None = None
    """Also checkpoint once this many minutes have passed since the last checkpoint."""
    eval_envs: int = 64
    """Episodes per evaluation (summed over devices), deterministic policy."""
    seed: int = 0
    """Seed of networks, exploration and episode randomisation."""
    run_dir: str | None = None
    """Output folder; default runs/<task>-<algo>-<time>."""
    resume: bool = False
    """Continue the run in --run-dir from its latest checkpoint."""
    save_replay: bool = True
    """Include the replay buffer in checkpoints (resume then equals an uninterrupted run)."""
    ddpg: DDPGConfig = DDPGConfig()
    """DDPG hyperparameters."""
    sac: SACConfig = SACConfig()
    """Brax's SAC (``--algo sac``); the presets size it like their DDPG."""
    ppo: PPOConfig = PPOConfig()
    """Brax's PPO (``--algo ppo``); the presets size it like their DDPG."""
    replay_ratio: float | None = None
    """Replayed transitions per collected one (updates x batch size / env steps), held as
    --num-envs changes: when set, it fixes --ddpg.updates-per-iteration (rounded to a
    multiple of --ddpg.actor-update-interval, at least one). Both presets replay 25.6."""

    def __post_init__(self):
        if (
            self.replay_ratio is not None
            and math.isfinite(self.replay_ratio)
            and self.replay_ratio > 0
        ):
            # Resolved here, so config.json records the updates the run makes.
            object.__setattr__(
                self, "ddpg", updates_for_ratio(self.ddpg, self.num_envs, self.replay_ratio)
            )
        problems = []
        for name in ("num_envs", "epochs", "eval_every", "eval_envs", "checkpoint_every"):
            if getattr(self, name) <= 0:
                problems.append(
                    f"--{name.replace('_', '-')} must be positive, got {getattr(self, name)}"
                )
        for name in ("max_minutes", "checkpoint_minutes"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                problems.append(
                    f"--{name.replace('_', '-')} must be a positive number, got {value}"
                )
        if self.replay_ratio is not None and not (
            math.isfinite(self.replay_ratio) and self.replay_ratio > 0
        ):
            problems.append(f"--replay-ratio must be a positive number, got {self.replay_ratio}")
        if self.algo not in learners.REGISTRY:
            problems.append(
                f"--algo {self.algo!r} is not a registered learner; expected one of "
                f"{', '.join(learners.REGISTRY)}"
            )
        try:
            reward_weights(self.env)
        except (ValueError, TypeError) as err:
            problems.append(f"--knobs: {err}")
        if self.env.mocap is not None and not Path(self.env.mocap).is_dir():
            problems.append(f"--mocap {self.env.mocap}: no such folder")
        if problems:
            raise ValueError("; ".join(problems))


def updates_for_ratio(ddpg: DDPGConfig, num_envs: int, ratio: float) -> DDPGConfig:
    """``ddpg`` with the updates per iteration that replay ``ratio`` sampled transitions per
    env step at ``num_envs`` envs: ratio x num_envs x unroll / batch, rounded to a multiple
    of the actor update interval (at least one interval)."""
    collected = num_envs * ddpg.unroll_length
    interval = ddpg.actor_update_interval
    updates = max(interval, interval * round(ratio * collected / ddpg.batch_size / interval))
    return dataclasses.replace(ddpg, updates_per_iteration=updates)


RECOMMENDED_ALGO = {"project": "ddpg-ln", "paper": "ddpg"}
"""The learner each profile trains without ``--algo``: the project's evidence's pick, the
paper's DDPG."""


def preset(kind: str, **overrides: Any) -> TrainConfig:
    """Default config of a preset: 'cpu' (2 cores, under an hour) or 'gpu' (thousands of envs).

    ``overrides`` are ``TrainConfig`` fields (the environment as ``env=EnvConfig(...)``).
    With ``env.profile='paper'`` the learner's sizes and budget are the authors'
    (:func:`mjx_hands.profiles.paper_learner` of ``env.task``) on either preset, evaluation
    batch and checkpointing the preset's."""
    if kind == "auto":
        kind = "gpu" if jax.default_backend() in ("gpu", "cuda", "rocm", "tpu") else "cpu"
    if kind == "cpu":
        base = TrainConfig(
            preset="cpu",
            num_envs=64,
            epochs=100,  # 640 k env steps, ~45 min on 2 quiet cores (~275 env steps/s with SGD)
            eval_envs=64,
            # A 250 MB checkpoint (the replay buffer) takes ~2.4 s against a ~6.5 s epoch
            # (native physics): every 5th epoch costs 7 %, every epoch 37 % (benchmarks/results/checkpoints.md).
            checkpoint_every=5,
            ddpg=DDPGConfig(
                replay_capacity=200_000,
                unroll_length=10,
                updates_per_iteration=64,
                iterations_per_epoch=10,
            ),
        )
    elif kind == "gpu":
        base = TrainConfig(
            preset="gpu",
            num_envs=4096,
            epochs=200,
            eval_envs=1024,
            save_replay=False,
            ddpg=DDPGConfig(
                batch_size=4096,
                replay_capacity=2_000_000,
                min_replay_size=40_960,
                unroll_length=5,
                # Replay ratio 25.6 as in the CPU preset (128 x 4,096 / 20,480): the H100
                # handshake run reached 86 % in 6.35 M steps with it; updates are cheap on a GPU.
                updates_per_iteration=128,
                iterations_per_epoch=10,
            ),
        )
    else:
        raise ValueError(f"unknown preset {kind!r}; expected auto, cpu or gpu")
    base = dataclasses.replace(base, sac=SACConfig.like(base.ddpg), ppo=PPOConfig.like(base.ddpg))
    env = overrides.get("env", base.env)
    if env.profile == "paper":
        paper = profiles.paper_learner(env.task)
        base = dataclasses.replace(
            base,
            **{k: v for k, v in paper.items() if k != "ddpg"},
            ddpg=dataclasses.replace(base.ddpg, **paper["ddpg"]),
        )
    algo = overrides.get("algo", base.algo)
    base = dataclasses.replace(base, ddpg=learner_config(algo, base.ddpg))
    config = dataclasses.replace(base, **overrides)
    return dataclasses.replace(config, env=with_partners(config.env, config.partners))


def with_partner_setup(config: TrainConfig, setup: str) -> TrainConfig:
    """``config`` training against the partner models of ``setup`` from now on (a resumed
    run's next curriculum stage), every partner field set as ``env_config.with_partners``
    sets it: 'static' the paper's static partner, 'robust' ``env_config.ROBUST_PARTNERS``
    over it (a partner flag of the previous stage, e.g. ``--action-delay``, is reset)."""
    return dataclasses.replace(config, partners=setup, env=with_partners(config.env, setup))


def learner_config(algo: str, ddpg: DDPGConfig) -> DDPGConfig:
    """``ddpg`` with the options of learner ``algo`` (its ``LearnerEntry.ddpg_options``:
    DDPG's variants; Brax's SAC/PPO read only its sizes and leave it as it is)."""
    options = learners.REGISTRY[algo].ddpg_options if algo in learners.REGISTRY else {}
    return dataclasses.replace(ddpg, **options)


def read_config_json(path: Path) -> dict[str, Any]:
    """A run's config.json as a dict; a damaged file is an error naming it."""
    try:
        data = json.loads(Path(path).read_text())
        if not isinstance(data, dict):
            raise TypeError(f"it holds a JSON {type(data).__name__}, not an object")
    except (OSError, ValueError, TypeError) as err:
        raise ValueError(f"{path} is unreadable ({err}); restore it or start a new run") from err
    return data


def resolved(config: TrainConfig) -> TrainConfig:
    """``config`` with every reward knob a number, as :func:`env_config.reward_weights`
    resolves them (the task's own where unset); under the paper profile unset knobs stay
    unset (each variant has the authors' own)."""
    if config.env.profile == "paper":
        return config
    knobs = reward_params.knobs_of(reward_weights(config.env))
    return dataclasses.replace(config, env=dataclasses.replace(config.env, knobs=knobs))


def config_to_json(config: TrainConfig) -> dict[str, Any]:
    """``config`` as JSON data, its knobs :func:`resolved` (a run keeps its reward when a
    task's own knobs change later)."""
    return dataclasses.asdict(resolved(config))


def config_from_json(data: dict[str, Any]) -> TrainConfig:
    """The config a run's config.json (or a grid record's ``train``) holds. Settings added
    since it was written take their defaults; a key this version does not know is a
    ``TypeError`` naming it."""
    data = dict(data)
    if "env" not in data:  # runs from before the environment was a field of its own
        names = {f.name for f in dataclasses.fields(EnvConfig)}
        data["env"] = {k: data.pop(k) for k in list(data) if k in names}
        data["env"].setdefault("demos", "all")  # before the setting, every demonstration
    env = dict(data["env"])
    if env.get("profile", "project") == "paper":
        env["knobs"] = reward_params.RewardKnobs(**(env.get("knobs") or {}))
    else:
        env["knobs"] = _knobs_from_json(env.get("knobs"), env.get("task", "handshake"))
    data["env"] = dataclass_from_json(EnvConfig, env)
    ddpg = dataclass_from_json(DDPGConfig, data.pop("ddpg"))
    # Runs from before SAC and PPO had settings of their own trained with DDPG's sizes.
    for name, kind in (("sac", SACConfig), ("ppo", PPOConfig)):
        data[name] = dataclass_from_json(kind, data[name]) if name in data else kind.like(ddpg)
    return dataclass_from_json(TrainConfig, data | {"ddpg": ddpg})


def dataclass_from_json(kind: type, data: dict[str, Any]):
    """A ``kind`` dataclass from its ``dataclasses.asdict`` JSON form: nested dataclasses
    from their dicts, lists back to tuples; fields absent take their defaults."""
    if not isinstance(data, dict):
        return data  # already built
    fields = {f.name: f for f in dataclasses.fields(kind)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise TypeError(f"{kind.__name__} has no setting {', '.join(unknown)}")
    hints = typing.get_type_hints(kind)
    values = {}
    for name, value in data.items():
        if dataclasses.is_dataclass(hints[name]) and isinstance(value, dict):
            value = dataclass_from_json(hints[name], value)
        elif isinstance(value, list):
            value = tuple(value)
        values[name] = value
    return kind(**values)


def _knobs_from_json(value, task: str) -> reward_params.RewardKnobs:
    """Knobs as config.json (or a checkpoint's metadata) holds them. Runs from before
    they were recorded trained with ``RewardWeights``' defaults; runs started on
    2026-12-02 may name a set ("authors" or "project")."""
    if isinstance(value, reward_params.RewardKnobs):
        value = dataclasses.asdict(value)
    if value is None or value == "project":
        return reward_params.knobs_of(reward_params.RewardWeights())
    if value == "authors":
        value = dict(tasks.spec(task).authors_knobs)
    return reward_params.task_knobs(task, reward_params.RewardKnobs(**value))


# Settings a resumed run must share with its checkpoint: they fix the task, the physics,
# the networks' and buffers' shapes. Everything else (learning rates, budget, the
# partner models: a curriculum changes them between resumes) may change.
RESUME_FIXED = (
    "env.task",
    "env.profile",
    "env.reward",
    "env.imitation",
    "env.knobs",
    "env.mocap_source",
    "env.mocap",
    "env.demos",
    "env.physics",
    "env.control_dt",
    "env.scene",
    "num_envs",
    "algo",
    "ddpg.hidden_sizes",
    "ddpg.layer_norm",
    "ddpg.batch_norm",
    "ddpg.twin_critics",
    "ddpg.num_atoms",
    "ddpg.replay_capacity",
)

MEMBER_FIELDS = ("seed", "env.reward", "env.imitation", "run_dir")
"""What members of one population may differ in; every other setting is shared (one
program): seeds, and reward variants as data."""


def dotted(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A nested JSON dict flattened to ``{"env.task": ..., "ddpg.batch_size": ...}``."""
    out = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out |= dotted(value, f"{prefix}{key}.")
        else:
            out[f"{prefix}{key}"] = value
    return out


def check_resumable(saved: dict[str, Any], config: TrainConfig, run_dir: Path) -> None:
    current = json.loads(json.dumps(config_to_json(config)))  # tuples as JSON lists
    # Through the dataclass: settings added since the run started take their defaults.
    saved = json.loads(json.dumps(config_to_json(config_from_json(saved))))

    def get(tree, key):
        for part in key.split("."):
            tree = tree.get(part) if isinstance(tree, dict) else None
        return tree

    for key in RESUME_FIXED:
        if get(saved, key) != get(current, key):
            raise checkpoint.CheckpointError(
                f"--resume: {run_dir} was trained with {key}={get(saved, key)!r}, "
                f"this command asks for {get(current, key)!r}"
            )


def check_population(configs: list[TrainConfig]) -> None:
    if not configs:
        raise ValueError("a population needs at least one run config")
    shared = lambda c: {
        k: v for k, v in dotted(config_to_json(c)).items() if k not in MEMBER_FIELDS
    }
    for config in configs[1:]:
        a, b = shared(configs[0]), shared(config)
        if a != b:
            diff = sorted(k for k in a if a[k] != b[k])
            raise ValueError(
                f"members of a population may differ only in {', '.join(MEMBER_FIELDS)}; "
                f"{config.run_dir} differs from {configs[0].run_dir} in {', '.join(diff)}"
            )
    dirs = [str(run_dir_path(c)) for c in configs]
    if len(set(dirs)) != len(dirs):
        raise ValueError(f"members need distinct run directories, got {dirs}")
    if any(not learners.entry(c.algo).in_training_loop for c in configs):
        raise ValueError(
            f"training.run trains {', '.join(learners.loop_learners())}; --algo "
            f"{configs[0].algo} has its own loop (train.py dispatches by --algo)"
        )


def run_dir_path(config: TrainConfig) -> Path:
    """``--run-dir``, or runs/<task>-<algo>-<time> when none is given."""
    return Path(
        config.run_dir or f"runs/{config.env.task}-{config.algo}-{time.strftime('%Y%m%d-%H%M%S')}"
    )


# What a config sets beyond its compiled programs: seeds are data, the rest is the run
# loop's. Learners are shared between configs that differ only in these
# (training.make_learner).
RUN_LOOP_FIELDS = {
    "seed": 0,
    "run_dir": None,
    "resume": False,
    "epochs": 1,
    "max_minutes": None,
    "eval_every": 1,
    "checkpoint_every": 1,
    "checkpoint_minutes": None,
    "save_replay": True,
    "replay_ratio": None,  # already resolved into ddpg.updates_per_iteration
    "preset": "auto",  # its values are in the other fields
    "partners": "static",  # so are these (the env's partner fields)
}


def program_config(config: TrainConfig) -> TrainConfig:
    """``config`` with the fields that leave its compiled programs unchanged at defaults,
    its knobs :func:`resolved` (unset and recorded knobs make the same program)."""
    return resolved(dataclasses.replace(config, **RUN_LOOP_FIELDS))
