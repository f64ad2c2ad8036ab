"""Soak: a small DDPG run for hundreds of epochs, checkpointing every epoch, with host
and device memory recorded per epoch. Growth means a leak (the jitted epoch, the
checkpoint writer, the metrics log, TensorBoard); the report fits it.

    python -m benchmarks.soak --epochs 500 --out benchmarks/results_soak_cpu.json

The task is the pure-JAX point reach (the hand physics adds nothing a leak would hide
in), so hundreds of epochs take minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import io
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import machine
from mjx_hands import train_config, training
from mjx_hands.agents.ddpg import DDPGConfig
from mjx_hands.env import BatchedEnv
from mjx_hands.point_reach import PointReach

DDPG = DDPGConfig(
    hidden_sizes=(64, 64),
    batch_size=128,
    replay_capacity=20_000,
    min_replay_size=256,
    unroll_length=5,
    updates_per_iteration=8,
    iterations_per_epoch=4,
)


def point_reach(config: train_config.TrainConfig, num_devices: int):
    single = PointReach()
    return (
        BatchedEnv(single, config.num_envs // num_devices),
        BatchedEnv(single, config.eval_envs // num_devices),
        single,
    )


def growth_per_100_epochs(epochs: np.ndarray, values: np.ndarray) -> float:
    """Slope of a least-squares line through (epochs, values), per 100 epochs."""
    return float(np.polyfit(epochs, values, 1)[0] * 100)


def summarize(rows: list[dict[str, float]], warmup: int) -> dict[str, float]:
    """Memory at the start and end and its growth after ``warmup`` epochs (compiles, the
    replay buffer filling, allocator pools settling)."""
    steady = [r for r in rows if r["epoch"] > warmup]
    epochs = np.array([r["epoch"] for r in steady])
    rss = np.array([r["memory/host_rss_gib"] for r in steady]) * 1024  # MiB
    out = {
        "epochs": len(rows),
        "host_rss_mib_after_warmup": float(rss[0]),
        "host_rss_mib_end": float(rss[-1]),
        "host_rss_mib_max": float(rss.max()),
        "host_rss_growth_mib_per_100_epochs": growth_per_100_epochs(epochs, rss),
        "host_peak_mib_end": rows[-1]["memory/host_peak_gib"] * 1024,
    }
    if "memory/device_in_use_gib" in steady[0]:
        device = np.array([r["memory/device_in_use_gib"] for r in steady]) * 1024
        out["device_in_use_mib_end"] = float(device[-1])
        out["device_in_use_growth_mib_per_100_epochs"] = growth_per_100_epochs(epochs, device)
    wall = np.diff([r["time/wall_seconds"] for r in rows])
    epoch_s = np.array([r["time/epoch_seconds"] for r in rows[1:]])
    out["epoch_seconds_median"] = float(np.median(epoch_s))
    # Wall clock between epochs beyond the epoch itself: checkpoint, evaluation, logging.
    out["between_epochs_seconds_median"] = float(np.median(wall - epoch_s))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--epochs", type=int, default=500)
    parser.add_argument("--warmup", type=int, default=20, help="epochs left out of the fit")
    parser.add_argument("--num-envs", type=int, default=32)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results_soak_cpu.json"))
    args = parser.parse_args(argv)
    run_dir = Path(tempfile.mkdtemp(prefix="soak-")) / "run"
    config = train_config.TrainConfig(
        num_envs=args.num_envs,
        eval_envs=args.num_envs,
        epochs=args.epochs,
        eval_every=5,
        run_dir=str(run_dir),
        ddpg=DDPG,
    )
    started = time.perf_counter()
    summary = training.run(config, out=io.StringIO(), env_factory=point_reach)
    with open(run_dir / "metrics.csv", newline="") as f:
        rows = [{k: float(v) for k, v in r.items() if v != ""} for r in csv.DictReader(f)]
    result = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "config": train_config.config_to_json(dataclasses.replace(config, run_dir=None)),
        "wall_seconds": time.perf_counter() - started,
        "stop_reason": summary["stop_reason"],
        "summary": summarize(rows, args.warmup),
        "per_epoch": {
            key: [r.get(key) for r in rows]
            for key in (
                "epoch",
                "memory/host_rss_gib",
                "memory/host_peak_gib",
                "time/epoch_seconds",
            )
        },
    }
    args.out.write_text(json.dumps(result, indent=1))
    shutil.rmtree(run_dir.parent)
    print(json.dumps(result["summary"], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
