"""Objective naturalness of trained policies: do they move like the humans they learnt from?

    python -m mjx_hands.naturalness RUN_OR_GRID [...] --out DIR [--variants full no_imitation]

For every policy's evaluation episodes (deterministic policy, the training's
randomisation), in the target palm's frame (where the demonstrations are):

* ``dtw``: root mean square distance (metres) of the agent's palm centre and five
  fingertips to the demonstration the episode started on, from its start step to the
  end of the demonstrated contact,
  along the dynamic-time-warping alignment of the two trajectories (18-dimensional
  points; ``dtaidistance``);
* ``jerk``: mean norm of the palm centre's jerk (third time derivative, m/s^3, by finite
  differences at the control period), next to the demonstrations' own at the same rate;
* ``path_ratio``: length of the palm's path over the straight distance from its start
  to its end (1: a straight reach);
* ``final_pose_error``: mean distance (metres) of the six points to their goals, the
  demonstrated final pose, at the last step.

A grid folder (``mjx_hands.experiments``) expands into its members; each variant's
metrics are the mean and standard error over its seeds, and the table says for each
task whether the metric ranks the imitation-trained policy as more natural than the one
without imitation, as the paper's raters did (its Table I: +0.26 handshake, +1.44 hand
clap, +0.07 E.T. on -2..2 in favour of imitation). Writes ``naturalness.csv``/``.json``
and ``naturalness.md`` to ``--out``.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import math
import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import tyro

from mjx_hands import checkpoint, compile_cache, grids, policies, rollouts, statistics, tasks
from mjx_hands import env as env_lib

METRICS = ("dtw", "jerk", "path_ratio", "final_pose_error")
"""Per-episode metrics; lower is more natural (closer to the demonstrations) for all."""
REFERENCES = ("demo_jerk", "demo_path_ratio")
"""The demonstrations' own jerk and path ratio over the same segments, for scale."""
MIN_DIRECT_PATH = 0.01  # metres: shorter start-to-end distances leave path_ratio undefined


@dataclasses.dataclass(frozen=True)
class NaturalnessArgs:
    """How natural trained policies move, measured against the demonstrations."""

    runs: Annotated[tuple[str, ...], tyro.conf.Positional, tyro.conf.arg(metavar="RUN_OR_GRID")]
    """Run folders (train.py) or experiment-grid folders."""
    out: str
    """Output folder of the table."""
    variants: tuple[str, ...] = ("full", "no_imitation")
    """Of a grid, the variants to measure."""
    episodes: int = 64
    """Evaluation episodes per policy."""
    best: bool = False
    """Use each run's best-evaluated policy instead of its latest checkpoint."""
    seed: int = 12345
    """Seed of the evaluation episodes (the same for every policy)."""


