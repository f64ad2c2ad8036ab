"""Robustness of trained policies to what training did not randomise: the target hand's
orientation, a target hand that moves, and imperfect sensing and actuation.

    python -m mjx_hands.robustness RUN_DIR [RUN_DIR ...] [--out DIR]
        [--max-angle-deg 60 --angle-step-deg 15] [--speeds 0 0.05 0.1 0.2 0.3]
    python -m mjx_hands.robustness RUN_DIR --sweep sensing [--noise-mm 0 2 5 10 --delays 0 1 2]

The paper's two tests (its Figs. 5 and 6), for one run or for several runs of one task
(e.g. the seeds of a grid variant: mean and standard error over them):

* **orientation**: the target hand turned about its palm centre by every (yaw, pitch) of
  a grid (``env.yaw_pitch_quat``: yaw about the vertical, pitch about the horizontal
  axis across the agent's reach) -> ``robustness_orientation.json`` / ``.png``, a
  heatmap of success at the end of the episode and at some step;
* **motion**: the target hand moving at a constant speed in a random direction drawn
  anew every ``--turn-period`` seconds, inside a box around its nominal position
  (``EnvConfig.target_speed``); goals and imitation references move with it ->
  ``robustness_motion.json`` / ``.png``, success against speed;
* **sensing** (``--sweep sensing`` or ``all``): the observed target position off by a
  Gaussian error of each ``--noise-mm`` (``EnvConfig.target_position_noise``), and the
  action reaching the actuators each of ``--delays`` control steps late
  (``EnvConfig.action_delay``) -> ``robustness_sensing.json`` / ``.png``;
* **partner** (``--sweep partner`` or ``all``): the static target against the recorded
  partner, which replays its demonstration's approach (``EnvConfig.partner``), at each
  of ``--partner-shares`` -> ``robustness_partner.json`` / ``.png``.

Every cell (and speed) sees the same episodes: episode k of each uses the same key
(demonstration, target position, start pose), so cells differ only in the target's
orientation or speed. Orientations and speeds are data of one compiled reset: a whole
sweep compiles once per run; each noise level and delay is an environment of its own
(one compile each).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
from pathlib import Path
from typing import Annotated, Literal

import jax
import numpy as np
import tyro

from mjx_hands import checkpoint, compile_cache, env_config, policies, rollouts
from mjx_hands import env as env_lib

ORIENTATION_FILE = "robustness_orientation"
MOTION_FILE = "robustness_motion"
SENSING_FILE = "robustness_sensing"
PARTNER_FILE = "robustness_partner"
SWEEPS = {
    "both": ("orientation", "motion"),
    "orientation": ("orientation",),
    "motion": ("motion",),
    "sensing": ("sensing",),
    "partner": ("partner",),
    "all": ("orientation", "motion", "sensing", "partner"),
}


@dataclasses.dataclass(frozen=True)
class RobustnessArgs:
    """Success of trained policies as the target hand is turned or moves."""

    run_dirs: Annotated[tuple[str, ...], tyro.conf.Positional, tyro.conf.arg(metavar="RUN_DIR")]
    """Folders written by train.py (or grid members), all of one task."""
    sweep: Literal[tuple(SWEEPS)] = "both"
    """Which tests to run: both (orientation and motion, the paper's), one of them,
    sensing (noise and delay), partner (static vs the recorded partner), or all."""
    out: str | None = None
    """Output folder; default the run's folder (required with several runs)."""
    max_angle_deg: float = 60.0
    """Yaw and pitch run from -this to +this, degrees."""
    angle_step_deg: float = 15.0
    """Step of the yaw and pitch grid, degrees."""
    speeds: tuple[float, ...] = (0.0, 0.05, 0.1, 0.15, 0.2, 0.3)
    """Speeds of the moving target, m/s."""
    noise_mm: tuple[float, ...] = (0.0, 2.0, 5.0, 10.0)
    """Std of the observed target position's error, millimetres (sensing sweep)."""
    delays: tuple[int, ...] = (0, 1, 2)
    """Control steps between an action and the actuators (sensing sweep)."""
    partner_shares: tuple[float, ...] = (0.5,)
    """The recorded partner's shares of the palms' closing to test (partner sweep; where
    the recordings hold no target path: ``EnvConfig.partner_share``)."""
    turn_period: float = 0.5
    """Seconds between the moving target's changes of direction."""
    motion_box: tuple[float, float, float] = (0.1, 0.1, 0.1)
    """Half-extent of the box (metres) around the nominal target position it moves in."""
    partner_motion: Literal[env_config.PARTNER_MOTIONS] | None = None
    """How the moving or recorded partner travels within a control period
    (``EnvConfig.partner_motion``: per_step or continuous); default each policy's own."""
    episodes: int = 32
    """Episodes per grid cell and per speed, per run."""
    best: bool = False
    """Use each run's best-evaluated policy (RUN_DIR/best) instead of the latest checkpoint."""
    seed: int = 12345
    """Seed of the episodes' randomisation (the same for every cell and speed)."""
    chunk: int = 512
    """Episodes simulated together (one compiled batch; the last one is padded)."""


def check_args(args: RobustnessArgs) -> None:
    """Raise ValueError naming every bad option."""
    problems = []
    if not args.run_dirs:
        problems.append("give at least one RUN_DIR")
    if len(args.run_dirs) > 1 and args.out is None:
        problems.append("several runs need --out DIR for the combined results")
    if not (math.isfinite(args.max_angle_deg) and 0 <= args.max_angle_deg <= 180):
        problems.append(f"--max-angle-deg {args.max_angle_deg} must lie in [0, 180]")
    if not (math.isfinite(args.angle_step_deg) and args.angle_step_deg > 0):
        problems.append(f"--angle-step-deg {args.angle_step_deg} must be positive")
    if not args.speeds or not all(math.isfinite(s) and s >= 0 for s in args.speeds):
        problems.append(f"--speeds {list(args.speeds)} must be one or more speeds >= 0 (m/s)")
    if not args.noise_mm or not all(math.isfinite(n) and n >= 0 for n in args.noise_mm):
        problems.append(f"--noise-mm {list(args.noise_mm)} must be one or more stds >= 0 (mm)")
    if not args.delays or not all(isinstance(d, int) and d >= 0 for d in args.delays):
        problems.append(f"--delays {list(args.delays)} must be one or more whole steps >= 0")
    shares = args.partner_shares
    if not shares or not all(math.isfinite(v) and 0 <= v <= 1 for v in shares):
        problems.append(f"--partner-shares {list(shares)} must be one or more shares in [0, 1]")
    if not (math.isfinite(args.turn_period) and args.turn_period > 0):
        problems.append(f"--turn-period {args.turn_period} must be positive (seconds)")
    if not all(math.isfinite(b) and b > 0 for b in args.motion_box):
        problems.append(f"--motion-box {list(args.motion_box)} must be three positive metres")
    for name in ("episodes", "chunk"):
        if getattr(args, name) < 1:
            problems.append(f"--{name} {getattr(args, name)} must be positive")
    if problems:
        raise ValueError("; ".join(problems))


def angle_grid(max_angle_deg: float, step_deg: float) -> np.ndarray:
    """Angles (n,) in degrees from -max to +max in steps of ``step_deg`` (0 included when
    the step divides max)."""
    n = math.floor(max_angle_deg / step_deg + 1e-9)
    return step_deg * np.arange(-n, n + 1, dtype=np.float64)


def run_episodes(
    env: env_lib.HandInteractionEnv,
    policy,
    tilts: np.ndarray,
    speeds: np.ndarray | None,
    episodes: int,
    seed: int,
    chunk: int,
) -> dict[str, np.ndarray]:
    """Success of ``episodes`` episodes per condition.

    Args:
      env: the run's environment; with ``speeds``, one built with ``target_speed`` set.
      tilts: (C, 4) quaternions of the target's turn per condition.
      speeds: (C,) m/s per condition, or None for a static target.
    Returns:
      ``success_final`` and ``success`` (C, episodes): all required contacts at the last
      step / at some step.
    """
    conditions = tilts.shape[0]
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the same for every condition
    flat_keys = np.tile(np.asarray(keys), (conditions, 1))
    flat_tilts = np.repeat(np.asarray(tilts, np.float32), episodes, axis=0)
    flat_speeds = np.repeat(
        np.zeros(conditions, np.float32) if speeds is None else np.asarray(speeds, np.float32),
        episodes,
    )
    total = conditions * episodes
    size = min(chunk, total)
    pad = (-total) % size
    pad_rows = lambda x: np.concatenate([x, np.repeat(x[-1:], pad, axis=0)]) if pad else x
    flat_keys, flat_tilts, flat_speeds = map(pad_rows, (flat_keys, flat_tilts, flat_speeds))

    reset = sweep_reset(env, moving=speeds is not None)
    final, reached = [], []
    for start in range(0, total + pad, size):
        part = slice(start, start + size)
        trajectory = rollouts.rollout(
            env,
            policy,
            flat_keys[part],
            reset=reset,
            reset_args=(flat_tilts[part], flat_speeds[part]),
        )
        success = trajectory["success"] > 0.5  # (T, size)
        final.append(success[-1])
        reached.append(success.any(0))
    shape = (conditions, episodes)
    return {
        "success_final": np.concatenate(final)[:total].reshape(shape).astype(np.float64),
        "success": np.concatenate(reached)[:total].reshape(shape).astype(np.float64),
    }


@functools.lru_cache(maxsize=8)
def sweep_reset(env, moving: bool):
    """The batched reset (keys, tilts, speeds) of a sweep, one object per env and kind,
    so that ``rollouts`` compiles a sweep once for every policy of one program."""
    if moving:
        return jax.vmap(env.reset_with)
    return jax.vmap(lambda key, tilt, speed: env.reset_with(key, tilt))


def moving_target_env(env, turn_period: float, motion_box: tuple[float, float, float]):
    """``env`` with a target that moves (its speed is data of each reset), one object per
    setting (see :func:`sweep_reset`)."""
    config = dataclasses.replace(
        env.config,
        target_speed=0.0,
        target_turn_period=turn_period,
        target_motion_box=motion_box,
    )
    return env_lib.env_for(config)


def orientation_sweep(env, policy, args: RobustnessArgs, log=None) -> dict:
    """Success per (pitch, yaw) cell of one policy: arrays (n_pitch, n_yaw)."""
    angles = angle_grid(args.max_angle_deg, args.angle_step_deg)
    yaw, pitch = np.meshgrid(np.radians(angles), np.radians(angles))  # rows: pitch
    tilts = np.asarray(jax.vmap(env_lib.yaw_pitch_quat)(yaw.ravel(), pitch.ravel()))
    print(
        f"  orientation: {angles.size} x {angles.size} cells x {args.episodes} episodes",
        file=log,
        flush=True,
    )
    result = run_episodes(env, policy, tilts, None, args.episodes, args.seed, args.chunk)
    shape = (angles.size, angles.size)
    return {k: v.mean(axis=1).reshape(shape) for k, v in result.items()}


def motion_sweep(env, policy, args: RobustnessArgs, log=None) -> dict:
    """Success per speed of one policy: arrays (n_speeds,)."""
    moving = moving_target_env(env, args.turn_period, tuple(args.motion_box))
    speeds = np.asarray(args.speeds, np.float64)
    identity = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (speeds.size, 1))
    print(f"  motion: {speeds.size} speeds x {args.episodes} episodes", file=log, flush=True)
    result = run_episodes(moving, policy, identity, speeds, args.episodes, args.seed, args.chunk)
    return {k: v.mean(axis=1) for k, v in result.items()}


