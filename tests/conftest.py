"""Shared, session-scoped compiled functions: MJX compiles take ~30 s each on 2 cores."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest

# Compiles dominate the suite: XLA's CPU backend at optimisation level 0 compiles ~25 %
# faster (MJX step 65 -> 52 s) and the programs it makes, slower to run, still finish
# sooner overall (the learning tests of test_ddpg: 89 -> 64 s). Same programs, same
# semantics: what the tests assert does not depend on how well LLVM optimised them.
os.environ.setdefault(
    "XLA_FLAGS", "--xla_cpu_multi_thread_eigen=true --xla_backend_optimization_level=0"
)
# Tests build the same programs again and again (every training.run with the same config
# compiles the same epoch; subprocesses recompile what their parent did): JAX's persistent
# compilation cache turns each repeat into a load (a point-reach run: 37 s -> 6 s). It
# starts empty in every session, so a fresh clone's time includes every first compile;
# set JAX_COMPILATION_CACHE_DIR to keep one between local runs.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _cache = tempfile.mkdtemp(prefix="mjx_hands_test_jax_cache_")
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _cache
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "0")
# Render videos in this process too: MuJoCo picks its GL platform at import.
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "mocap" / "drl_handshake"


def real_data_or_skip() -> Path:
    """Path of the authors' recordings, or skip when this checkout has none beside it."""
    if not (REAL_DATA / "handshake_interaction_t.npy").is_file():
        pytest.skip(f"real mocap data not found at {REAL_DATA}")
    return REAL_DATA


@pytest.fixture(scope="session")
def handshake_env():
    """A batched handshake env on MJX (project's synthetic demos) with jitted reset/step.
    16 envs: MJX on 2 CPU cores steps in time proportional to the batch, and 16 draws
    still spread every randomised quantity the tests check."""
    import jax

    from mjx_hands import env as env_lib

    env = env_lib.make_env("handshake", num_envs=16, mocap_source="synthetic", physics="mjx")
    return env, jax.jit(env.reset), jax.jit(env.step)


@pytest.fixture(scope="session")
def reset_state(handshake_env):
    import jax

    _, reset, _ = handshake_env
    return reset(jax.random.PRNGKey(42))


@pytest.fixture(scope="session")
def native_handshake_env():
    """The same batched handshake env on native MuJoCo (compiles in seconds)."""
    import jax

    from mjx_hands import env as env_lib

    env = env_lib.make_env("handshake", num_envs=16, mocap_source="synthetic", physics="native")
    return env, jax.jit(env.reset), jax.jit(env.step)


# Tests that compile MJX, train for several epochs or start subprocesses that do: the
# full suite runs them; `pytest -m "not slow"` leaves them out for the inner loop.
SLOW_FIXTURES = {"handshake_env", "hand_run", "trained_point_reach"}
# The README's test command runs two pytest-xdist workers (--dist loadgroup): the tests of
# one expensive fixture go to one worker, so it is built once.
GROUPED_FIXTURES = ("handshake_env", "hand_run", "native_handshake_env", "trained_point_reach")


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups
def pytest_collection_modifyitems(config, items):
    for item in items:
        names = set(getattr(item, "fixturenames", ()))
        if SLOW_FIXTURES & names:
            item.add_marker(pytest.mark.slow)
        group = next((name for name in GROUPED_FIXTURES if name in names), None)
        if group is not None:
            item.add_marker(pytest.mark.xdist_group(group))
