"""The training command: ``python train.py`` in a checkout, ``mjx-hands-train`` once
installed (both call :func:`main`)."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

USAGE = """Train a hand-interaction policy: the project's single command.

    python train.py --task handshake            # the project's setup (ddpg-ln), preset by device
    python train.py --task et --profile paper   # the authors' environment and DDPG
    python train.py --task handclap --algo ddpg-ln  # with LayerNorm (the evidence's pick)
    python train.py --task et --no-imitation    # an ablation
    python train.py --task et --partners robust # against a recorded, turning, moving partner
    python train.py --run-dir runs/x --resume   # continue a run with its own config
    python train.py --run-dir runs/x --resume --epochs 400   # ... and a larger budget

(installed: mjx-hands-train with the same options). Everything written goes to the run
directory: config.json, metrics.csv, TensorBoard events (``tensorboard --logdir runs``),
Orbax checkpoints and success.png. ``python -m mjx_hands.evaluate RUN_DIR`` (installed:
mjx-hands-evaluate) reloads the policy and renders a video."""


def option(argv: list[str], name: str) -> str | None:
    """Value of ``--name V`` or ``--name=V`` in argv, read before the full parse."""
    for i, arg in enumerate(argv):
        if arg == name and i + 1 < len(argv):
            return argv[i + 1]
        if arg.startswith(name + "="):
            return arg.split("=", 1)[1]
    return None


def default_config(argv: list[str]):
    """The config the command line overrides: a resumed run's own, else the preset's."""
    import dataclasses
    from pathlib import Path

    from mjx_hands import train_config

    run_dir = option(argv, "--run-dir") or option(argv, "--run_dir")
    if "--resume" in argv and run_dir and (Path(run_dir) / "config.json").is_file():
        saved = train_config.read_config_json(Path(run_dir) / "config.json")
        try:
            config = train_config.config_from_json(saved)
        except TypeError as err:  # a key this version does not know
            raise ValueError(f"{run_dir}/config.json does not fit this version: {err}") from err
        partners = option(argv, "--partners")
        if partners is not None:  # a curriculum's next stage: the named partner models
            config = train_config.with_partner_setup(config, partners)
        return dataclasses.replace(config, resume=False)
    return preset_default(argv)


def preset_default(argv: list[str]):
    """The preset --preset names (auto by default) for the profile --profile names and
    the learner --algo names (default: the profile's, ``RECOMMENDED_ALGO``)."""
    from mjx_hands import profiles, tasks, train_config
    from mjx_hands.env_config import EnvConfig

    profile = profiles.check(option(argv, "--profile") or "project")
    task = option(argv, "--task") or "handshake"
    return train_config.preset(
        option(argv, "--preset") or "auto",
        env=EnvConfig(task=task if task in tasks.TASKS else "handshake", profile=profile),
        algo=option(argv, "--algo") or train_config.RECOMMENDED_ALGO[profile],
        partners=option(argv, "--partners") or "static",
    )


def reported(start: Callable[[], T]) -> tuple[T | None, int]:
    """``(start(), 0)``, or, when training cannot go on, ``(None, exit code)`` after
    printing ``error: ...``: 3 when every run diverged, 2 for a refusal (bad options or
    data, a damaged checkpoint, a missing or occupied folder). Every training command
    (train.py, experiments run) reports its errors through this."""
    from mjx_hands import checkpoint, training
    from mjx_hands.mocap import MocapError

    refusals = (
        ValueError,
        MocapError,
        checkpoint.CheckpointError,
        FileNotFoundError,
        FileExistsError,
    )
    try:
        return start(), 0
    except training.TrainingDiverged as err:
        print(f"error: {err}", file=sys.stderr)
        return None, 3
    except refusals as err:
        print(f"error: {err}", file=sys.stderr)
        return None, 2


def main(argv: list[str] | None = None) -> int:
    import tyro

    from mjx_hands import compile_cache, learners, train_config, training

    argv = sys.argv[1:] if argv is None else argv

    def start() -> dict:
        default = default_config(argv)
        config = tyro.cli(train_config.TrainConfig, default=default, args=argv, description=USAGE)
        compile_cache.enable()
        learner = learners.entry(config.algo)
        if learner.in_training_loop:
            return training.run(config)
        return learner.run(config, training.run_services(config))

    summary, code = reported(start)
    if code:
        return code
    final = summary["final_eval"]
    print(
        f"done ({summary['stop_reason']}): {summary['epochs']} epochs, "
        f"eval success at the end {final.get('eval/success_final', float('nan')):.2f} "
        f"(some step {final.get('eval/success', float('nan')):.2f}), "
        f"best {summary.get('best_eval_success_final', float('nan')):.2f}"
        + (
            f" (epoch {summary['best_checkpoint']}, policy in best/)"
            if summary.get("best_checkpoint") is not None
            else ""
        )
        + f"; results in {summary['run_dir']}"
    )
    return 0
