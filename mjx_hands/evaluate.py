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
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import jax
import tyro

from mjx_hands import (
    checkpoint,
    compile_cache,
    contact_profile,
    learners,
    run_directory,
    train_config,
    training,
)
from mjx_hands.rollouts import episode_keys, rollout, summarize


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
    seed: int = 12345
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
    physics: Literal["run", "auto", "mjx", "native"] = "run"
    """Physics of the evaluation episodes: the run's own, or another implementation of
    the same scene (e.g. a policy trained on native MuJoCo evaluated on MJX)."""


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


VIDEO_KEYS = ("qpos", "mocap_pos", "mocap_quat")
"""The :func:`rollout` arrays (T+1, n, ...) that :func:`render_video` reads."""


def render_video(single, trajectory, path: Path, camera: str, width: int, height: int, fps: float):
    """Write the rendered episodes of ``trajectory`` (see :func:`rollout`) one after another."""
    import imageio.v2 as imageio
    import mujoco

    model = single.mj_model
    data = mujoco.MjData(model)
    renderer = mujoco.Renderer(model, height, width)
    try:
        with imageio.get_writer(str(path), fps=fps, codec="libx264", quality=7) as writer:
            for episode in range(trajectory["qpos"].shape[1]):
                for t in range(trajectory["qpos"].shape[0]):
                    data.qpos[:] = trajectory["qpos"][t, episode]
                    data.mocap_pos[:] = trajectory["mocap_pos"][t, episode]
                    data.mocap_quat[:] = trajectory["mocap_quat"][t, episode]
                    mujoco.mj_forward(model, data)
                    renderer.update_scene(data, camera=camera)
                    writer.append_data(renderer.render())
    finally:
        renderer.close()


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
        "task": config.task,
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
            trajectory["contacts"], profile, plot_path, config.task, single.config.control_dt
        )
    (run_dir / "eval.json").write_text(json.dumps(summary, indent=2))
    print(
        f"{config.task}: success at the end {metrics['eval/success_final']:.3f} (at some "
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