# ----------------------------------------------------------------- the metrics
def dtw_rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS distance of trajectories ``a`` (n, d) and ``b`` (m, d) along their DTW alignment:
    sqrt(sum of squared point distances on the optimal warping path / path length)."""
    from dtaidistance import dtw_ndim

    a, b = np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64)
    path = dtw_ndim.warping_path(a, b)
    squared = sum(float(np.sum((a[i] - b[j]) ** 2)) for i, j in path)
    return math.sqrt(squared / len(path))


def mean_jerk(positions: np.ndarray, dt: float) -> float:
    """Mean norm of the third finite difference of ``positions`` (T, 3) over dt^3, m/s^3."""
    jerk = np.diff(positions, n=3, axis=0) / dt**3
    return float(np.linalg.norm(jerk, axis=-1).mean())


def path_ratio(positions: np.ndarray) -> float:
    """Path length of ``positions`` (T, 3) over its start-to-end distance (NaN when that is
    under ``MIN_DIRECT_PATH``: a hand that ends where it began has no direct path)."""
    length = np.linalg.norm(np.diff(positions, axis=0), axis=-1).sum()
    direct = np.linalg.norm(positions[-1] - positions[0])
    return float(length / direct) if direct >= MIN_DIRECT_PATH else math.nan


def demo_at_control_rate(actor_points: np.ndarray, fps: float, dt: float) -> np.ndarray:
    """A demonstration's actor points (F, 6, 3) at capture rate ``fps`` resampled (linear
    interpolation) at the control steps k·dt of its window: (K, 6, 3)."""
    frames = actor_points.shape[0]
    times = np.arange(0.0, (frames - 1) / fps + 1e-9, dt) * fps  # fractional frame indices
    flat = actor_points.reshape(frames, -1)
    out = np.stack([np.interp(times, np.arange(frames), flat[:, c]) for c in range(flat.shape[1])])
    return out.T.reshape(times.size, *actor_points.shape[1:])


def episode_metrics(
    points: np.ndarray, goals: np.ndarray, demo: np.ndarray, dt: float
) -> dict[str, float]:
    """Metrics of one episode.

    Args:
      points: (T+1, 6, 3) the agent's palm centre + fingertips, target palm frame.
      goals: (6, 3) their goals at the last step, same frame.
      demo: (K, 6, 3) the actor's points of the episode's demonstration from its start
        step to the end of its contact, control rate, same frame.
    """
    # Per point: the row distance of 6 stacked points is sqrt(6) times their RMS distance.
    row_rms = dtw_rms(points.reshape(len(points), -1), demo.reshape(len(demo), -1))
    return {
        "dtw": row_rms / math.sqrt(points.shape[1]),
        "jerk": mean_jerk(points[:, 0], dt),
        "path_ratio": path_ratio(points[:, 0]),
        "final_pose_error": float(np.linalg.norm(points[-1] - goals, axis=-1).mean()),
    }


# -------------------------------------------------------------- on a policy
@functools.lru_cache(maxsize=4)
def hand_points_record(single):
    """state -> what the metrics read at every step: the hand's points and goals in the
    target palm's frame, the episode's demonstration and start step. One object per env,
    so ``rollouts`` compiles once for every policy of one program."""

    def record(state):
        ep = state.info["episode"]
        return {
            "points": single.points_in_target_frame(state),
            "goals": (ep.goal_points - ep.target_pos) @ ep.target_rot,
            "demo": ep.demo,
            "start": ep.start_step,
        }

    return record


def policy_metrics(single, policy, episodes: int, seed: int) -> dict[str, float]:
    """Mean of each metric over ``episodes`` evaluation episodes of ``policy``, plus
    ``REFERENCES``: jerk and path ratio of the demonstration segments they are compared
    with (the demonstration the episode started on, from its start step to the end of
    its demonstrated contact), at the same rate."""

    keys = rollouts.episode_keys(seed, episodes)
    trajectory = rollouts.rollout(single, policy, keys, extra=hand_points_record(single))
    dt = single.config.control_dt
    demos = [demo_at_control_rate(d.actor_points, d.fps, dt) for d in single.demos]
    contact_end = [math.floor(d.contact_end / d.fps / dt) for d in single.demos]
    rows = []
    for i in range(episodes):
        index, start = int(trajectory["demo"][0, i]), int(trajectory["start"][0, i])
        demo = demos[index][start : max(contact_end[index], start + 4) + 1]
        row = episode_metrics(trajectory["points"][:, i], trajectory["goals"][-1, i], demo, dt)
        row["demo_jerk"] = mean_jerk(demo[:, 0], dt)
        row["demo_path_ratio"] = path_ratio(demo[:, 0])
        rows.append(row)
    return {k: float(np.nanmean([r[k] for r in rows])) for k in rows[0]}


def expand(paths: tuple[str, ...], variants: tuple[str, ...]) -> list[dict]:
    """``{'label', 'variant', 'run_dir'}`` per policy: grid folders give their members of
    ``variants`` (label: the variant), run folders themselves (label: the folder name)."""
    out = []
    for path in map(Path, paths):
        if (path / grids.GRID_FILE).is_file():
            grid = json.loads((path / grids.GRID_FILE).read_text())
            members = [m for m in grid["members"] if m["variant"] in variants]
            if not members:
                raise ValueError(
                    f"{path}: no member of variants {list(variants)} (it has {grid['variants']})"
                )
            out += [
                {"label": m["variant"], "variant": m["variant"], "run_dir": path / m["run_dir"]}
                for m in members
            ]
        elif path.is_dir():
            label = f"{path.parent.name}/{path.name}"
            out.append({"label": label, "variant": None, "run_dir": path})
        else:
            raise FileNotFoundError(f"{path}: no such run or grid folder")
    return out


def table(per_policy: list[dict]) -> list[dict]:
    """One row per (task, label): n, mean and SE of each metric over the policies."""
    rows = []
    for key in dict.fromkeys((p["task"], p["label"]) for p in per_policy):
        group = [p for p in per_policy if (p["task"], p["label"]) == key]
        row = {"task": key[0], "label": key[1], "n": len(group)}
        for metric in (*METRICS, *REFERENCES):
            row[metric], row[f"{metric}_se"] = statistics.mean_se([g[metric] for g in group])
        rows.append(row)
    return rows


def rankings(rows: list[dict], per_policy: list[dict]) -> list[dict]:
    """Per task with both 'full' and 'no_imitation': for each metric, whether it calls the
    imitation policy more natural (lower), Welch's p, and the raters' verdict."""
    out = []
    for task in dict.fromkeys(r["task"] for r in rows):
        values = {
            label: [p for p in per_policy if p["task"] == task and p["label"] == label]
            for label in ("full", "no_imitation")
        }
        if not all(values.values()):
            continue
        raters = tasks.spec(task).paper_raters_score
        for metric in METRICS:
            a = [p[metric] for p in values["full"]]
            b = [p[metric] for p in values["no_imitation"]]
            _, p_value = statistics.welch(a, b)
            out.append(
                {
                    "task": task,
                    "metric": metric,
                    "full": float(np.nanmean(a)),
                    "no_imitation": float(np.nanmean(b)),
                    "imitation_more_natural": bool(np.nanmean(a) < np.nanmean(b)),
                    "p": p_value,
                    "raters": raters,
                    # A task the paper's raters never saw agrees with nobody.
                    "agrees_with_raters": None
                    if raters is None
                    else bool(np.nanmean(a) < np.nanmean(b)) == (raters > 0),
                }
            )
    return out


def _signed(value: float | None) -> str:
    return "–" if value is None else f"{value:+.2f}"


def _yes_no(value: bool | None) -> str:
    return "–" if value is None else ("yes" if value else "no")


def markdown(rows: list[dict], ranks: list[dict]) -> str:
    lines = [
        "| task | policy | n | DTW to demo (cm) | palm jerk (m/s³) | demos' jerk | path ratio "
        + "| demos' path ratio | final pose error (cm) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:

        def f(key: str, scale: float = 1.0, digits: int = 2, r=r) -> str:
            return f"{scale * r[key]:.{digits}f} ± {scale * r[key + '_se']:.{digits}f}"

        lines.append(
            f"| {r['task']} | {r['label']} | {r['n']} | {f('dtw', 100, 1)} | {f('jerk', 1, 1)} "
            f"| {r['demo_jerk']:.1f} | {f('path_ratio')} | {r['demo_path_ratio']:.2f} "
            f"| {f('final_pose_error', 100, 1)} |"
        )
    if ranks:
        lines += [
            "",
            "| task | metric | full | no imitation | imitation more natural? | p (Welch) "
            + "| raters (Table I) | agrees |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for k in ranks:
            lines.append(
                f"| {k['task']} | {k['metric']} | {k['full']:.4g} | {k['no_imitation']:.4g} | "
                f"{'yes' if k['imitation_more_natural'] else 'no'} | {k['p']:.3g} | "
                f"{_signed(k['raters'])} | {_yes_no(k['agrees_with_raters'])} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    args = tyro.cli(
        NaturalnessArgs, args=sys.argv[1:] if argv is None else argv, description=__doc__
    )
    compile_cache.enable()
    try:
        if args.episodes < 1:
            raise ValueError(f"--episodes {args.episodes} must be positive")
        runs = expand(args.runs, args.variants)
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    per_policy = []
    for entry in runs:
        try:
            loaded = policies.load_policy(entry["run_dir"], eval_envs=args.episodes, best=args.best)
        except (checkpoint.CheckpointError, ValueError, FileNotFoundError) as err:
            print(f"error: {entry['run_dir']}: {err}", file=sys.stderr)
            return 2
        config, epoch = loaded.config, loaded.epoch
        single = env_lib.scoring_env(loaded.single.config)  # the same partner for every policy
        metrics = policy_metrics(single, loaded.act, args.episodes, args.seed)
        per_policy.append(
            {
                "task": config.env.task,
                "label": entry["label"],
                "run_dir": str(entry["run_dir"]),
                "epoch": epoch,
            }
            | metrics
        )
        print(
            f"{entry['run_dir']}: "
            + ", ".join(f"{k} {metrics[k]:.4g}" for k in (*METRICS, *REFERENCES)),
            flush=True,
        )
    rows = table(per_policy)
    ranks = rankings(rows, per_policy)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with (out / "naturalness.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    record = {"episodes": args.episodes, "seed": args.seed, "policies": per_policy}
    record |= {"table": rows, "rankings": ranks}
    (out / "naturalness.json").write_text(json.dumps(record, indent=1))
    text = markdown(rows, ranks)
    (out / "naturalness.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
