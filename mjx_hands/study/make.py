"""Render the video pairs of a blind rating study.

    python -m mjx_hands.study make --out STUDY_DIR \\
        --runs IMITATION_RUN NO_IMITATION_RUN [IMITATION_RUN NO_IMITATION_RUN ...]

Each pair of runs (one task; the first trained with the imitation reward, the second
without) gives ``--pairs-per-task`` regular pairs and ``--non-smooth-per-task`` pairs
whose start is far from every demonstration (the palm put ``--far-start-noise`` metres
off the demonstrated start, the fingers ``--far-joint-noise`` radians off). Both videos
of a pair show the same episode (same key: demonstration, target position, start pose)
under the two policies, each in its own run's environment. Which policy plays on the
left is drawn at random per pair; pairs are shuffled; file names are ``p01_L.mp4`` and
``p01_R.mp4``; what is where is written only to ``key.json``, which the server never
serves.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path
from typing import Literal

import jax
import numpy as np
import tyro

from mjx_hands import checkpoint, compile_cache, policies, render, rollouts
from mjx_hands import env as env_lib
from mjx_hands.study import layout


@dataclasses.dataclass(frozen=True)
class MakeArgs:
    """Render paired videos of policies with and without imitation for a rating study."""

    out: str
    """Study folder to create (must not hold a study yet)."""
    runs: tuple[str, ...]
    """Pairs of run folders, imitation first: IMITATION_RUN NO_IMITATION_RUN [...]."""
    name: str = "naturalness"
    """Name of the study (shown to no rater; in study.json)."""
    pairs_per_task: int = 3
    """Regular pairs per task: starts on the demonstrations, as in training."""
    non_smooth_per_task: int = 1
    """Pairs per task whose start is far from every demonstration."""
    far_start_noise: float = 0.1
    """Std (metres) of the start palm's offset in non-smooth pairs (training: 0.02)."""
    far_joint_noise: float = 0.3
    """Std (radians) of the start fingers' offset in non-smooth pairs (training: 0.05)."""
    best: bool = False
    """Use each run's best-evaluated policy instead of its latest checkpoint."""
    seed: int = 0
    """Seed of the episodes, the left/right draw and the pair order."""
    camera: Literal["side", "top"] = "side"
    """Scene camera."""
    width: int = 512
    """Video width in pixels (a multiple of 16 keeps codecs from resizing)."""
    height: int = 384
    """Video height in pixels."""


def check_args(args: MakeArgs) -> None:
    problems = []
    if not args.runs or len(args.runs) % 2:
        problems.append(
            f"--runs takes pairs IMITATION_RUN NO_IMITATION_RUN; got {len(args.runs)} folder(s)"
        )
    if args.pairs_per_task < 0 or args.non_smooth_per_task < 0:
        problems.append("--pairs-per-task and --non-smooth-per-task must be >= 0")
    elif args.pairs_per_task + args.non_smooth_per_task == 0:
        problems.append("no pairs to make: raise --pairs-per-task or --non-smooth-per-task")
    if not (args.far_start_noise >= 0 and args.far_joint_noise >= 0):
        problems.append("--far-start-noise and --far-joint-noise must be >= 0")
    out = Path(args.out)
    if (out / layout.STUDY_FILE).exists():
        problems.append(f"{out} already holds a study ({layout.STUDY_FILE}); choose a new --out")
    if problems:
        raise ValueError("; ".join(problems))


def episodes_of(
    single, policy, count: int, key: jax.Array, far: tuple[float, float] | None
) -> tuple[env_lib.HandInteractionEnv, dict[str, np.ndarray]]:
    """(env, rollout arrays) of ``count`` episodes of ``policy``; with ``far`` = (palm
    metres, finger radians), in a copy of the environment whose starts are that noisy."""
    if far is not None:
        config = dataclasses.replace(
            single.config, start_position_noise=far[0], start_joint_noise=far[1]
        )
        single = env_lib.HandInteractionEnv(config)
    return single, rollouts.rollout(single, policy, jax.random.split(key, count))


def make(args: MakeArgs, log=None) -> layout.Study:
    """Render every pair into ``args.out`` and write the study; returns it as read back."""
    check_args(args)
    out = Path(args.out)
    (out / layout.VIDEOS_DIR).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    clips = []  # (task, kind, seed, {policy: (env, trajectory, episode)})
    for index in range(0, len(args.runs), 2):
        loaded = {}
        for policy_name, run_dir in zip(layout.POLICIES, args.runs[index : index + 2]):
            policy = policies.load_policy(Path(run_dir), eval_envs=1, best=args.best)
            loaded[policy_name] = (policy.config, policy.single, policy.act)
        tasks = {config.env.task for config, _, _ in loaded.values()}
        if len(tasks) > 1:
            raise ValueError(f"--runs {args.runs[index : index + 2]} are of different tasks")
        task = tasks.pop()
        for kind, count, far in (
            ("regular", args.pairs_per_task, None),
            ("non_smooth", args.non_smooth_per_task, (args.far_start_noise, args.far_joint_noise)),
        ):
            if count == 0:
                continue
            batch = len(clips)  # episodes of a batch: keys split from fold_in(seed, batch)
            key = jax.random.fold_in(jax.random.PRNGKey(args.seed), batch)
            rendered = {
                name: episodes_of(single, policy, count, key, far)
                for name, (_, single, policy) in loaded.items()
            }
            for episode in range(count):
                clips.append((task, kind, batch, rendered, episode))
            print(f"{task}: {count} {kind} pair(s) simulated", file=log, flush=True)

    order = rng.permutation(len(clips))
    pairs, key_entries = [], {}
    for number, clip_index in enumerate(order):
        task, kind, batch, rendered, episode = clips[clip_index]
        pid = layout.pair_id(number)
        left = layout.POLICIES[int(rng.integers(2))]
        sides = {"left": left, "right": next(p for p in layout.POLICIES if p != left)}
        for side, policy_name in sides.items():
            single, trajectory = rendered[policy_name]
            shown = {k: trajectory[k][:, episode : episode + 1] for k in render.VIDEO_KEYS}
            render.render_video(
                single,
                shown,
                out / layout.video_path(pid, side),
                args.camera,
                args.width,
                args.height,
                fps=1.0 / single.config.control_dt,
            )
        pairs.append(
            {
                "id": pid,
                "task": task,
                "kind": kind,
                "left": layout.video_path(pid, "left"),
                "right": layout.video_path(pid, "right"),
            }
        )
        key_entries[pid] = {
            "left": left,
            "seed": args.seed,
            "episode": episode,
            "batch": batch,
            "runs": list(args.runs),
        }
        print(f"{pid}: {task} {kind} rendered", file=log, flush=True)
    return layout.write_study(out, args.name, pairs, key_entries)


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")
    args = tyro.cli(MakeArgs, args=sys.argv[1:] if argv is None else argv, description=__doc__)
    compile_cache.enable()
    try:
        study = make(args)
    except (checkpoint.CheckpointError, ValueError, FileNotFoundError, FileExistsError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(
        f"study {study.name!r}: {len(study.pairs)} pairs in {args.out}; "
        f"serve it with: python -m mjx_hands.study serve {args.out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
