"""Grids over several processes (``jax.distributed``): the options, and two CPU processes
that train and resume a grid whose every member equals one process's with both devices."""

from __future__ import annotations

import csv
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from mjx_hands import cluster

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"processes": 0}, "--cluster.processes must be at least 1, got 0"),
        ({"processes": 2, "process_id": 2}, r"--cluster.process-id must be in 0 .. 1, got 2"),
        ({"coordinator": "nohost"}, "--cluster.coordinator must be host:port, got 'nohost'"),
    ],
)
def test_cluster_options_refuse_bad_input_with_a_message(kwargs, message):
    with pytest.raises(ValueError, match=message):
        cluster.ClusterConfig(**kwargs)


def test_the_cluster_options_are_read_before_the_rest_of_the_command_line():
    argv = ["--task", "et", "--cluster.processes", "4", "--seeds", "2",
            "--cluster.process-id=3", "--cluster.detect", "--cluster.coordinator", "h:1"]
    assert cluster.early_config(argv) == cluster.ClusterConfig(
        processes=4, process_id=3, coordinator="h:1", detect=True
    )
    assert not cluster.early_config(["--task", "et"]).distributed


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _workers(grid_dir: Path, epochs: int, processes: int, *extra: str, devices: int = 1) -> list[str]:
    """Run the grid worker as ``processes`` processes of ``devices`` CPU devices each."""
    env = dict(os.environ, JAX_PLATFORMS="cpu",
               XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    port = str(_free_port())
    procs = [
        subprocess.Popen(
            [sys.executable, str(ROOT / "tests" / "grid_worker.py"), str(grid_dir), str(epochs),
             str(processes), str(k), port, *extra],
            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )
        for k in range(processes)
    ]
    logs = [p.communicate(timeout=600)[0] for p in procs]
    for p, log in zip(procs, logs):
        assert p.returncode == 0 and "WORKER DONE" in log, log[-3000:]
    return logs


def _rows(run_dir: Path) -> list[dict[str, str]]:
    with (run_dir / "metrics.csv").open() as f:
        return [
            {k: v for k, v in r.items() if not k.startswith(("time/", "memory/"))}
            for r in csv.DictReader(f)
        ]


@pytest.mark.slow
def test_two_processes_train_and_resume_a_grid_as_one_process_with_both_devices(tmp_path):
    """Point reach, 2 members, 16 environments each over 2 CPU devices. One process with
    both devices trains 4 epochs. The same grid spread over two processes of one device
    each (jax.distributed on this machine) trains 2 epochs, resumes to 3, and is resumed
    to 4 by one process with both devices. Every member's metrics and its checkpoint of
    epoch 4 (learner, environments, replay rows of both devices) are the same, bit for
    bit; process 0 alone wrote the grid record, the logs and the progress lines."""
    spread, alone = tmp_path / "spread", tmp_path / "alone"
    _workers(alone, 4, 1, devices=2)
    _workers(spread, 2, 2)
    logs = _workers(spread, 3, 2, "--resume")
    # One progress log: process 0 prints it, the other process trains the same members.
    assert "resumed from epoch 2" in logs[0] and "grid:" in logs[0]
    assert "resumed from epoch" not in logs[1] and "grid:" not in logs[1]
    assert "tensorboard" not in logs[1] and '"processes": 2' in (spread / "grid.json").read_text()
    assert len(list((spread / "full" / "seed0" / "tensorboard").iterdir())) == 2  # process 0's
    log = _workers(spread, 4, 1, "--resume", "--compare", str(alone), devices=2)[0]
    assert "resumed from epoch 3" in log and "COMPARE equal" in log, log[-2000:]
    for seed in (0, 1):
        member = Path("full") / f"seed{seed}"
        spread_rows, alone_rows = _rows(spread / member), _rows(alone / member)
        assert [r["epoch"] for r in spread_rows] == ["1.0", "2.0", "3.0", "4.0"]
        assert spread_rows == alone_rows
