"""mjx_hands: demonstration-guided RL of dexterous human-robot hand interactions in MJX.

``make_env`` is imported lazily so that ``import mjx_hands`` stays cheap.
"""

__all__ = ["TASKS", "make_env"]
TASKS = ("handshake", "handclap", "et")


def make_env(*args, **kwargs):
    """See :func:`mjx_hands.env.make_env`."""
    from mjx_hands.env import make_env as _make_env

    return _make_env(*args, **kwargs)
