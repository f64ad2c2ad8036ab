"""Commands with sub-commands (``experiments``, ``study``): one dispatch for both."""

from __future__ import annotations

import sys
from collections.abc import Callable


def dispatch(
    argv: list[str] | None, commands: dict[str, Callable[[list[str]], int]], usage: str
) -> int:
    """Run ``commands[argv[0]](argv[1:])``; ``-h``/``--help`` print ``usage``; a missing or
    unknown command prints it to stderr with what was expected and returns 2."""
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in commands:
        return commands[argv[0]](argv[1:])
    if argv and argv[0] in ("-h", "--help"):
        print(usage)
        return 0
    names = list(commands)
    expected = ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else names[0]
    print(usage, file=sys.stderr)
    print(
        f"error: expected a command, {expected}; got {argv[0] if argv else 'none'}", file=sys.stderr
    )
    return 2