def imperfect_env(env, noise: float, delay: int):
    """``env`` observing the target with a ``noise`` (m) error and acting ``delay`` steps
    late, one object per setting (so every policy of a program shares its compile)."""
    if (noise, delay) == (env.config.target_position_noise, env.config.action_delay):
        return env
    config = dataclasses.replace(env.config, target_position_noise=noise, action_delay=delay)
    return env_lib.env_for(config)


def sensing_sweep(env, policy, args: RobustnessArgs, log=None) -> dict:
    """Success per noise level (delay 0) and per delay (noise 0) of one policy: arrays
    ``noise_success_final`` (n_noise,), ``delay_success_final`` (n_delays,) and the same
    at some step. Every condition runs the same episodes."""
    identity = np.array([[1.0, 0.0, 0.0, 0.0]])
    print(
        f"  sensing: {len(args.noise_mm)} noise levels, {len(args.delays)} delays x "
        f"{args.episodes} episodes",
        file=log,
        flush=True,
    )
    conditions = [("noise", (mm / 1000.0, 0)) for mm in args.noise_mm]
    conditions += [("delay", (0.0, d)) for d in args.delays]
    out: dict[str, list] = {}
    for axis, (noise, delay) in conditions:
        run = imperfect_env(env, noise, delay)
        result = run_episodes(run, policy, identity, None, args.episodes, args.seed, args.chunk)
        for key, value in result.items():
            out.setdefault(f"{axis}_{key}", []).append(float(value.mean()))
    return {k: np.asarray(v) for k, v in out.items()}


