"""XLA settings the hand-pair physics needs on CPU, applied when ``mjx_hands`` is imported.

XLA's CPU fusion emitters (the default since jaxlib 0.5) turn MJX's batched
forward kinematics into loop fusions that recompute each parent body's quaternion
for every component of every descendant: one vmapped ``mjx.kinematics`` of the hand
pair took 150 ms at 128 envs on 2 cores, against 3.3 ms with the older elemental
emitters (``benchmarks/results/cost_drivers.md``). The whole
physics step ran 5.8x faster at 128 envs (the figure the README gives). The flag
only touches CPU code generation; GPU programs are unchanged.

XLA reads ``XLA_FLAGS`` once, when JAX starts its first backend, and aborts the
process on a flag it does not know. So the flag is added only if JAX has not started
yet, the user has not set it either way, and the installed jaxlib knows it.
"""

from __future__ import annotations

import mmap
import os
import sys
import warnings
from pathlib import Path

FLAG_NAME = "xla_cpu_use_fusion_emitters"
FLAG = f"--{FLAG_NAME}=false"


def _jaxlib_knows(flag_name: str) -> bool:
    """Whether the installed jaxlib's XLA registers the flag ``flag_name``.

    The flag parser's table holds each name as a C string (NUL on both sides); the
    DebugOptions proto descriptor, which can keep a removed flag's field, stores names
    length-prefixed, so it does not count.
    """
    try:
        import jaxlib
    except ImportError:
        return False
    needle = b"\0" + flag_name.encode() + b"\0"
    for lib in Path(jaxlib.__file__).parent.glob("*.so"):
        with open(lib, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            if mm.find(needle) >= 0:
                return True
    return False


def _backends_started() -> bool:
    if "jax" not in sys.modules:  # cheap path: nothing can have started
        return False
    try:
        from jax._src import xla_bridge
    except ImportError:  # JAX moved its internals: assume started, change nothing
        return True
    return xla_bridge.backends_are_initialized()


def configure_cpu_codegen() -> bool:
    """Adds :data:`FLAG` to ``XLA_FLAGS`` where that is safe; returns whether it is set.

    Set ``XLA_FLAGS=--xla_cpu_use_fusion_emitters=true`` to keep XLA's default.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if FLAG_NAME in flags:
        return FLAG in flags.split()
    if not _jaxlib_knows(FLAG_NAME):
        return False
    if _backends_started():
        warnings.warn(
            "JAX started before mjx_hands was imported, so XLA runs without "
            f"{FLAG}: MJX physics on CPU will be ~4x slower. Import mjx_hands before "
            "running any JAX computation, or set XLA_FLAGS yourself.",
            stacklevel=3,
        )
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {FLAG}".strip()
    return True
