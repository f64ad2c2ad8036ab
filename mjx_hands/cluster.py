"""Experiment grids over several processes and hosts, with ``jax.distributed`` (a single
run is a grid of one member).

Multi-controller JAX: every process runs the same program on its own devices, the
population's ``pmap`` spans the devices of all of them, so each process steps its share
of every member's environments and holds that share of the replay buffers, and the
updates' all-reduces (gradients, observation statistics) and the evaluation's mean run
over all devices. A member trained on 2 processes of 1 device each is the member trained
by one process with 2 devices (``tests/test_cluster.py``). Checkpoints are collective:
each process writes its rows of the device-split state into the run's one checkpoint
and reads them back on resume; process 0 writes everything else (grid record, metrics,
TensorBoard, plots). The grid's folder must be on a filesystem every host sees (a
cluster's shared home or scratch). DDPG (every ``ddpg*`` learner) lays its checkpoints out
so; a plug-in learner does with ``Population.take_member`` / ``global_rows`` /
``own_rows``.

    # one machine, two processes
    for k in 0 1; do
      python -m mjx_hands.experiments run --run-dir runs/g --cluster.processes 2 \\
          --cluster.process-id $k &
    done; wait
    # SLURM: one task per node (or per GPU), everything read from srun's environment
    srun --nodes 4 --ntasks-per-node 1 python -m mjx_hands.experiments run \\
        --run-dir runs/g --cluster.detect

:func:`join` must run before anything asks JAX for its devices (the ``auto`` preset
does), so the command parses these options first (:func:`early_config`).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from typing import TextIO

FLAG_PREFIX = "--cluster."


@dataclasses.dataclass(frozen=True)
class ClusterConfig:
    """How this process joins a grid spread over processes (``jax.distributed``)."""

    processes: int = 1
    """Processes of the grid in all, on one host or several; 1: this process alone."""
    process_id: int = 0
    """This process's index, 0 .. processes - 1 (process 0 writes the grid record)."""
    coordinator: str = "localhost:12355"
    """host:port of process 0, where the others connect (any free port)."""
    detect: bool = False
    """Read processes, process id and coordinator from the cluster's environment
    (SLURM's srun, Open MPI's mpirun, ...) as ``jax.distributed.initialize`` does."""

    def __post_init__(self):
        problems = config_problems(self)
        if problems:
            raise ValueError("; ".join(problems))

    @property
    def distributed(self) -> bool:
        return self.detect or self.processes > 1


def config_problems(config: ClusterConfig) -> list[str]:
    """What is wrong with ``config``, as messages naming the option and what it expects."""
    problems = []
    if config.processes < 1:
        problems.append(f"--cluster.processes must be at least 1, got {config.processes}")
    elif not 0 <= config.process_id < config.processes:
        problems.append(
            f"--cluster.process-id must be in 0 .. {config.processes - 1}, got {config.process_id}"
        )
    host, _, port = config.coordinator.rpartition(":")
    if not host or not port.isdigit():
        problems.append(f"--cluster.coordinator must be host:port, got {config.coordinator!r}")
    return problems


def early_config(argv: Sequence[str]) -> ClusterConfig:
    """The ``--cluster.*`` options of ``argv`` alone (the full parse reads them again)."""
    import tyro

    picked: list[str] = []
    for i, arg in enumerate(argv):
        if arg.startswith(FLAG_PREFIX):
            picked.append(arg)
            takes_value = "=" not in arg and not arg.endswith(("detect", "no-detect"))
            if takes_value and i + 1 < len(argv):
                picked.append(argv[i + 1])
    return tyro.cli(ClusterConfig, args=[a.replace(FLAG_PREFIX, "--", 1) for a in picked])


def join(config: ClusterConfig) -> None:
    """Join the other processes (no-op for one process). Before any JAX computation."""
    if not config.distributed:
        return
    import jax

    if config.detect:
        jax.distributed.initialize()
    else:
        jax.distributed.initialize(
            config.coordinator, num_processes=config.processes, process_id=config.process_id
        )


def is_primary() -> bool:
    """Whether this process writes what the processes share (process 0)."""
    import jax

    return jax.process_index() == 0


def progress_stream(out: TextIO | None) -> TextIO | None:
    """Where this process prints progress: ``out`` (None: stdout) on process 0, nowhere on
    the others (they train the same members: one progress log)."""
    if is_primary():
        return out
    return open(os.devnull, "w")


def processes() -> int:
    """Processes in this program (1 unless :func:`join` joined others)."""
    import jax

    return jax.process_count()


def barrier(name: str) -> None:
    """Wait until every process gets here (no-op for one process)."""
    import jax

    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)


def agree(value):
    """Process 0's ``value`` (a bool or a NumPy array) on every process: decisions that
    lead to collectives (stop, save, a member diverged) must not differ between processes
    whose clocks or per-device metrics do."""
    import jax
    import numpy as np

    if jax.process_count() == 1:
        return value
    from jax.experimental import multihost_utils

    agreed = np.asarray(multihost_utils.broadcast_one_to_all(np.asarray(value)))
    return bool(agreed) if isinstance(value, bool) else agreed
