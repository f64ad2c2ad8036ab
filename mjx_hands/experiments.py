"""Experiment grids: seeds x reward variants of one task trained as one population,
and the paper's Fig. 4 comparison reported from them.

    python -m mjx_hands.experiments run --task et --seeds 5 --run-dir runs/fig4-et \\
        --variants full baseline1 baseline2 no_imitation
    python -m mjx_hands.experiments run --run-dir runs/fig4-et --resume
    python -m mjx_hands.experiments report runs/fig4-* --out benchmarks/fig4
    python -m mjx_hands.experiments archive runs/fig4-et benchmarks/fig4/et --log fig4-et.log

(installed: ``mjx-hands-experiments``). ``run`` trains every member together in one
compiled epoch (:func:`mjx_hands.training.run_population`); members differ only in
their seed and reward variant (data, not program). Each member is an ordinary run
directory, ``RUN_DIR/<variant>/seed<k>``, that ``mjx_hands.evaluate`` opens;
``RUN_DIR/grid.json`` records the grid so that ``--resume`` continues all of it.
Every other option is ``train.py``'s (preset, epochs, sizes, ``--ddpg.*``).

``report`` reads grids (any tasks) and writes ``fig4.png`` (success at the end of the
episode, mean +- standard error over seeds, per variant; one panel per task, against
environment steps and wall clock), ``summary.csv``/``summary.json`` (final and best
success per variant) and ``statements.json``/``.md``: the paper's four findings, each
held / not held / not significant with the numbers behind it.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import tyro

from mjx_hands import (
    cli,
    compile_cache,
    learners,
    reward_params,
    run_directory,
    train_cli,
    train_config,
    training,
)
from mjx_hands import cluster as cluster_lib
from mjx_hands.grids import GRID_FILE, HEADLINE, load_grid, read_rows
from mjx_hands.statistics import ALPHA, holm, mean_se, welch

VARIANTS = reward_params.VARIANTS  # the one vocabulary of reward variants
Variant = Literal[tuple(VARIANTS)]
FIG4_VARIANTS = ("full", "baseline1", "baseline2", "no_imitation")
HIGH_SUCCESS = 0.8  # "a high success rate" (statement 3)


# ------------------------------------------------------------------------- run
@dataclasses.dataclass(frozen=True)
class GridConfig:
    """Train seeds x reward variants of one task together (one compiled program)."""

    variants: tuple[Variant, ...] = FIG4_VARIANTS
    """Reward variants of the grid."""
    seeds: int = 5
    """Seeds per variant: --seed, --seed + 1, ..."""
    train: Annotated[train_config.TrainConfig, tyro.conf.arg(name="")] = train_config.TrainConfig()
    """Everything else, as train.py takes it."""
    cluster: cluster_lib.ClusterConfig = cluster_lib.ClusterConfig()
    """Spread the grid's devices over processes and hosts (README, "Running on a
    cluster"); not part of the grid's record: a grid resumes on any layout of the same
    number of devices."""


def members(grid: GridConfig) -> list[tuple[str, Any]]:
    """(variant, run config) of every member of ``grid``, variant-major."""
    base = grid.train
    run_dir = Path(base.run_dir)
    out = []
    for variant in grid.variants:
        chosen = VARIANTS[variant]
        env = dataclasses.replace(base.env, reward=chosen.reward, imitation=chosen.imitation)
        for seed in range(base.seed, base.seed + grid.seeds):
            config = dataclasses.replace(
                base,
                env=env,
                seed=seed,
                run_dir=str(run_dir / variant / f"seed{seed}"),
            )
            out.append((variant, config))
    return out


def _check_grid(grid: GridConfig) -> None:
    base = grid.train
    problems = []
    if base.run_dir is None:
        problems.append("--run-dir is required (the grid's folder)")
    if not grid.variants:
        problems.append("--variants needs at least one variant")
    if len(set(grid.variants)) != len(grid.variants):
        problems.append(f"--variants repeats a variant: {' '.join(grid.variants)}")
    if grid.seeds < 1:
        problems.append(f"--seeds must be positive, got {grid.seeds}")
    if base.env.reward != "full" or not base.env.imitation:
        problems.append("--reward/--no-imitation do not apply to a grid; name --variants instead")
    if base.algo in learners.REGISTRY and not learners.entry(base.algo).in_training_loop:
        problems.append(
            f"grids train the learners of the project's loop "
            f"({', '.join(learners.loop_learners())}); --algo {base.algo} has its own loop"
        )
    if problems:
        raise ValueError("; ".join(problems))


def _grid_default(argv: list[str]) -> GridConfig:
    """The grid the command line overrides: a resumed grid's own, else the preset's."""
    run_dir = train_cli.option(argv, "--run-dir") or train_cli.option(argv, "--run_dir")
    if "--resume" in argv and run_dir:
        path = Path(run_dir) / GRID_FILE
        if not path.is_file():
            raise FileNotFoundError(
                f"--resume: no grid to continue in {run_dir} ({GRID_FILE} missing)"
            )
        try:
            saved = json.loads(path.read_text())
            train = dataclasses.replace(train_config.config_from_json(saved["train"]), resume=False)
            return GridConfig(variants=tuple(saved["variants"]), seeds=saved["seeds"], train=train)
        except (json.JSONDecodeError, KeyError, TypeError) as err:
            raise ValueError(f"{path} is not a grid record this version reads: {err!r}") from err
    return GridConfig(train=train_cli.preset_default(argv))


def run_grid(grid: GridConfig, out=None, env_factory=None) -> list[dict[str, Any]]:
    """Train ``grid``; returns each member's summary (with its ``variant``). Progress goes
    to ``out`` (None: stdout) from process 0 only."""
    _check_grid(grid)
    out = cluster_lib.progress_stream(out)
    pairs = members(grid)
    run_dir = Path(grid.train.run_dir)
    record = {
        "task": grid.train.env.task,
        "variants": list(grid.variants),
        "seeds": grid.seeds,
        "members": [
            {"variant": v, "seed": c.seed, "run_dir": str(Path(c.run_dir).relative_to(run_dir))}
            for v, c in pairs
        ],
        "train": train_config.config_to_json(dataclasses.replace(grid.train, resume=False)),
        "processes": cluster_lib.processes(),  # of the last (re)start, for the record
    }
    if grid.train.resume:
        saved = json.loads((run_dir / GRID_FILE).read_text())
        if saved["members"] != record["members"]:
            raise ValueError(
                f"--resume: {run_dir} holds another grid ({len(saved['members'])} members of "
                f"{', '.join(saved['variants'])}); resume it without --variants/--seeds/--seed"
            )
    elif (run_dir / GRID_FILE).exists() and any(
        (Path(c.run_dir) / "config.json").exists() for _, c in pairs
    ):
        raise FileExistsError(
            f"{run_dir} already holds a grid; pass --resume to continue it or choose another --run-dir"
        )
    print(
        f"grid: {grid.train.env.task}, {len(grid.variants)} variants x {grid.seeds} seeds = "
        f"{len(pairs)} runs trained together",
        file=out,
        flush=True,
    )
    # Refusals (existing runs, resume mismatches) come before anything is written; every
    # process checks every member, so all refuse alike.
    for _, config in pairs:
        run_directory.RunDirectory(config).check()
    cluster_lib.barrier("grid checked")
    if cluster_lib.is_primary():
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / GRID_FILE).write_text(json.dumps(record, indent=2))
    labels = [v for v, _ in pairs]
    summaries = training.run_population([c for _, c in pairs], out, env_factory, labels=labels)
    return [s | {"variant": v} for s, (v, _) in zip(summaries, pairs)]


RUN_USAGE = """Train an experiment grid (seeds x reward variants of one task) in one program.

    python -m mjx_hands.experiments run --task handshake --seeds 5 --run-dir runs/fig4-handshake
    python -m mjx_hands.experiments run --run-dir runs/fig4-handshake --resume

