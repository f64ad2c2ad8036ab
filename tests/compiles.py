"""Count the programs JAX traces inside a block: a jitted function called again with
arguments of known shapes and structure traces nothing."""

from __future__ import annotations

import contextlib

import jax

TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"


@contextlib.contextmanager
def counting_traces():
    """Yields a list that collects one entry per program traced inside the block."""
    traced: list[str] = []

    def listen(event: str, duration: float, **kwargs) -> None:
        if event == TRACE_EVENT:
            traced.append(kwargs.get("fun_name", "?"))

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield traced
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