def partner_env(env, partner: str, share: float):
    """``env`` with the ``partner`` model at ``share``, one object per setting."""
    if (partner, share) == (env.config.partner, env.config.partner_share):
        return env
    config = dataclasses.replace(env.config, partner=partner, partner_share=share)
    return env_lib.env_for(config)


def partner_conditions(env, args: RobustnessArgs) -> list[tuple[str, float]]:
    """(partner, share) of every condition of the partner sweep: the static target,
    then the recorded partner at each share."""
    return [("static", env.config.partner_share)] + [("recorded", s) for s in args.partner_shares]


def partner_sweep(env, policy, args: RobustnessArgs, log=None) -> dict:
    """Success per partner condition (:func:`partner_conditions`) of one policy: arrays
    (n_conditions,). Every condition runs the same episodes (demonstration, target
    placement, start); the recorded partner's lag is drawn per episode."""
    identity = np.array([[1.0, 0.0, 0.0, 0.0]])
    conditions = partner_conditions(env, args)
    print(
        f"  partner: {len(conditions)} conditions x {args.episodes} episodes", file=log, flush=True
    )
    out: dict[str, list] = {}
    for partner, share in conditions:
        run = partner_env(env, partner, share)
        result = run_episodes(run, policy, identity, None, args.episodes, args.seed, args.chunk)
        for key, value in result.items():
            out.setdefault(key, []).append(float(value.mean()))
    return {k: np.asarray(v) for k, v in out.items()}


