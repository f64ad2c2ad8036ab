"""Evaluate a trained policy and render a video of it.

    python -m mjx_hands.evaluate RUN_DIR [--episodes 128] [--video-episodes 3]

Reloads the latest (or ``--step``, or with ``--best`` the best-evaluated) checkpoint
of a ``train.py`` run, runs the
deterministic policy for ``--episodes`` randomised episodes and reports the success
rate (all required contacts touched at some step; and at the last step), the mean
return and the contact profile (which sensors touched, when; plotted to
``RUN_DIR/contact_profile.png``), writes them to ``RUN_DIR/eval.json``, and renders
``RUN_DIR/eval.mp4`` of the first few of those episodes with MuJoCo's renderer
(``MUJOCO_GL=egl`` renders without a display).
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from pathlib import Path
from typing import Annotated, Literal

import tyro

from mjx_hands import (
    checkpoint,
    compile_cache,
    contact_profile,
)
from mjx_hands.policies import load_policy
from mjx_hands.render import VIDEO_KEYS, render_video
from mjx_hands.rollouts import EVAL_SEED, episode_keys, rollout, summarize


@dataclasses.dataclass(frozen=True)
class EvalArgs:
    """Evaluate the policy of a training run and render a video."""

    run_dir: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN_DIR")]
    """Folder written by train.py."""
    episodes: int = 128
    """Evaluation episodes (one batch)."""
    step: int | None = None
    """Checkpoint epoch to load; default the latest."""
    best: bool = False
    """Load the policy of the run's best evaluation during training (RUN_DIR/best)
    instead of the latest checkpoint."""
    seed: int = EVAL_SEED
    """Seed of the evaluation episodes' randomisation."""
    video_episodes: int = 3
    """Episodes rendered into the video (0: no video)."""
    video: str | None = None
    """Video path; default RUN_DIR/eval.mp4."""
    camera: Literal["side", "top"] = "side"
    """Scene camera."""
    width: int = 512
    """Video width in pixels (a multiple of 16 keeps codecs from resizing)."""
    height: int = 384
    """Video height in pixels."""
    physics: Literal["run", "auto", "mjx", "native", "warp"] = "run"
    """Physics of the evaluation episodes: the run's own, or another implementation of
    the same scene (e.g. a policy trained on native MuJoCo evaluated on MJX)."""


def _check_video_size(model, args: EvalArgs) -> None:
    limit = (model.vis.global_.offwidth, model.vis.global_.offheight)
    if args.video_episodes > 0 and (args.width > limit[0] or args.height > limit[1]):
        raise ValueError(
            f"video {args.width}x{args.height} exceeds the scene's offscreen buffer "
            f"{limit[0]}x{limit[1]}; choose --width/--height within it"
        )


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")
    args = tyro.cli(EvalArgs, args=sys.argv[1:] if argv is None else argv, description=__doc__)
    compile_cache.enable()
    run_dir = Path(args.run_dir)
    try:
        if not 0 <= args.video_episodes <= args.episodes:
            raise ValueError(
                f"--video-episodes {args.video_episodes} must be between 0 and --episodes "
                f"{args.episodes}: the video shows the first of the evaluated episodes"
            )
        if args.best and args.step is not None:
            raise ValueError("--best and --step both pick the checkpoint; give one of them")
        loaded = load_policy(run_dir, args.step, args.episodes, args.best)
        config, single, epoch = loaded.config, loaded.single, loaded.epoch
        _check_video_size(single.mj_model, args)
        if args.physics != "run":
            from mjx_hands import env as env_lib

            single = env_lib.HandInteractionEnv(
                dataclasses.replace(single.config, physics=args.physics)
            )
    except (checkpoint.CheckpointError, ValueError, FileNotFoundError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    trajectory = rollout(single, loaded.act, episode_keys(args.seed, args.episodes))
    metrics, profile = summarize(single, trajectory)
    summary = {
        "run_dir": str(run_dir),
        "task": config.env.task,
        "checkpoint": {
            "kind": "best" if args.best else "latest" if args.step is None else "step",
            "epoch": epoch,
        },
        "episodes": args.episodes,
        "physics": single.backend,
    } | metrics
    if profile is not None:
        summary["contact_profile"] = profile
        plot_path = run_dir / "contact_profile.png"
        contact_profile.plot(
            trajectory["contacts"], profile, plot_path, config.env.task, single.config.control_dt
        )
    (run_dir / "eval.json").write_text(json.dumps(summary, indent=2))
    print(
        f"{config.env.task}: success at the end {metrics['eval/success_final']:.3f} (at some "
        f"step {metrics['eval/success']:.3f}), mean return {metrics['eval/episode_return']:.2f} "
        f"over {args.episodes} episodes ({summary['checkpoint']['kind']} checkpoint, epoch {epoch})"
    )
    if profile is not None:
        touched = ", ".join(f"{n} {profile['touched'][n]:.2f}" for n in profile["required"])
        print(f"required sensors touched (share of episodes): {touched}; plot: {plot_path}")
    if args.video_episodes > 0:
        shown = {k: trajectory[k][:, : args.video_episodes] for k in VIDEO_KEYS}
        video = Path(args.video or run_dir / "eval.mp4")
        try:
            render_video(
                single,
                shown,
                video,
                args.camera,
                args.width,
                args.height,
                fps=1.0 / single.config.control_dt,
            )
        except Exception as err:  # noqa: BLE001 - no GL context, codec missing, ...: say so, keep eval.json
            print(
                f"error: rendering failed ({type(err).__name__}: {err}); the evaluation is in "
                f"{run_dir / 'eval.json'}. Headless machines need MUJOCO_GL=egl or osmesa.",
                file=sys.stderr,
            )
            return 1
        print(f"video: {video} ({args.video_episodes} episodes, camera {args.camera!r})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
