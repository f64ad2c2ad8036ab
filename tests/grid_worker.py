"""One process of a point-reach experiment grid spread over several, for the cluster test.

    python tests/grid_worker.py GRID_DIR EPOCHS PROCESSES PROCESS_ID PORT [--resume]
        [--compare OTHER_GRID_DIR]

The grid is 2 seeds of the full reward, 16 environments each over every device of every
process. With one process it runs without ``jax.distributed`` (on as many devices as
XLA_FLAGS gives it). ``--compare``: then compare every array of each member's last
checkpoint with the same member's in OTHER_GRID_DIR (``COMPARE equal`` when all are equal,
NaNs included, else ``COMPARE differ`` and the largest difference).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import jax
import numpy as np
from tiny import point_config, point_factory

from mjx_hands import checkpoint, cluster, experiments, training


def main(argv: list[str]) -> None:
    grid_dir, epochs, processes, process_id, port = argv[0], *map(int, argv[1:5])
    train = point_config(Path(grid_dir), epochs=epochs, eval_every=1, checkpoint_every=1)
    grid = experiments.GridConfig(
        variants=("full",),
        seeds=2,
        train=dataclasses.replace(train, resume="--resume" in argv),
        cluster=cluster.ClusterConfig(
            processes=processes, process_id=process_id, coordinator=f"localhost:{port}"
        ),
    )
    cluster.join(grid.cluster)
    experiments.run_grid(grid, sys.stdout, env_factory=point_factory)
    print("WORKER DONE", flush=True)
    if "--compare" in argv:
        other = Path(argv[argv.index("--compare") + 1])
        compare(grid, other, epochs)


def compare(grid: experiments.GridConfig, other: Path, epoch: int) -> None:
    """Each member's checkpoint of ``epoch`` here and in ``other``: every array."""
    equal, worst = True, 0.0
    for index, (_, config) in enumerate(experiments.members(grid)):
        algo, _ = training.make_learner(config, env_factory=point_factory)
        like = algo.checkpoint_tree(algo.state_shapes, config.save_replay)
        run_dir = Path(config.run_dir)
        mine, _ = checkpoint.restore(run_dir / "checkpoints", like, epoch)
        theirs, _ = checkpoint.restore(other / run_dir.relative_to(grid.train.run_dir) / "checkpoints", like, epoch)
        for a, b in zip(jax.tree.leaves(mine), jax.tree.leaves(theirs)):
            floating = np.issubdtype(a.dtype, np.floating)
            equal &= bool(np.array_equal(a, b, equal_nan=floating))
            if floating:
                worst = max(worst, float(np.nanmax(np.abs(a - b), initial=0.0)))
    print(f"COMPARE {'equal' if equal else 'differ'} {worst}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