def combine(per_run: list[dict], episodes: int) -> dict:
    """Mean and standard error of each array: {key: list, key_se: list, key_per_run}. The
    error is over runs; for one run, the binomial error over its ``episodes``."""
    out = {}
    for key in per_run[0]:
        stack = np.stack([r[key] for r in per_run])
        mean = stack.mean(axis=0)
        if len(per_run) > 1:
            se = stack.std(axis=0, ddof=1) / math.sqrt(len(per_run))
        else:
            se = np.sqrt(mean * (1 - mean) / episodes)
        out[key] = mean.tolist()
        out[f"{key}_se"] = se.tolist()
        out[f"{key}_per_run"] = stack.tolist()
    return out


def plot_orientation(summary: dict, path: Path) -> None:
    """Two heatmaps (success at the end, at some step) over yaw x pitch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    angles = np.asarray(summary["angles_deg"])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), constrained_layout=True)
    for ax, key, title in zip(
        axes, ("success_final", "success"), ("success at the end", "success at some step")
    ):
        values = np.asarray(summary[key])
        image = ax.imshow(values, origin="lower", vmin=0, vmax=1, cmap="viridis")
        ax.set_xticks(range(angles.size), [f"{a:g}" for a in angles])
        ax.set_yticks(range(angles.size), [f"{a:g}" for a in angles])
        ax.set_xlabel("yaw of the target hand (degrees)")
        ax.set_ylabel("pitch of the target hand (degrees)")
        ax.set_title(title)
        for (i, j), v in np.ndenumerate(values):
            ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=7,
                    color="white" if v < 0.5 else "black")  # fmt: skip
    fig.colorbar(image, ax=axes, shrink=0.8, label="success rate")
    fig.suptitle(
        f"{summary['task']}: target hand turned ({summary['runs']} run(s), "
        f"{summary['episodes']} episodes per cell each)"
    )
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_motion(summary: dict, path: Path) -> None:
    """Success (at the end, at some step) against the target's speed, ± SE over runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    speeds = np.asarray(summary["speeds"])
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    for key, style, label in (
        ("success_final", "s-", "success at the end"),
        ("success", "o--", "success at some step"),
    ):
        ax.errorbar(speeds, summary[key], yerr=summary[f"{key}_se"], fmt=style, capsize=3,
                    label=label)  # fmt: skip
    ax.set_xlabel("speed of the target hand (m/s)")
    ax.set_ylabel("success rate")
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left")
    ax.set_title(
        f"{summary['task']}: moving target, turns every {summary['turn_period']} s "
        f"({summary['runs']} run(s))"
    )
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_sensing(summary: dict, path: Path) -> None:
    """Success at the end against the sensing error and against the action delay."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True, sharey=True)
    for ax, axis, xs, label in (
        (axes[0], "noise", summary["noise_mm"], "std of the observed target position (mm)"),
        (axes[1], "delay", summary["delays"], "action delay (control steps)"),
    ):
        for key, style, name in (
            ("success_final", "s-", "success at the end"),
            ("success", "o--", "success at some step"),
        ):
            values = summary[f"{axis}_{key}"]
            ax.errorbar(xs, values, yerr=summary[f"{axis}_{key}_se"], fmt=style, capsize=3,
                        label=name)  # fmt: skip
        ax.set_xlabel(label)
        ax.set_xticks(xs)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success rate")
    axes[0].legend(loc="lower left")
    fig.suptitle(f"{summary['task']}: imperfect sensing and actuation ({summary['runs']} run(s))")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_partner(summary: dict, path: Path) -> None:
    """Success against the partner model: bars with their standard errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = summary["conditions"]
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(1.6 * len(names) + 3, 4), constrained_layout=True)
    for offset, key, name in (
        (-0.2, "success_final", "at the end"),
        (0.2, "success", "at some step"),
    ):
        ax.bar(x + offset, summary[key], 0.4, yerr=summary[f"{key}_se"], capsize=3, label=name)
    ax.set_xticks(x, names)
    ax.set_ylim(0, 1.02)
    ax.set_ylabel("success rate")
    ax.legend(loc="lower left")
    ax.grid(alpha=0.3, axis="y")
    ax.set_title(f"{summary['task']}: static target vs recorded partner ({summary['runs']} run(s))")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def load_runs(args: RobustnessArgs) -> list[tuple]:
    """(run_dir, policy, env, epoch) per run; all of one task, else ValueError. The env is
    the task's scoring environment (``env.scoring_env``): the static partner that every
    sweep changes one condition of, whatever partner models a policy trained against."""
    loaded = []
    for run_dir in args.run_dirs:
        policy = policies.load_policy(Path(run_dir), eval_envs=args.chunk, best=args.best)
        # Every policy meets the same partner, whatever it trained against.
        scoring = env_lib.scoring_env(policy.single.config)
        if args.partner_motion not in (None, scoring.config.partner_motion):
            motion = dataclasses.replace(scoring.config, partner_motion=args.partner_motion)
            scoring = env_lib.env_for(motion)
        loaded.append((run_dir, policy.act, scoring, policy.epoch))
    tasks = {single.config.task for _, _, single, _ in loaded}
    if len(tasks) > 1:
        raise ValueError(f"the runs are of different tasks {sorted(tasks)}; give runs of one task")
    motions = {single.config.partner_motion for _, _, single, _ in loaded}
    if len(motions) > 1:
        raise ValueError(
            f"the runs' partners travel differently {sorted(motions)}; give --partner-motion"
        )
    return loaded


