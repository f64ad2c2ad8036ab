"""The task registry: every interaction is one module of this package.

A module ``mjx_hands.tasks.<name>`` holds ``SPEC = TaskSpec(...)`` (``tasks.spec``):
its success rule, reward weights per profile and variant, target placement, the design
of its synthetic demonstrations and its paper references. ``MODULES`` below registers
it; every other module reads the registry (``TASKS``, :func:`spec`), never a task's
name. Adding an interaction: write its module, add its name to ``MODULES``, give it
demonstrations (``python -m mjx_hands.synthetic_demos --task NAME`` for a designed
one, ``python -m mjx_hands.import_mocap`` for recordings).
"""

from __future__ import annotations

import importlib

from mjx_hands.tasks.spec import (
    CONTROL_DT,
    AuthorsWeights,
    SyntheticDesign,
    TargetBox,
    TaskSpec,
    name_key,
)

MODULES = ("handshake", "handclap", "et", "fist_bump")
"""The registered task modules, in the order of ``TASKS`` (the registry line)."""

REGISTRY: dict[str, TaskSpec] = {}
for _module in MODULES:
    _spec = importlib.import_module(f"{__name__}.{_module}").SPEC
    if _spec.name != _module:
        raise ImportError(f"mjx_hands.tasks.{_module} declares the task {_spec.name!r}")
    REGISTRY[_spec.name] = _spec
TASKS = tuple(REGISTRY)
"""Names of the registered interactions."""
RELEASE_TASKS = tuple(name for name, task in REGISTRY.items() if task.in_authors_release)
"""The interactions the authors' recordings hold (the paper's three)."""


def spec(task: str) -> TaskSpec:
    """The registered facts of ``task``; a clear error for an unknown name."""
    try:
        return REGISTRY[task]
    except KeyError:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(TASKS)}") from None


__all__ = [
    "CONTROL_DT",
    "MODULES",
    "REGISTRY",
    "RELEASE_TASKS",
    "TASKS",
    "AuthorsWeights",
    "SyntheticDesign",
    "TargetBox",
    "TaskSpec",
    "name_key",
    "spec",
]