Each member is a run directory RUN_DIR/<variant>/seed<k> (evaluate opens it); the
progress line shows each variant's mean evaluation success at the end of the episode."""


def run_main(argv: list[str]) -> int:
    def start() -> tuple[list[dict[str, Any]], GridConfig]:
        if "--help" not in argv and "-h" not in argv:  # before the preset asks for devices
            cluster_lib.join(cluster_lib.early_config(argv))
        default = _grid_default(argv)
        grid = tyro.cli(GridConfig, default=default, args=argv, description=RUN_USAGE)
        compile_cache.enable()
        return run_grid(grid), grid

    result, code = train_cli.reported(start)
    if code:
        return code
    summaries, grid = result
    if not cluster_lib.is_primary():
        return 0  # process 0 reports (every process holds the same evaluations)
    by_variant: dict[str, list[float]] = {}
    for s in summaries:
        by_variant.setdefault(s["variant"], []).append(s["final_eval"].get(HEADLINE, math.nan))
    shown = ", ".join(
        f"{v} {mean_se(x)[0]:.2f} +- {mean_se(x)[1]:.2f}" for v, x in by_variant.items()
    )
    print(f"done ({summaries[0]['stop_reason']}): success at the end, mean +- SE: {shown}")
    print(f"report: python -m mjx_hands.experiments report {grid.train.run_dir}")
    return 0