def main(argv: list[str] | None = None) -> int:
    args = tyro.cli(
        RobustnessArgs, args=sys.argv[1:] if argv is None else argv, description=__doc__
    )
    compile_cache.enable()
    try:
        check_args(args)
        runs = load_runs(args)
    except (checkpoint.CheckpointError, ValueError, FileNotFoundError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out or args.run_dirs[0])
    out.mkdir(parents=True, exist_ok=True)
    task = runs[0][2].config.task
    common = {
        "task": task,
        "runs": len(runs),
        "run_dirs": [str(r) for r in args.run_dirs],
        "checkpoint": {"kind": "best" if args.best else "latest", "epochs": [r[3] for r in runs]},
        "episodes": args.episodes,
        "seed": args.seed,
        "partner_motion": runs[0][2].config.partner_motion,
    }
    sweeps = SWEEPS[args.sweep]
    if "orientation" in sweeps:
        per_run = []
        for run_dir, policy, single, _ in runs:
            print(f"{run_dir}:", flush=True)
            per_run.append(orientation_sweep(single, policy, args))
        summary = common | {"angles_deg": angle_grid(args.max_angle_deg, args.angle_step_deg)}
        summary = summary | combine(per_run, args.episodes)
        summary["angles_deg"] = summary["angles_deg"].tolist()
        (out / f"{ORIENTATION_FILE}.json").write_text(json.dumps(summary, indent=1))
        plot_orientation(summary, out / f"{ORIENTATION_FILE}.png")
        centre = len(summary["angles_deg"]) // 2
        print(
            f"orientation: success at the end {np.mean(summary['success_final']):.2f} over "
            f"the grid, {summary['success_final'][centre][centre]:.2f} at the nominal pose; "
            f"{out / ORIENTATION_FILE}.json/.png"
        )
    if "motion" in sweeps:
        per_run = []
        for run_dir, policy, single, _ in runs:
            print(f"{run_dir}:", flush=True)
            per_run.append(motion_sweep(single, policy, args))
        summary = common | {
            "speeds": list(args.speeds),
            "turn_period": args.turn_period,
            "motion_box": list(args.motion_box),
        }
        summary = summary | combine(per_run, args.episodes)
        (out / f"{MOTION_FILE}.json").write_text(json.dumps(summary, indent=1))
        plot_motion(summary, out / f"{MOTION_FILE}.png")
        shown = ", ".join(
            f"{s:g} m/s {v:.2f}" for s, v in zip(args.speeds, summary["success_final"])
        )
        print(f"motion: success at the end {shown}; {out / MOTION_FILE}.json/.png")
    if "sensing" in sweeps:
        per_run = []
        for run_dir, policy, single, _ in runs:
            print(f"{run_dir}:", flush=True)
            per_run.append(sensing_sweep(single, policy, args))
        summary = common | {"noise_mm": list(args.noise_mm), "delays": list(args.delays)}
        summary = summary | combine(per_run, args.episodes)
        (out / f"{SENSING_FILE}.json").write_text(json.dumps(summary, indent=1))
        plot_sensing(summary, out / f"{SENSING_FILE}.png")
        noise = ", ".join(
            f"{n:g} mm {v:.2f}" for n, v in zip(args.noise_mm, summary["noise_success_final"])
        )
        delay = ", ".join(
            f"{d} steps {v:.2f}" for d, v in zip(args.delays, summary["delay_success_final"])
        )
        print(f"sensing: success at the end {noise}; delay {delay}; {out / SENSING_FILE}.json/.png")
    if "partner" in sweeps:
        per_run = []
        for run_dir, policy, single, _ in runs:
            print(f"{run_dir}:", flush=True)
            per_run.append(partner_sweep(single, policy, args))
        names = [
            "static" if p == "static" else f"recorded, share {v:g}"
            for p, v in partner_conditions(runs[0][2], args)
        ]
        summary = common | {"conditions": names, "partner_lag": list(runs[0][2].config.partner_lag)}
        summary = summary | combine(per_run, args.episodes)
        (out / f"{PARTNER_FILE}.json").write_text(json.dumps(summary, indent=1))
        plot_partner(summary, out / f"{PARTNER_FILE}.png")
        shown = ", ".join(f"{n} {v:.2f}" for n, v in zip(names, summary["success_final"]))
        print(f"partner: success at the end {shown}; {out / PARTNER_FILE}.json/.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
