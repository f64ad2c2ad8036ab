"""mjx_hands: demonstration-guided RL of dexterous human-robot hand interactions in MJX.

``make_env`` is imported lazily so that ``import mjx_hands`` stays cheap.
"""

from mjx_hands import xla_flags

# Before JAX starts a backend: MJX physics on CPU is ~4x faster with it (see xla_flags).
xla_flags.configure_cpu_codegen()

__all__ = ["TASKS", "make_env"]
TASKS = ("handshake", "handclap", "et")


def make_env(*args, **kwargs):
    """See :func:`mjx_hands.env.make_env`."""
    from mjx_hands.env import make_env as _make_env

    return _make_env(*args, **kwargs)
