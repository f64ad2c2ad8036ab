"""Evaluate a trained policy and render a video of it.

    python -m mjx_hands.evaluate RUN_DIR [--episodes 128] [--video-episodes 3]

Reloads the latest (or ``--step``) checkpoint of a ``train.py`` run, runs the
deterministic policy for ``--episodes`` randomised episodes and reports the success
rate (all required contacts touched at some step; and at the last step) and the mean
return, writes them to ``RUN_DIR/eval.json``, and renders ``RUN_DIR/eval.mp4`` of a
few episodes with MuJoCo's renderer (``MUJOCO_GL=egl`` renders without a display).
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from pathlib import Path
from typing import Annotated, Literal

import jax
import numpy as np
import tyro

from mjx_hands import checkpoint, training


@dataclasses.dataclass(frozen=True)
class EvalArgs:
    """Evaluate the policy of a training run and render a video."""

    run_dir: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN_DIR")]
    """Folder written by train.py."""
    episodes: int = 128
    """Evaluation episodes (one batch)."""
    step: int | None = None
    """Checkpoint epoch to load; default the latest."""
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


def restore_run(run_dir: Path, step: int | None = None, eval_envs: int | None = None):
    """(algo, checkpoint tree, config, single env) of a run's checkpoint; nothing compiled.

    The tree is what training saved: ``learner``, ``env_state`` (leaves with a leading
    device axis), ... ``eval_envs`` overrides the run's evaluation batch.
    """
    ckpt_dir = Path(run_dir) / "checkpoints"
    meta = checkpoint.read_metadata(ckpt_dir, step)
    config = training.config_from_json(meta["config"])
    config = dataclasses.replace(config, resume=False)
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
    algo, single = training.make_learner(config, devices=devices)
    like = jax.eval_shape(algo.init, jax.random.PRNGKey(0))  # structure only, no compile
    tree, _ = checkpoint.restore(
        ckpt_dir, training._checkpoint_tree(like, config.save_replay), step
    )
    return algo, tree, config, single


def load_policy(run_dir: Path, step: int | None = None, eval_envs: int = 128):
    """(algo, unreplicated learner, config, single env) of a run's checkpoint."""
    algo, tree, config, single = restore_run(run_dir, step, eval_envs)
    return algo, tree["learner"], config, single


def rollout(single, policy, num_episodes: int, rng: jax.Array) -> dict[str, np.ndarray]:
    """Run ``num_episodes`` whole episodes of ``single`` (no restarts) under ``policy``.

    Returns reward (T, n) and success (T, n), T the episode length, and for MuJoCo
    environments qpos (T+1, n, nq), mocap_pos (T+1, n, nmocap, 3), mocap_quat (T+1, n, nmocap, 4).
    """
    reset = jax.jit(jax.vmap(single.reset))
    step = jax.jit(lambda s: jax.vmap(single.step)(s, policy(s.obs)))
    state = reset(jax.random.split(rng, num_episodes))
    frames, rewards, successes = [state.pipeline_state], [], []
    for _ in range(single.episode_length):
        state = step(state)
        frames.append(state.pipeline_state)
        rewards.append(state.reward)
        successes.append(state.info["success"])
    stack = lambda xs: np.stack([np.asarray(x) for x in xs])
    result = {"reward": stack(rewards), "success": stack(successes)}
    if hasattr(frames[0], "qpos"):  # MuJoCo physics (the point-reach test task has none)
        for key in ("qpos", "mocap_pos", "mocap_quat"):
            result[key] = stack([getattr(d, key) for d in frames])
    return result


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
    run_dir = Path(args.run_dir)
    try:
        algo, learner, config, single = load_policy(run_dir, args.step, args.episodes)
        _check_video_size(single.mj_model, args)
    except (checkpoint.CheckpointError, ValueError, FileNotFoundError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    replicated = jax.tree.map(lambda x: np.broadcast_to(x, (algo.num_devices,) + x.shape), learner)
    metrics = algo.evaluate_learner(replicated, jax.random.PRNGKey(args.seed))
    summary = {"run_dir": str(run_dir), "task": config.task, "episodes": args.episodes} | metrics
    (run_dir / "eval.json").write_text(json.dumps(summary, indent=2))
    print(
        f"{config.task}: success {metrics['eval/success']:.3f} (at the end "
        f"{metrics['eval/success_final']:.3f}), mean return {metrics['eval/episode_return']:.2f} "
        f"over {args.episodes} episodes"
    )
    if args.video_episodes > 0:
        policy = lambda obs: algo.policy(learner, obs)
        trajectory = rollout(single, policy, args.video_episodes, jax.random.PRNGKey(args.seed + 1))
        video = Path(args.video or run_dir / "eval.mp4")
        try:
            render_video(
                single,
                trajectory,
                video,
                args.camera,
                args.width,
                args.height,
                fps=1.0 / single.config.control_dt,
            )
        except Exception as err:  # no GL context, codec missing, ...: say so, keep eval.json
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