# ---------------------------------------------------------------------- report
def merge_grids(grids: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Grids of one task and profile as one (e.g. a grid trained in chunks of seeds), in
    first-seen order; a (variant, seed) that two of them hold is an error naming both."""
    merged: dict[tuple[str, str], dict[str, Any]] = {}
    for grid in grids:
        key = (grid["task"], grid.get("profile", "project"))
        if key not in merged:
            merged[key] = grid | {"members": list(grid["members"]), "dirs": [grid["dir"]]}
            continue
        into = merged[key]
        held = {(m["variant"], m["seed"]): m["source"] for m in into["members"]}
        for m in grid["members"]:
            if (m["variant"], m["seed"]) in held:
                raise ValueError(
                    f"{m['variant']} seed {m['seed']} of {key[0]} ({key[1]} profile) is in "
                    f"both {held[(m['variant'], m['seed'])]} and {grid['dir']}"
                )
            into["members"].append(m)
        into["dirs"].append(grid["dir"])
        into["dir"] = ", ".join(into["dirs"])
    return list(merged.values())


def authors_epochs(task: str, env_steps: np.ndarray) -> np.ndarray:
    """Env steps per run in the authors' epochs: 50 cycles x 2 episodes of T steps."""
    from mjx_hands import tasks

    return np.asarray(env_steps) / (100 * tasks.spec(task).episode_length)


def curves(grid: dict[str, Any], key: str = HEADLINE) -> dict[str, dict[str, np.ndarray]]:
    """Per variant, mean and SE of ``key`` over seeds at each evaluation epoch that every
    seed reached: ``{variant: {'epoch', 'env_steps', 'wall_seconds', 'mean', 'se', 'n'}}``."""
    out = {}
    variants = dict.fromkeys(m["variant"] for m in grid["members"])
    for variant in variants:
        runs = [m["evals"] for m in grid["members"] if m["variant"] == variant and m["evals"]]
        if not runs:
            continue
        epochs = sorted(set.intersection(*[{r["epoch"] for r in evals} for evals in runs]))
        by_epoch = [{r["epoch"]: r for r in evals} for evals in runs]
        stats = [mean_se([b[e].get(key, math.nan) for b in by_epoch]) for e in epochs]
        out[variant] = {
            "epoch": np.asarray(epochs),
            "env_steps": np.asarray(
                [np.mean([b[e]["train/env_steps"] for b in by_epoch]) for e in epochs]
            ),
            "wall_seconds": np.asarray(
                [
                    np.mean([b[e].get("time/wall_seconds", math.nan) for b in by_epoch])
                    for e in epochs
                ]
            ),
            "mean": np.asarray([s[0] for s in stats]),
            "se": np.asarray([s[1] for s in stats]),
            "n": len(runs),
        }
    return out


SUMMARY_KEYS = {
    "success_end": HEADLINE,
    "success_some_step": "eval/success",
    "fingertip_goal_distance": "eval/final_fingertip_goal_distance",
    "palm_goal_distance": "eval/final_palm_goal_distance",
}


def summarize(grids: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (task, variant): n seeds, the last evaluation's figures (mean, SE and
    the per-seed values) and the best success at the end over each seed's evaluations."""
    rows = []
    for grid in grids:
        variants = dict.fromkeys(m["variant"] for m in grid["members"])
        for variant in variants:
            runs = [m for m in grid["members"] if m["variant"] == variant and m["evals"]]
            if not runs:
                continue
            row: dict[str, Any] = {
                "task": grid["task"],
                "profile": grid.get("profile", "project"),
                "variant": variant,
                "n_seeds": len(runs),
                "seeds": [m["seed"] for m in runs],
                "final_epoch": min(m["evals"][-1]["epoch"] for m in runs),
                "final_env_steps": float(
                    np.mean([m["evals"][-1]["train/env_steps"] for m in runs])
                ),
            }
            for name, key in SUMMARY_KEYS.items():
                values = [m["evals"][-1].get(key, math.nan) for m in runs]
                row[f"final_{name}"], row[f"final_{name}_se"] = mean_se(values)
                row[f"final_{name}_values"] = values
            best = [max(r[HEADLINE] for r in m["evals"]) for m in runs]
            row["best_success_end"], row["best_success_end_se"] = mean_se(best)
            row["best_success_end_values"] = best
            rows.append(row)
    return rows


def _lookup(summary: list[dict[str, Any]], task: str, variant: str) -> dict[str, Any] | None:
    """``summary``'s row of (task, variant); ``summary`` holds one profile."""
    return next((r for r in summary if r["task"] == task and r["variant"] == variant), None)


def _corrected(judged: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``judged`` with every Welch test's Holm-adjusted p (``p_holm``) over the family of
    all of them, and each statement's verdict under it (``verdict_holm``)."""
    tests = [t for s in judged for t in s["tests"] if "p" in t]
    for t, adjusted in zip(tests, holm([t["p"] for t in tests])):
        t["p_holm"] = adjusted
        if t["verdict"] in ("held", "not held") and not adjusted < ALPHA:
            t["verdict_holm"] = "not significant"
        else:
            t["verdict_holm"] = t["verdict"]
    for s in judged:
        parts = [t for t in s["tests"] if "verdict" in t]
        for t in parts:
            t.setdefault("verdict_holm", t["verdict"])  # untested parts
        if not any("p" in t for t in parts):
            s["verdict_holm"] = s["verdict"]  # statement 3 is one interval, no family
        elif s["statement"].startswith("4."):  # held when no test is significant
            tested = [t for t in parts if t["verdict"] != "not tested"]
            s["verdict_holm"] = (
                s["verdict"]
                if not tested
                else "held"
                if all(t["verdict_holm"] == "not significant" for t in tested)
                else "not held"
            ) + (" (partly tested)" if tested and len(tested) < len(parts) else "")
        else:
            s["verdict_holm"] = _combine([t | {"verdict": t["verdict_holm"]} for t in parts])
    return judged


def _compare(summary, task, a, b, metric, better: str) -> dict[str, Any]:
    """Welch test of variant ``a`` vs ``b`` on ``metric`` ('higher' or 'lower' is better for
    ``a`` to hold): verdict held / not held / not significant, with the numbers."""
    ra, rb = _lookup(summary, task, a), _lookup(summary, task, b)
    if ra is None or rb is None:
        missing = [v for v, r in ((a, ra), (b, rb)) if r is None]
        return {
            "task": task,
            "comparison": f"{a} vs {b}",
            "verdict": "not tested",
            "why": f"no {', '.join(missing)} runs of {task}",
        }
    xa, xb = ra[f"final_{metric}_values"], rb[f"final_{metric}_values"]
    t, p = welch(xa, xb)
    diff = ra[f"final_{metric}"] - rb[f"final_{metric}"]
    wanted = diff > 0 if better == "higher" else diff < 0
    if not math.isfinite(p):
        verdict = "not tested"
    elif p >= ALPHA:
        verdict = "not significant"
    else:
        verdict = "held" if wanted else "not held"
    return {
        "task": task,
        "comparison": f"{a} vs {b}",
        "metric": f"final {metric}",
        a: f"{ra[f'final_{metric}']:.3f} +- {ra[f'final_{metric}_se']:.3f} (n={ra['n_seeds']})",
        b: f"{rb[f'final_{metric}']:.3f} +- {rb[f'final_{metric}_se']:.3f} (n={rb['n_seeds']})",
        "t": t,
        "p": p,
        "verdict": verdict,
    }


def _combine(parts: list[dict[str, Any]]) -> str:
    """held if every tested part held; not held if any part contradicts; else not
    significant; "(partly tested)" when some parts had no runs."""
    verdicts = [p["verdict"] for p in parts if p["verdict"] != "not tested"]
    if not verdicts:
        return "not tested"
    if "not held" in verdicts:
        verdict = "not held"
    elif all(v == "held" for v in verdicts):
        verdict = "held"
    else:
        verdict = "not significant"
    return verdict + (" (partly tested)" if len(verdicts) < len(parts) else "")


def statements(summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The paper's four findings about Fig. 4, judged on the grids' final evaluations."""
    out = []
    # Like for like: the baselines have no imitation terms, nor has the authors' full reward.
    parts = [
        _compare(summary, task, "no_imitation", baseline, "success_end", "higher")
        for task in ("handshake", "et")
        for baseline in ("baseline1", "baseline2")
    ]
    out.append(
        {
            "statement": "1. The full reward beats both baselines on the handshake and E.T. "
            "(success at the end; the full reward without imitation, as the baselines).",
            "verdict": _combine(parts),
            "tests": parts,
        }
    )
    parts = [
        _compare(summary, task, "baseline2", "baseline1", "fingertip_goal_distance", "lower")
        for task in ("handshake", "et")
    ]
    out.append(
        {
            "statement": "2. Baseline 2 ends closer to the desired final pose than Baseline 1 "
            "(handshake, E.T.; mean fingertip-to-goal distance at the last step, metres).",
            "verdict": _combine(parts),
            "tests": parts,
        }
    )
    clap = _lookup(summary, "handclap", "baseline1")
    if clap is None:
        out.append(
            {
                "statement": "3. On the hand clap Baseline 1 reaches a high success rate.",
                "verdict": "not tested",
                "tests": [{"why": "no baseline1 runs of handclap"}],
            }
        )
    else:
        from scipy import stats

        finite = [v for v in clap["final_success_end_values"] if math.isfinite(v)]
        n, mean, se = len(finite), clap["final_success_end"], clap["final_success_end_se"]
        half = float(stats.t.ppf(1 - ALPHA / 2, n - 1) * se) if n > 1 else math.nan
        low, high = mean - half, mean + half
        if not math.isfinite(half):
            verdict = "not tested"
        elif low >= HIGH_SUCCESS:
            verdict = "held"
        elif high < HIGH_SUCCESS:
            verdict = "not held"
        else:
            verdict = "not significant"
        out.append(
            {
                "statement": f"3. On the hand clap Baseline 1 reaches a high success rate "
                f"(at the end; high: >= {HIGH_SUCCESS}, judged by the 95 % confidence interval).",
                "verdict": verdict,
                "tests": [
                    {
                        "task": "handclap",
                        "baseline1": f"{mean:.3f} +- {se:.3f} (n={n})",
                        "ci95": [low, high],
                    }
                ],
            }
        )
    parts = [
        _compare(summary, task, "full", "no_imitation", "success_end", "higher")
        for task in ("handshake", "handclap", "et")
    ]
    tested = [p for p in parts if p["verdict"] != "not tested"]
    if not tested:
        verdict = "not tested"
    elif all(p["verdict"] == "not significant" for p in tested):
        verdict = "held"  # no significant difference: consistent, not a proof of equality
    else:
        verdict = "not held"
    if tested and len(tested) < len(parts):
        verdict += " (partly tested)"
    out.append(
        {
            "statement": "4. Adding imitation does not significantly change success rates "
            f"(Welch's t-test, p >= {ALPHA}, per task; with few seeds a weak test, not one of "
            "equivalence).",
            "verdict": verdict,
            "tests": parts,
        }
    )
    return out


COLORS = {"full": "C0", "baseline1": "C1", "baseline2": "C2", "no_imitation": "C3"}


def plot_fig4(grids: list[dict[str, Any]], path: Path) -> None:
    """Success at the end vs env steps (top) and wall clock (bottom), one column per task."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(grids), figsize=(4.5 * len(grids), 7), squeeze=False)
    for column, grid in enumerate(grids):
        grid_curves = curves(grid)
        for variant, c in grid_curves.items():
            color = COLORS.get(variant)
            label = f"{variant} (n={c['n']})"
            epochs = authors_epochs(grid["task"], c["env_steps"])
            for row, x in enumerate((epochs, c["wall_seconds"] / 60)):
                ax = axes[row, column]
                ax.plot(x, c["mean"], color=color, label=label)
                ax.fill_between(x, c["mean"] - c["se"], c["mean"] + c["se"], color=color, alpha=0.2)
        axes[0, column].set_title(f"{grid['task']} ({grid.get('profile', 'project')} profile)")
        axes[0, column].set_xlabel("the authors' epochs (100 T env steps each)")
        axes[1, column].set_xlabel("wall clock of the grid, minutes")
        for ax in axes[:, column]:
            ax.set_ylim(-0.02, 1.02)
            ax.grid(alpha=0.3)
            ax.set_ylabel("success at the end of the episode")
        if grid_curves:
            axes[0, column].legend(loc="best", fontsize=8)
    fig.suptitle("Success at the last step, mean ± SE over seeds", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_report(grid_dirs: list[Path], out_dir: Path) -> dict[str, Any]:
    """fig4.png, summary.csv/.json, statements.json/.md from ``grid_dirs`` into ``out_dir``.

    Grids of one task and profile merge (chunks of seeds); statements are judged per
    profile, each with its verdict after Holm's correction over its tests."""
    grids = merge_grids([load_grid(d) for d in grid_dirs])
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = summarize(grids)
    if not summary:
        raise ValueError(f"no evaluations in {', '.join(map(str, grid_dirs))} yet")
    judged = []
    for profile in dict.fromkeys(r["profile"] for r in summary):
        rows = [r for r in summary if r["profile"] == profile]
        judged += [s | {"profile": profile} for s in _corrected(statements(rows))]
    plot_fig4(grids, out_dir / "fig4.png")
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    flat = [{k: v for k, v in r.items() if not isinstance(v, list)} for r in summary]
    with (out_dir / "summary.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(flat[0]))
        writer.writeheader()
        writer.writerows(flat)
    (out_dir / "statements.json").write_text(json.dumps(judged, indent=2))
    lines = [
        "| profile | statement | verdict | after Holm's correction | numbers |",
        "|---|---|---|---|---|",
    ]
    for s in judged:
        numbers = "; ".join(
            ", ".join(
                f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                for k, v in t.items()
                if k not in ("statement",)
            )
            for t in s["tests"]
        )
        lines.append(
            f"| {s['profile']} | {s['statement']} | **{s['verdict']}** | "
            f"{s['verdict_holm']} | {numbers} |"
        )
    (out_dir / "statements.md").write_text("\n".join(lines) + "\n")
    (out_dir / "fig4.md").write_text(fig4_markdown(summary, judged))
    sides = side_by_side(summary)
    if sides:
        (out_dir / "profiles.json").write_text(json.dumps(sides, indent=2))
        (out_dir / "profiles.md").write_text(side_by_side_markdown(sides))
    return {"summary": summary, "statements": judged, "profiles": sides}


def fig4_markdown(summary: list[dict[str, Any]], judged: list[dict[str, Any]]) -> str:
    """Fig. 4 as two tables: success at the end (mean ± SE, seeds) per profile, task and
    variant at the last evaluation, and each statement's verdict with its tests' p-values
    (raw / after Holm's correction) per task; statements a profile cannot test (no
    baselines trained) are left out."""
    variants = [v for v in FIG4_VARIANTS if any(r["variant"] == v for r in summary)]
    variants += sorted({r["variant"] for r in summary} - set(variants))
    lines = [
        "| profile | task | env steps | " + " | ".join(variants) + " |",
        "|---|---|---|" + "---|" * len(variants),
    ]
    by_key = {(r["profile"], r["task"], r["variant"]): r for r in summary}
    for profile, task in dict.fromkeys((r["profile"], r["task"]) for r in summary):
        rows = [by_key.get((profile, task, v)) for v in variants]
        steps = max(r["final_env_steps"] for r in rows if r)
        cells = [
            f"{r['final_success_end']:.2f} ± {r['final_success_end_se']:.2f} ({r['n_seeds']})"
            if r
            else "–"
            for r in rows
        ]
        lines.append(f"| {profile} | {task} | {steps / 1e3:.0f} k | " + " | ".join(cells) + " |")
    lines += [
        "",
        "| profile | statement | verdict | after Holm's correction | tests: p (p after Holm) |",
        "|---|---|---|---|---|",
    ]
    for s in (s for s in judged if s["verdict"] != "not tested"):
        tests = "; ".join(_test_cell(t) for t in s["tests"])
        lines.append(
            f"| {s['profile']} | {s['statement'].split(' (')[0]} | **{s['verdict']}** | "
            f"{s['verdict_holm']} | {tests} |"
        )
    return "\n".join(lines) + "\n"


def _test_cell(test: dict[str, Any]) -> str:
    """One statement test in a few words: its task, comparison and p-values (or interval)."""
    if "p" in test:
        return f"{test['task']} {test['comparison']}: {test['p']:.2g} ({test['p_holm']:.2g})"
    if "ci95" in test:
        low, high = test["ci95"]
        return f"{test['task']} 95 % interval [{low:.2f}, {high:.2f}]"
    return test.get("why", test.get("verdict", ""))


def side_by_side(summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (task, variant) that both profiles trained: success at the end under each
    (mean, SE, n) and Welch's p of the difference; [] when only one profile is there."""
    rows = []
    for r in summary:
        if r["profile"] != "paper":
            continue
        other = next(
            (
                o
                for o in summary
                if o["profile"] == "project"
                and (o["task"], o["variant"]) == (r["task"], r["variant"])
            ),
            None,
        )
        if other is None:
            continue
        _, p = welch(other["final_success_end_values"], r["final_success_end_values"])
        rows.append(
            {
                "task": r["task"],
                "variant": r["variant"],
                **{
                    f"{side}_{k}": row[k]
                    for side, row in (("paper", r), ("project", other))
                    for k in (
                        "final_success_end",
                        "final_success_end_se",
                        "n_seeds",
                        "final_env_steps",
                    )
                },
                "p": p,
            }
        )
    return rows


def side_by_side_markdown(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| task | variant | paper profile | project profile | difference | Welch's p |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        cells = [
            f"{r[f'{side}_final_success_end']:.2f} ± {r[f'{side}_final_success_end_se']:.2f} "
            f"(n={r[f'{side}_n_seeds']}, {r[f'{side}_final_env_steps'] / 1e3:.0f} k steps)"
            for side in ("paper", "project")
        ]
        diff = r["project_final_success_end"] - r["paper_final_success_end"]
        lines.append(
            f"| {r['task']} | {r['variant']} | {cells[0]} | {cells[1]} | {diff:+.2f} | {r['p']:.3g} |"
        )
    return "\n".join(lines) + "\n"


@dataclasses.dataclass(frozen=True)
class ReportArgs:
    """Report experiment grids: Fig.-4-style plot, summary table, the paper's statements."""

    grid_dirs: tyro.conf.Positional[tuple[str, ...]]
    """Grid folders (each written by `experiments run`), e.g. one per task."""
    out: str = "fig4_report"
    """Folder for fig4.png, summary.csv/.json and statements.json/.md."""


def report_main(argv: list[str]) -> int:
    args = tyro.cli(ReportArgs, args=argv)
    try:
        result = write_report([Path(d) for d in args.grid_dirs], Path(args.out))
    except (FileNotFoundError, ValueError, KeyError, json.JSONDecodeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for row in result["summary"]:
        print(
            f"{row['task']:9s} {row['profile']:7s} {row['variant']:13s} n={row['n_seeds']}  "
            "success at the end "
            f"{row['final_success_end']:.2f} +- {row['final_success_end_se']:.2f} "
            f"(best {row['best_success_end']:.2f}; some step {row['final_success_some_step']:.2f})"
        )
    for s in result["statements"]:
        print(f"[{s['profile']}: {s['verdict']}; Holm: {s['verdict_holm']}] {s['statement']}")
    print(f"written: {args.out}/fig4.png, fig4.md, summary.csv, summary.json, statements.md")
    return 0


# --------------------------------------------------------------------- compare
TARGET_SUCCESS = 0.9  # issue target: every seed ends at >= 90 % success at the end
COLLAPSE_FROM = 0.8  # ... and loses no more than COLLAPSE_LIMIT once it first reached this
COLLAPSE_LIMIT = 0.2


def seed_record(evals: list[dict[str, float]], first_epoch_seconds: float) -> dict[str, float]:
    """One member's figures from its evaluation rows (in epoch order): final and best
    success at the end, the env steps and grid wall seconds at which it first reached
    ``TARGET_SUCCESS`` (NaN: never), and its collapse: the largest fall below its running
    best after it first reached ``COLLAPSE_FROM`` (0 if never reached)."""
    values = [r[HEADLINE] for r in evals]
    reached = next((r for r in evals if r[HEADLINE] >= TARGET_SUCCESS), None)
    collapse, peak = 0.0, None
    for v in values:
        if peak is None and v >= COLLAPSE_FROM:
            peak = v
        if peak is not None:
            peak = max(peak, v)
            collapse = max(collapse, peak - v)
    return {
        "final": values[-1],
        "best": max(values),
        "steps_to_target": reached["train/env_steps"] if reached else math.nan,
        "seconds_to_target": reached.get("time/wall_seconds", math.nan) if reached else math.nan,
        "collapse": collapse,
        "first_epoch_seconds": first_epoch_seconds,
    }


def _first_epoch_seconds(grid_dir: Path, member: dict[str, Any]) -> float:
    """Wall seconds from launch to the end of epoch 1 (building and compiles included)."""
    rows = read_rows(Path(grid_dir) / member["run_dir"] / "metrics.csv")
    first = next((r for r in rows if r.get("epoch") == 1.0), None)
    return first.get("time/wall_seconds", math.nan) if first else math.nan


def _grouped(labelled: list[tuple[str, Path]]) -> dict[str, list[Path]]:
    """Grid folders per label, labels in first-seen order (a label may name several grids:
    e.g. seeds 0-2 from one grid and seeds 3-4 from another of the same config)."""
    groups: dict[str, list[Path]] = {}
    for label, path in labelled:
        groups.setdefault(label, []).append(path)
    return groups


def _merged(grid_dirs: list[Path], variant: str, env_steps: int | None = None) -> dict[str, Any]:
    """The members of ``variant`` of several grids of one task as one grid record; each
    member also carries its ``grid_dir``, and its wall clock is per run (see below).
    ``env_steps``: only the evaluations up to that budget (a longer grid read as if it
    had stopped there)."""
    grids = [load_grid(d) for d in grid_dirs]
    tasks = {g["task"] for g in grids}
    if len(tasks) > 1:
        raise ValueError(
            f"{', '.join(map(str, grid_dirs))}: grids of different tasks {sorted(tasks)}"
        )
    # On 2 cores SGD sets the pace, so a grid costs about members x one run: its wall
    # clock over its member count is what one run alone would take on the same cores.
    members = [
        m
        | {
            "grid_dir": Path(g["dir"]),
            "evals": [
                r | {"time/wall_seconds": r.get("time/wall_seconds", math.nan) / len(g["members"])}
                for r in m["evals"]
                if env_steps is None or r["train/env_steps"] <= env_steps
            ],
        }
        for g in grids
        for m in g["members"]
        if m["variant"] == variant and m["evals"]
    ]
    if not members:
        raise ValueError(f"{', '.join(map(str, grid_dirs))}: no evaluated member of {variant!r}")
    return {"task": tasks.pop(), "dir": str(grid_dirs[0]), "members": members}


def compare_learners(
    labelled: list[tuple[str, Path]], variant: str, env_steps: int | None = None
) -> list[dict[str, Any]]:
    """One row per label (the members of ``variant`` of its grids): mean +- SE over seeds
    of the :func:`seed_record` figures (seconds per run: the grid's wall clock over its
    member count), how many seeds met the targets, and Welch's p of the final success
    against the first label's; with ``env_steps``, as at that budget."""
    rows = []
    for label, grid_dirs in _grouped(labelled).items():
        grid = _merged(grid_dirs, variant, env_steps)
        members = grid["members"]
        seeds = [seed_record(m["evals"], _first_epoch_seconds(m["grid_dir"], m)) for m in members]
        row: dict[str, Any] = {"label": label, "task": grid["task"], "n_seeds": len(seeds)}
        row["seeds"] = [m["seed"] for m in members]
        row["grids"] = [str(d) for d in grid_dirs]
        row["final_epoch"] = min(m["evals"][-1]["epoch"] for m in members)
        row["final_env_steps"] = float(
            np.mean([m["evals"][-1]["train/env_steps"] for m in members])
        )
        for key in seeds[0]:
            row[key], row[f"{key}_se"] = mean_se([s[key] for s in seeds])
            row[f"{key}_values"] = [s[key] for s in seeds]
        row["seeds_at_target"] = sum(s["final"] >= TARGET_SUCCESS for s in seeds)
        row["seeds_reached_target"] = sum(math.isfinite(s["steps_to_target"]) for s in seeds)
        row["worst_collapse"] = max(s["collapse"] for s in seeds)
        row["seeds_collapsed"] = sum(s["collapse"] > COLLAPSE_LIMIT for s in seeds)
        row["min_final"] = min(s["final"] for s in seeds)
        if rows:
            row["p_final_vs_first"] = welch(row["final_values"], rows[0]["final_values"])[1]
        rows.append(row)
    return rows


def plot_learners(
    labelled: list[tuple[str, Path]], variant: str, path: Path, env_steps: int | None = None
) -> None:
    """Success at the end, mean +- SE over seeds, against env steps and grid wall clock."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    task = ""
    for label, grid_dirs in _grouped(labelled).items():
        grid = _merged(grid_dirs, variant, env_steps)
        task = grid["task"]
        c = curves(grid)[variant]
        for ax, x in zip(axes, (c["env_steps"], c["wall_seconds"] / 60)):
            ax.plot(x, c["mean"], label=f"{label} (n={c['n']})")
            ax.fill_between(x, c["mean"] - c["se"], c["mean"] + c["se"], alpha=0.2)
    axes[0].set_xlabel("environment steps per run")
    axes[1].set_xlabel("minutes per run (the grid's wall clock / its members)")
    for ax in axes:
        ax.axhline(TARGET_SUCCESS, color="grey", lw=0.8, ls="--")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.set_ylabel("success at the end of the episode")
        ax.legend(loc="lower right", fontsize=8)
    fig.suptitle(f"{task}: learners compared ({variant} reward), mean +- SE over seeds")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def learners_markdown(rows: list[dict[str, Any]]) -> str:
    """The comparison as a Markdown table."""

    def pm(row, key, scale=1.0, digits=2):
        return f"{scale * row[key]:.{digits}f} ± {scale * row[key + '_se']:.{digits}f}"

    lines = [
        "| learner | seeds | success at the end | min | seeds >= 0.9 at the end | best "
        + "| env steps to 0.9 (seeds) | minutes to 0.9 per run | worst fall after 0.8 "
        + "| first epoch (s) | p vs first |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        p = r.get("p_final_vs_first")
        lines.append(
            f"| {r['label']} | {r['n_seeds']} | {pm(r, 'final')} | {r['min_final']:.2f} "
            f"| {r['seeds_at_target']}/{r['n_seeds']} | {pm(r, 'best')} "
            f"| {r['steps_to_target']:,.0f} ({r['seeds_reached_target']}/{r['n_seeds']}) "
            f"| {r['seconds_to_target'] / 60:.1f} | {r['worst_collapse']:.2f} "
            f"| {r['first_epoch_seconds']:.0f} | {'' if p is None else f'{p:.3g}'} |"
        )
    return "\n".join(lines) + "\n"


@dataclasses.dataclass(frozen=True)
class CompareArgs:
    """Compare learners: grids of one task and reward variant trained with different
    learner options (e.g. the paper's DDPG against TD3's additions)."""

    grids: tyro.conf.Positional[tuple[str, ...]]
    """LABEL=GRID_DIR pairs; the first label is the baseline of the p-values; a label given
    twice pools the members of its grids (e.g. seeds 0-2 and 3-4 trained apart)."""
    out: str = "learners"
    """Folder for learners.png, learners.csv/.json/.md."""
    variant: str = "full"
    """Reward variant of the grids to compare."""
    env_steps: int | None = None
    """Compare at this budget: each member's evaluations up to this many env steps per
    run (grids trained for different lengths, side by side at the shorter one's)."""


def parse_labelled(items: tuple[str, ...]) -> list[tuple[str, Path]]:
    """``LABEL=GRID_DIR`` strings as (label, path); ValueError naming a malformed one."""
    out = []
    for item in items:
        label, sep, path = item.partition("=")
        if not sep or not label or not path:
            raise ValueError(f"{item!r}: expected LABEL=GRID_DIR, e.g. ddpg=runs/clap-ddpg")
        out.append((label, Path(path)))
    if not out:
        raise ValueError("give at least one LABEL=GRID_DIR")
    return out


def compare_main(argv: list[str]) -> int:
    args = tyro.cli(CompareArgs, args=argv)
    try:
        labelled = parse_labelled(args.grids)
        if args.env_steps is not None and args.env_steps <= 0:
            raise ValueError(f"--env-steps {args.env_steps}: expected a positive budget")
        rows = compare_learners(labelled, args.variant, args.env_steps)
    except (FileNotFoundError, ValueError, KeyError, json.JSONDecodeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plot_learners(labelled, args.variant, out / "learners.png", args.env_steps)
    (out / "learners.json").write_text(json.dumps(rows, indent=2))
    flat = [{k: v for k, v in r.items() if not isinstance(v, list)} for r in rows]
    with (out / "learners.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=sorted({k for r in flat for k in r}, key=str))
        writer.writeheader()
        writer.writerows(flat)
    text = learners_markdown(rows)
    (out / "learners.md").write_text(text)
    print(text)
    return 0


# --------------------------------------------------------------------- archive
ARCHIVED_FILES = ("metrics.csv", "config.json")
"""What a member keeps in an archive: its curves and its configuration, not its
checkpoints, replay buffer or TensorBoard events."""


@dataclasses.dataclass(frozen=True)
class ArchiveArgs:
    """Keep a grid's evidence without its checkpoints: grid.json and each member's
    metrics.csv and config.json, in a folder small enough to commit. The report and
    compare commands read the archive as they read the grid."""

    grid: Annotated[tyro.conf.Positional[str], tyro.conf.arg(metavar="GRID_DIR")]
    """The trained grid's folder (holding grid.json)."""
    dest: Annotated[tyro.conf.Positional[str], tyro.conf.arg(metavar="DEST")]
    """A new (or empty) folder for the archive."""
    log: Annotated[str | None, tyro.conf.arg(metavar="FILE")] = None
    """The grid's console output, kept as grid.log (optional)."""


def archive_grid(grid_dir: Path, dest: Path, log: Path | None = None) -> list[Path]:
    """Copy ``grid_dir``'s record into the new folder ``dest``; returns the files written.
    Each member's config.json names its run folder inside ``dest`` (the original folder,
    with its checkpoints, is not part of the archive); grid.json keeps ``archived_from``.
    Everything is read and checked before the first file is written."""
    grid_dir, dest = Path(grid_dir), Path(dest)
    record_path = grid_dir / GRID_FILE
    if not record_path.is_file():
        raise FileNotFoundError(f"{grid_dir} is not an experiment grid ({GRID_FILE} missing)")
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        raise FileExistsError(f"{dest} exists and is not an empty folder; choose a new one")
    if log is not None and not Path(log).is_file():
        raise FileNotFoundError(f"--log {log}: no such file")
    record = json.loads(record_path.read_text())
    outside = [m["run_dir"] for m in record["members"] if not _inside(m["run_dir"])]
    if outside:
        raise ValueError(f"{record_path}: member folders outside the grid: {', '.join(outside)}")
    missing = [
        f"{m['run_dir']}/{name}"
        for m in record["members"]
        for name in ARCHIVED_FILES
        if not (grid_dir / m["run_dir"] / name).is_file()
    ]
    if missing:
        raise FileNotFoundError(f"{grid_dir}: members not trained yet ({', '.join(missing)})")
    kept = {  # member folder -> (metrics.csv bytes, config)
        m["run_dir"]: (
            (grid_dir / m["run_dir"] / "metrics.csv").read_bytes(),
            json.loads((grid_dir / m["run_dir"] / "config.json").read_text()),
        )
        for m in record["members"]
    }
    written = []
    for run_dir, (metrics, config) in kept.items():
        target = dest / run_dir
        target.mkdir(parents=True, exist_ok=True)
        (target / "metrics.csv").write_bytes(metrics)
        (target / "config.json").write_text(
            json.dumps(config | {"run_dir": str(target)}, indent=2) + "\n"
        )
        written += [target / name for name in ARCHIVED_FILES]
    if "train" in record:
        record["train"]["run_dir"] = str(dest)
    record["archived_from"] = str(grid_dir)
    (dest / GRID_FILE).write_text(json.dumps(record, indent=2) + "\n")
    written.append(dest / GRID_FILE)
    if log is not None:
        (dest / "grid.log").write_bytes(Path(log).read_bytes())
        written.append(dest / "grid.log")
    return written


def _inside(run_dir: str) -> bool:
    """Whether a member's folder, as grid.json names it, lies inside its grid."""
    path = Path(run_dir)
    return not path.is_absolute() and ".." not in path.parts


def archive_main(argv: list[str]) -> int:
    args = tyro.cli(ArchiveArgs, args=argv)
    try:
        written = archive_grid(Path(args.grid), Path(args.dest), args.log and Path(args.log))
    except (OSError, ValueError, KeyError) as err:  # JSONDecodeError is a ValueError
        print(f"error: {err}", file=sys.stderr)
        return 2
    size = sum(f.stat().st_size for f in written) / 2**20
    print(f"archived {args.grid} into {args.dest}: {len(written)} files, {size:.1f} MiB")
    return 0


USAGE = """usage: python -m mjx_hands.experiments {run,report,compare,archive} [--help] ...

  run      train seeds x reward variants of one task as one population
  report   Fig.-4-style plot, summary table and the paper's statements from grids
  compare  learners side by side: grids of one task trained with different options
  archive  a grid's curves and configs without its checkpoints (small enough to commit)"""


def main(argv: list[str] | None = None) -> int:
    return cli.dispatch(
        argv,
        {"run": run_main, "report": report_main, "compare": compare_main, "archive": archive_main},
        USAGE,
    )


if __name__ == "__main__":
    raise SystemExit(main())
