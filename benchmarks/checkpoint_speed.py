"""Checkpoint save/restore time of a real training state: the project's format
(uncompressed zarr3 + SHA-256 digest) side by side with Orbax's default (zstd, zarr2).

    python -m benchmarks.checkpoint_speed RUN_DIR --out benchmarks/results_checkpoint_cpu.json

RUN_DIR is any DDPG run; its newest checkpoint (networks, optimiser states, environment
states and, by default, the replay buffer) is what is written and read back.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import orbax.checkpoint as ocp

from benchmarks import machine
from mjx_hands import checkpoint


def folder_mib(path: Path) -> float:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) / 2**20


def orbax_default(directory: Path, arrays: dict[str, np.ndarray]) -> None:
    """What checkpoint.save wrote before: Orbax's standard handler (zstd, zarr2)."""
    options = ocp.CheckpointManagerOptions(create=True)
    with ocp.CheckpointManager(directory, options=options) as manager:
        manager.save(0, args=ocp.args.StandardSave(arrays))
        manager.wait_until_finished()


def orbax_default_restore(directory: Path) -> dict:
    with ocp.CheckpointManager(directory) as manager:
        return manager.restore(0, args=ocp.args.StandardRestore())


def timed(fn, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results_checkpoint_cpu.json"))
    args = parser.parse_args(argv)
    source = args.run_dir / "checkpoints"
    step = checkpoint.latest_step(source)
    with ocp.CheckpointManager(source.absolute()) as manager:
        restored = manager.restore(step, args=ocp.args.Composite(state=ocp.args.PyTreeRestore()))
    arrays = {k: np.asarray(v) for k, v in restored["state"].items()}
    like = dict(arrays)
    scratch = Path(tempfile.mkdtemp(prefix="ckpt-speed-"))
    results = {}
    for name in ("orbax_default", "project"):
        target = scratch / name

        def save(name=name, target=target):
            shutil.rmtree(target, ignore_errors=True)
            if name == "project":
                checkpoint.save(target, 0, arrays, {"epoch": 0})
            else:
                orbax_default(target, arrays)

        def restore(name=name, target=target):
            if name == "project":
                return checkpoint.restore(target, like)[0]
            return orbax_default_restore(target)

        save_s = timed(save, args.repeats)
        restore_s = timed(restore, args.repeats)
        back = restore()
        assert all(np.array_equal(np.asarray(back[k]), arrays[k]) for k in arrays), name
        results[name] = {
            "save_seconds": save_s,
            "restore_seconds": restore_s,
            "disk_mib": folder_mib(target),
        }
    results["digest_seconds"] = timed(
        lambda: checkpoint.damage(scratch / "project", 0), args.repeats
    )
    shutil.rmtree(scratch)
    out = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "run_dir": str(args.run_dir),
        "step": step,
        "state_mib": sum(a.nbytes for a in arrays.values()) / 2**20,
        "results": results,
    }
    args.out.write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
