"""Time from launch to the first epoch, with and without JAX's persistent compilation
cache, side by side in one run.

    python -m benchmarks.first_epoch --out benchmarks/results_first_epoch_cpu.json

For each physics, ``train.py`` runs one epoch three times, each in a fresh process:
without the cache, with an empty cache folder (cold) and again with that folder (warm,
the second launch of the same program: a resumed run, a new seed, a grid after its
pilot). Reported per launch: the process's wall clock, the run's own clock at the end of
epoch 1 (``time/wall_seconds``: building, compiling and the epoch itself) and the cache
folder's files. The epoch is small, so compiling dominates both.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import machine

ROOT = Path(__file__).resolve().parent.parent
SMALL = [
    "--epochs", "1", "--eval-every", "1", "--num-envs", "16", "--eval-envs", "16",
    "--ddpg.unroll-length", "5", "--ddpg.iterations-per-epoch", "2",
    "--ddpg.updates-per-iteration", "8", "--ddpg.min-replay-size", "16",
]  # fmt: skip


def launch(run_dir: Path, physics: str, task: str, cache: Path | None, extra: list[str]) -> dict:
    """One ``train.py`` process; its wall clock and the run's clock at epoch 1."""
    env = dict(os.environ)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    env.pop("JAX_ENABLE_COMPILATION_CACHE", None)
    if cache is not None:
        env["JAX_COMPILATION_CACHE_DIR"] = str(cache)
    else:  # off, even where the commands would default to a folder
        env["JAX_ENABLE_COMPILATION_CACHE"] = "false"
    args = [sys.executable, str(ROOT / "train.py"), "--task", task, "--physics", physics]
    args += ["--run-dir", str(run_dir), *SMALL, *extra]
    start = time.perf_counter()
    done = subprocess.run(args, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed:\n{done.stderr[-3000:]}")
    with open(run_dir / "metrics.csv") as f:
        first = next(csv.DictReader(f), None)
    if first is None:
        raise RuntimeError(f"{run_dir}/metrics.csv has no epoch")
    files = sorted(cache.iterdir()) if cache is not None and cache.is_dir() else []
    return {
        "process_seconds": wall,
        "run_clock_at_epoch_1": float(first["time/wall_seconds"]),
        "epoch_1_seconds": float(first["time/epoch_seconds"]),
        "cache_files": len(files),
        "cache_mib": sum(f.stat().st_size for f in files) / 2**20,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--physics", nargs="+", default=["native", "mjx"])
    parser.add_argument("--task", default="handclap")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results_first_epoch_cpu.json"))
    parser.add_argument("extra", nargs="*", help="more train.py options (after --)")
    args = parser.parse_args(argv)
    described = machine.describe_in_child()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for physics in args.physics:
            cache = Path(tmp) / f"cache-{physics}"
            for label, folder in (("off", None), ("cold", cache), ("warm", cache)):
                run_dir = Path(tmp) / f"{physics}-{label}"
                row = {"physics": physics, "cache": label}
                row |= launch(run_dir, physics, args.task, folder, args.extra)
                print(json.dumps(row), flush=True)
                results.append(row)
    record = {
        "machine": described,
        "versions": machine.versions(),
        "task": args.task,
        "train_options": SMALL + args.extra,
        "results": results,
    }
    args.out.write_text(json.dumps(record, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
