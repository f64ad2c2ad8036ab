"""Train a hand-interaction policy: the project's single command.

The DDPG trainer is the next milestone; until it lands this command checks that the
chosen task's environment builds and steps, and says so.
"""

from __future__ import annotations

import argparse
import sys

from mjx_hands import TASKS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--task", default="handshake", choices=TASKS)
    parser.add_argument("--num-envs", type=int, default=64)
    args = parser.parse_args(argv)
    print("Training arrives with the DDPG trainer; checking the environment instead.")
    from mjx_hands import env

    sys.argv = [sys.argv[0], "--task", args.task, "--num-envs", str(args.num_envs), "--steps", "5"]
    env._main()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
