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
import functools
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import jax
import numpy as np
import tyro

from mjx_hands import checkpoint, contact_profile, contract, shadow_hand, training


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


def restore_run(
    run_dir: Path,
    step: int | None = None,
    eval_envs: int | None = None,
    best: bool = False,
    learner_only: bool = False,
):
    """(algo, checkpoint tree, config, single env) of a run's checkpoint; nothing compiled.

    The tree is what training saved: ``learner``, ``env_state`` (leaves with a leading
    device axis), ...; with ``best`` or ``learner_only``, the ``learner`` only (read by
    path, so checkpoints whose environment state has another layout still load).
    ``eval_envs`` overrides the run's evaluation batch.
    """
    if not Path(run_dir).is_dir():
        raise FileNotFoundError(f"{run_dir}: no such run folder")
    ckpt_dir = Path(run_dir) / (training.BEST_DIR if best else "checkpoints")
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
    step = checkpoint.resolve_step(ckpt_dir, step)  # the newest intact one when None
    meta = checkpoint.read_metadata(ckpt_dir, step, verified=True)
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
    partial = learner_only or meta.get("contents") == "policy"
    if partial:
        like_tree = algo.policy_tree(like)
    else:
        like_tree = algo.checkpoint_tree(like, config.save_replay)
    tree, meta = checkpoint.restore(ckpt_dir, like_tree, step, partial=partial, verified=True)
    return algo, tree | {"epoch": int(meta["epoch"])}, config, single


def load_policy(run_dir: Path, step: int | None = None, eval_envs: int = 128, best: bool = False):
    """(algo, unreplicated learner, config, single env, epoch) of a run's checkpoint."""
    algo, tree, config, single = restore_run(run_dir, step, eval_envs, best, learner_only=True)
    return algo, tree["learner"], config, single, tree["epoch"]


@functools.lru_cache(maxsize=8)
def compiled_rollout(single, policy, reset=None, extra=None):
    """The jitted (reset, step, per-state record) of :func:`rollout`, kept per (env,
    policy, reset, extra): a sweep that rolls out chunk after chunk compiles once."""
    reset = jax.jit(reset or jax.vmap(single.reset))
    step = jax.jit(lambda s: jax.vmap(single.step)(s, policy(s.obs)))
    per_state = jax.jit(
        jax.vmap(lambda s: single.pose(s.pipeline_state) | (extra(s) if extra else {}))
    )
    return reset, step, per_state


def rollout(
    single,
    policy,
    num_episodes: int,
    rng: jax.Array,
    reset: Callable[..., Any] | None = None,
    reset_args: tuple = (),
    extra: Callable[[Any], dict[str, jax.Array]] | None = None,
) -> dict[str, np.ndarray]:
    """Run ``num_episodes`` whole episodes of ``single`` (no restarts) under ``policy``.

    Args:
      reset: (keys (num_episodes, 2), *reset_args) -> batched initial ``State``; default
        ``single.reset`` vmapped. Robustness sweeps pass ``single.reset_with`` vmapped and
        the target's tilts and speeds as ``reset_args`` (data: one compile for all).
      extra: single ``State`` -> {name: array}, recorded at every step as ``name``
        (T+1, n, ...) beside the rest (e.g. hand points for the naturalness metrics).

    Returns reward (T, n) and success (T, n), T the episode length; for the hand
    environments also contacts (T, n, 15), the sensor readings, qpos (T+1, n, nq),
    mocap_pos (T+1, n, nmocap, 3), mocap_quat (T+1, n, nmocap, 4) for rendering, and
    the last step's ``pose/<name>`` metrics (n,).
    """
    reset, step, per_state = compiled_rollout(single, policy, reset, extra)
    state = reset(jax.random.split(rng, num_episodes), *reset_args)
    sensors = [f"contact/{n}" for n in shadow_hand.CONTACT_SENSORS]
    has_contacts = all(k in state.metrics for k in sensors)
    record = {key: [] for key in ("reward", "success", "contacts")}

    def keep(state):  # host copies only: whole mjx.Data per step would pile up on device
        for key, value in per_state(state).items():
            record.setdefault(key, []).append(np.asarray(value))

    keep(state)
    for _ in range(single.episode_length):
        state = step(state)
        keep(state)
        record["reward"].append(np.asarray(state.reward))
        record["success"].append(np.asarray(state.info["success"]))
        if has_contacts:
            record["contacts"].append(np.stack([np.asarray(state.metrics[k]) for k in sensors], -1))
    out = {key: np.stack(values) for key, values in record.items() if values}
    # The last step's pose metrics (n,): the final pose errors of the result schema.
    out |= {
        k: np.asarray(v) for k, v in state.metrics.items() if k.startswith(contract.POSE_PREFIX)
    }
    return out


def summarize(single, trajectory: dict[str, np.ndarray]) -> tuple[dict, dict | None]:
    """(metrics, contact profile or None) of a :func:`rollout`: the training's evaluation
    metrics (:func:`contract.evaluation_metrics`: success at some step and at the last
    step, mean return, final pose errors) and, for the hand environments,
    :func:`contact_profile.summarize` of the sensor readings."""
    final = {k: v for k, v in trajectory.items() if k.startswith(contract.POSE_PREFIX)}
    arrays = contract.evaluation_metrics(
        trajectory["reward"], (trajectory["success"] > 0.5).astype(np.float32), final
    )
    metrics = {k: float(v) for k, v in arrays.items()}
    if "contacts" not in trajectory:
        return metrics, None
    groups = np.asarray(single.params.success_groups[0])
    return metrics, contact_profile.summarize(trajectory["contacts"], groups)


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
    run_dir = Path(args.run_dir)
    try:
        if not 0 <= args.video_episodes <= args.episodes:
            raise ValueError(
                f"--video-episodes {args.video_episodes} must be between 0 and --episodes "
                f"{args.episodes}: the video shows the first of the evaluated episodes"
            )
        if args.best and args.step is not None:
            raise ValueError("--best and --step both pick the checkpoint; give one of them")
        algo, learner, config, single, epoch = load_policy(
            run_dir, args.step, args.episodes, args.best
        )
        _check_video_size(single.mj_model, args)
        if args.physics != "run":
            from mjx_hands import env as env_lib

            single = env_lib.HandInteractionEnv(
                dataclasses.replace(single.config, physics=args.physics)
            )
    except (checkpoint.CheckpointError, ValueError, FileNotFoundError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    def policy(obs):
        return algo.policy(learner, obs)

    trajectory = rollout(single, policy, args.episodes, jax.random.PRNGKey(args.seed))
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
