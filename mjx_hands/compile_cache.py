"""JAX's persistent compilation cache for the project's commands.

A second launch of the same program (a resumed run, the next seed, evaluating a run
that was trained in another process) then reads its compiled programs from disk
instead of compiling them again (``benchmarks/results/first_epoch.md``). Programs with host callbacks (the native CPU physics) are never cached by
JAX; MJX programs, on CPU and GPU, are.

The commands call :func:`enable`; library use of ``mjx_hands`` leaves JAX's settings
alone.
"""

from __future__ import annotations

import os
from pathlib import Path


def default_folder() -> Path:
    """``$XDG_CACHE_HOME/mjx_hands/jax`` (``~/.cache/mjx_hands/jax`` without it)."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "mjx_hands" / "jax"


def enable() -> Path | None:
    """Point JAX's persistent cache at :func:`default_folder`, unless the user chose:
    ``JAX_COMPILATION_CACHE_DIR`` names another folder (JAX reads it itself) and
    ``JAX_ENABLE_COMPILATION_CACHE=false`` turns caching off. Returns the folder in use,
    or None when caching is off."""
    import jax

    if not jax.config.jax_enable_compilation_cache:
        return None
    chosen = jax.config.jax_compilation_cache_dir or os.environ.get("JAX_COMPILATION_CACHE_DIR")
    if chosen:
        return Path(chosen)
    folder = default_folder()
    jax.config.update("jax_compilation_cache_dir", str(folder))
    return folder
