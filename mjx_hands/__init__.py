"""mjx_hands: demonstration-guided RL of dexterous human-robot hand interactions in MJX.

``make_env`` is imported lazily so that ``import mjx_hands`` stays cheap (it imports
``mujoco.mjx``, quietly). Two process-wide settings are made here, on import, and only
where the user has not made them, because neither can be made later by a command:

* ``XLA_FLAGS`` gains ``--xla_cpu_use_fusion_emitters=false`` (``xla_flags``): XLA reads
  it once, when JAX starts its first backend, and the MJX physics step runs 5.8x faster
  on CPU with it; a library user who builds an environment never runs one of our
  commands, so the flag has to be in place before their first JAX computation. Set
  ``XLA_FLAGS`` yourself (either way) and it is left alone; GPU programs are unchanged.
* ``MUJOCO_GL=egl`` when no display is set: MuJoCo picks its OpenGL platform when it is
  imported, and this package imports it; offscreen rendering (``evaluate``'s videos,
  the rating study) then works headless. A set ``MUJOCO_GL`` is left alone.
"""

import contextlib
import io
import os
import sys

from mjx_hands import xla_flags

# Before JAX starts a backend: the MJX physics step on 2 CPU cores ran 5.8x faster with
# it at 128 envs (benchmarks/results/cost_drivers.md; xla_flags).
xla_flags.configure_cpu_codegen()


def _import_mjx_quietly() -> None:
    """Import ``mujoco.mjx`` (Brax imports it too) without the two lines it prints when
    its optional Warp backend is absent; the project runs MJX's JAX implementation."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        import mujoco.mjx  # noqa: F401
    for line in printed.getvalue().splitlines():
        if not line.startswith(("Failed to import warp", "Failed to import mujoco_warp")):
            print(line, file=sys.stdout)


# MuJoCo picks its OpenGL platform when it is imported: without a display, render offscreen
# with EGL (videos of evaluate and the rating study) unless the user chose otherwise.
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")
_import_mjx_quietly()

from mjx_hands.tasks import TASKS

__all__ = ["TASKS", "make_env"]


def make_env(*args, **kwargs):
    """See :func:`mjx_hands.env.make_env`."""
    from mjx_hands.env import make_env as _make_env

    return _make_env(*args, **kwargs)
