"""How policies hold contact with a moving partner: per run and target speed, the share of
steps in contact after the first contact, how often contact starts or ends, and success
at the end.

    python -m benchmarks.contact_hold LABEL=RUN_DIR [LABEL=RUN_DIR ...] \
        --out benchmarks/partners/contact_hold_handclap.json

Every policy is scored as ``mjx_hands.robustness``'s motion sweep scores it (against the
static partner of its task, carried at each ``--speeds`` in a random direction that
turns every 0.5 s, within 10 cm of its nominal place; the same episodes of evaluate's
seed for every policy and speed). "In contact" is the task's success condition (every
required sensor group touching at once) at a control step. A policy that reaches
contact and holds it has one change (the start of contact) and a share near 1; one that
touches and lets go, again and again, has many.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks import machine
from mjx_hands import env as env_lib
from mjx_hands import policies, robustness, rollouts


def hold_statistics(success: np.ndarray) -> dict[str, float]:
    """Statistics of a (T, n) bool array of per-step success over n episodes."""
    reached = success.any(axis=0)
    first = success.argmax(axis=0)
    after = [success[f:, i].mean() for i, f in enumerate(first) if reached[i]]
    changes = (np.diff(success.astype(np.int8), axis=0) != 0).sum(axis=0)
    return {
        "success_final": float(success[-1].mean()),
        "success_some_step": float(reached.mean()),
        "first_contact_step_median": float(np.median(first[reached])) if reached.any() else None,
        "share_in_contact_after_first": float(np.mean(after)) if after else None,
        "contact_changes_median": float(np.median(changes)),
        "share_in_contact_last_10_steps": float(success[-10:].mean()),
    }


def measure(run_dir: str, speeds: list[float], episodes: int, seed: int) -> dict:
    """{speed: hold statistics} of one run's policy."""
    loaded = policies.load_policy(run_dir, eval_envs=episodes)
    scoring = env_lib.scoring_env(loaded.single.config)
    sweep = robustness.RobustnessArgs  # the motion sweep's own turns and box
    moving = robustness.moving_target_env(scoring, sweep.turn_period, sweep.motion_box)
    reset = robustness.sweep_reset(moving, moving=True)
    keys = rollouts.episode_keys(seed, episodes)
    tilts = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (episodes, 1))
    out = {}
    for speed in speeds:
        trajectory = rollouts.rollout(
            moving, loaded.act, keys, reset=reset,
            reset_args=(tilts, np.full(episodes, speed, np.float32)),
        )  # fmt: skip
        out[f"{speed:g}"] = hold_statistics(trajectory["success"] > 0.5)
    return {"task": loaded.config.env.task, "run_dir": run_dir, "speeds": out}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", help="LABEL=RUN_DIR per policy")
    parser.add_argument("--speeds", type=float, nargs="+", default=[0.0, 0.2], help="m/s")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=rollouts.EVAL_SEED)
    parser.add_argument("--out")
    args = parser.parse_args(argv)
    runs = {}
    for spec in args.runs:
        label, sep, run_dir = spec.partition("=")
        if not sep or not label or not run_dir:
            parser.error(f"{spec!r}: expected LABEL=RUN_DIR")
        runs[label] = measure(run_dir, args.speeds, args.episodes, args.seed)
        for speed, stats in runs[label]["speeds"].items():
            print(f"{label} at {speed} m/s: " + ", ".join(
                f"{k} {v:.2f}" for k, v in stats.items() if v is not None))  # fmt: skip
    record = machine.provenance("benchmarks.contact_hold", argv) | {
        "episodes": args.episodes, "seed": args.seed, "runs": runs,
    }  # fmt: skip
    machine.write_record(args.out, record)
    return record


if __name__ == "__main__":
    main()
