"""Minutes from launch to a target success at the end of the episode: one ``train.py``
run per task and learner, each in a fresh process, the learners side by side.

    python -m benchmarks.time_to_target --out benchmarks/results_time_to_target_cpu.json

Each launch trains one seed with the device's preset on the authors' recordings (or
``--mocap-source synthetic``, where ../shared is absent, e.g. on a lent GPU), the
reward each task's five-seed grids used (handshake and E.T.: the authors' reward,
without imitation; the clap: with imitation). The benchmark reads the run's
``metrics.csv`` while it trains; the first evaluation whose success at the end reaches
``--target`` stops the run, and its time is the process's wall clock since launch
(building, compiling, training and evaluating included: what a user waits for). A run
that has not reached it after ``--minutes`` is reported as not reached, with its best.
The JSON is rewritten after every launch, so a long sweep keeps what it measured.
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import machine

ROOT = Path(__file__).resolve().parent.parent
HEADLINE = "eval/success_final"
TASK_OPTIONS = {
    "handshake": ["--no-imitation"],
    "et": ["--no-imitation"],
    "handclap": ["--imitation"],
}
"""Per task, the reward of its five-seed learner grids (benchmarks/results/learners.md)."""


def evaluations(metrics: Path) -> list[dict]:
    """The evaluated epochs of a (possibly growing) metrics.csv: epoch, env steps, the
    run's clock and the headline success."""
    if not metrics.is_file():
        return []
    with open(metrics) as f:
        rows = list(csv.DictReader(f))
    return [
        {
            "epoch": int(float(r["epoch"])),
            "env_steps": int(float(r["train/env_steps"])),
            "run_seconds": float(r["time/wall_seconds"]),
            "success": float(r[HEADLINE]),
        }
        for r in rows
        if r.get(HEADLINE)
    ]


def median_of(rows: list[dict], key: str) -> float | None:
    values = [float(r[key]) for r in rows if r.get(key)]
    return statistics.median(values) if values else None


def rates(metrics: Path) -> dict:
    """Median env steps and critic updates per second of the run's epochs after the first
    (which includes the compiles)."""
    with open(metrics) as f:
        rows = list(csv.DictReader(f))[1:]
    return {
        "env_steps_per_second": median_of(rows, "time/env_steps_per_second"),
        "updates_per_second": median_of(rows, "time/updates_per_second"),
    }


def launch(run_dir: Path, task: str, algo: str, seed: int, args) -> dict:
    """One train.py process, stopped at the first evaluation at or above the target."""
    command = [
        sys.executable, str(ROOT / "train.py"), "--task", task, "--algo", algo,
        "--seed", str(seed), "--mocap-source", args.mocap_source, "--run-dir", str(run_dir),
        "--max-minutes", str(args.minutes), *TASK_OPTIONS[task], *args.extra,
    ]  # fmt: skip
    log = run_dir.with_suffix(".log")
    start = time.perf_counter()
    with open(log, "w") as out:  # a file, not a pipe: a full pipe would block the run
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT)
        reached, curve = None, []
        while process.poll() is None:
            time.sleep(1.0)
            seen = evaluations(run_dir / "metrics.csv")
            for row in seen[len(curve) :]:
                row["launch_seconds"] = time.perf_counter() - start  # observed within ~1 s
                curve.append(row)
                if reached is None and row["success"] >= args.target:
                    reached = row
            if reached is not None:
                process.terminate()  # train.py checkpoints and stops at the epoch's end
                break
        process.wait()
    wall = time.perf_counter() - start
    if reached is None and process.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{log.read_text()[-3000:]}")
    for row in evaluations(run_dir / "metrics.csv")[len(curve) :]:
        row["launch_seconds"] = wall  # written as the run ended
        curve.append(row)
    best = max(curve, key=lambda r: r["success"], default=None)
    return {
        "task": task,
        "algo": algo,
        "seed": seed,
        "reached": reached is not None,
        "minutes_to_target": reached["launch_seconds"] / 60 if reached else None,
        "env_steps_to_target": reached["env_steps"] if reached else None,
        "epoch_at_target": reached["epoch"] if reached else None,
        "best_success": best["success"] if best else None,
        "process_minutes": wall / 60,
        **rates(run_dir / "metrics.csv"),
        "curve": curve,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--tasks", nargs="+", default=list(TASK_OPTIONS), choices=list(TASK_OPTIONS)
    )
    parser.add_argument("--algos", nargs="+", default=["ddpg-ln", "ddpg"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--target", type=float, default=0.9)
    parser.add_argument(
        "--mocap-source", default="optitrack", choices=["optitrack", "synthetic"],
        help="the authors' recordings (../shared) or the project's synthetic demonstrations",
    )  # fmt: skip
    parser.add_argument("--minutes", type=float, default=15.0, help="give up after this long")
    parser.add_argument(
        "--out", type=Path, default=Path("benchmarks/results_time_to_target_cpu.json")
    )
    parser.add_argument("extra", nargs="*", help="more train.py options (after --)")
    args = parser.parse_args(argv)
    record = {
        "machine": machine.describe_in_child(),
        "versions": machine.versions(),
        "target": args.target,
        "mocap_source": args.mocap_source,
        "minutes_cap": args.minutes,
        "train_options": args.extra,
        "results": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        for task in args.tasks:
            for algo in args.algos:
                row = launch(Path(tmp) / f"{task}-{algo}", task, algo, args.seed, args)
                summary = {k: v for k, v in row.items() if k != "curve"}
                print(json.dumps(summary), flush=True)
                record["results"].append(row)
                args.out.write_text(json.dumps(record, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
