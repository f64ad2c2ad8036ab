"""A point-reach training run in its own process, for the fault-injection tests to kill.

    python tests/point_reach_worker.py RUN_DIR EPOCHS [--hold-before-digest FOLDER/STEP]

``--hold-before-digest checkpoints/3`` (or ``best/2``) stops (sleeps) once Orbax has
written that step and before its digest is, after printing ``holding checkpoints/3``: a
kill then lands mid-save.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from tiny import point_config, point_factory

from mjx_hands import checkpoint, training


def main(argv: list[str]) -> None:
    run_dir, epochs = Path(argv[0]), int(argv[1])
    if "--hold-before-digest" in argv:
        hold = argv[argv.index("--hold-before-digest") + 1]
        write_digest = checkpoint._write_digest

        def holding(step_dir: Path) -> None:
            if f"{step_dir.parent.name}/{step_dir.name}" == hold:
                print(f"holding {hold}", flush=True)
                time.sleep(600)
            write_digest(step_dir)

        checkpoint._write_digest = holding
    training.run(
        point_config(run_dir, epochs=epochs, eval_every=2), out=sys.stdout, env_factory=point_factory
    )


if __name__ == "__main__":
    main(sys.argv[1:])
