"""The machine and library versions a benchmark's JSON records, in one shape for all.

    python -m benchmarks.machine     # prints the record as JSON

Benchmarks that time ``train.py`` in child processes call :func:`describe_in_child`: on a
GPU, initialising JAX in the parent would take the accelerator's memory from the run
being timed (JAX preallocates most of it per process).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from importlib import metadata


def versions() -> dict:
    """Python's and the numeric stack's versions (None where a package is absent)."""

    def version_of(package: str) -> str | None:
        try:
            return metadata.version(package)
        except metadata.PackageNotFoundError:
            return None

    packages = (
        "jax", "jaxlib", "jax-cuda12-plugin", "jax-cuda13-plugin", "mujoco", "mujoco-mjx",
        "numpy", "flax", "optax", "orbax-checkpoint", "brax", "warp-lang",
    )  # fmt: skip
    return {"python": platform.python_version()} | {p: version_of(p) for p in packages}


def cpu_model() -> str:
    """The CPU's marketing name where Linux reports it (platform.processor() often gives
    only the architecture), else the architecture."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def describe() -> dict:
    """This process's machine: CPU, the cores it may use, JAX's default device, and the
    XLA flags as a training process sees them (importing mjx_hands adds its CPU flag)."""
    import jax

    import mjx_hands  # noqa: F401  (its XLA flags, before jax.devices() starts XLA)

    device = jax.devices()[0]
    return {
        "platform": platform.platform(),
        "processor": cpu_model(),
        "cpu_count": os.cpu_count(),
        "usable_cores": len(os.sched_getaffinity(0)),
        "backend": jax.default_backend(),
        "device": str(device),
        "device_kind": device.device_kind,
        "device_count": jax.device_count(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }


def provenance(module: str, argv: list[str] | None) -> dict:
    """The head of a benchmark's JSON record: the command that rewrites it (``module`` run
    with ``argv``, default the process's), the machine and the package versions."""
    import sys

    args = sys.argv[1:] if argv is None else argv
    return {"command": f"python -m {module} " + " ".join(args), "machine": describe(), "versions": versions()}


def write_record(path, record: dict) -> None:
    """``record`` as indented JSON at ``path`` (its folder made), when a path is given."""
    import json
    from pathlib import Path

    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(record, indent=1))


def describe_in_child() -> dict:
    """:func:`describe`, run in a fresh Python so this process never holds the device.
    Launchers call it before their first launch, so a failure costs no measurement."""
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.machine"],
        capture_output=True, text=True, check=False,
        cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
    )  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"describing the machine failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.splitlines()[-1])["machine"]


if __name__ == "__main__":
    print(json.dumps({"machine": describe(), "versions": versions()}))
