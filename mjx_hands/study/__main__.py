"""Command line of the rating study.

    python -m mjx_hands.study make ...                        render the videos, write the study
    python -m mjx_hands.study serve STUDY_DIR [--port 8000] [--host 127.0.0.1]
    python -m mjx_hands.study report STUDY_DIR [--out DIR]    Table I from the answers

``COMMAND --help`` describes each command's options.
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Annotated

import tyro

from mjx_hands import cli

USAGE = __doc__


@dataclasses.dataclass(frozen=True)
class ServeArgs:
    """Serve the rating page of a study; answers go to STUDY_DIR/answers.sqlite."""

    study_dir: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="STUDY_DIR")]
    """Study folder (study.json, key.json, videos/)."""
    port: int = 8000
    """TCP port (0: any free one; the URL printed says which)."""
    host: str = "127.0.0.1"
    """Address to listen on; 0.0.0.0 lets other machines of the network reach it."""


@dataclasses.dataclass(frozen=True)
class ReportArgs:
    """Table I of a study: preference for the imitation policy per task and kind of start."""

    study_dir: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="STUDY_DIR")]
    """Study folder with the raters' answers.sqlite."""
    out: Annotated[str | None, tyro.conf.arg(metavar="DIR")] = None
    """Folder for table1.csv/.json/.png; default the study folder."""


def serve_main(argv: list[str]) -> int:
    from mjx_hands.study import server

    args = tyro.cli(ServeArgs, args=argv, prog="python -m mjx_hands.study serve")
    try:
        server.serve(args.study_dir, host=args.host, port=args.port)
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # the address: port taken, host not of this machine
        print(f"error: cannot listen on {args.host}:{args.port}: {err.strerror}", file=sys.stderr)
        return 2
    return 0


def report_main(argv: list[str]) -> int:
    from mjx_hands.study import report

    args = tyro.cli(ReportArgs, args=argv, prog="python -m mjx_hands.study report")
    try:
        rows = report.write_report(args.study_dir, args.out)
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(report.format_rows(rows))
    out = args.study_dir if args.out is None else args.out
    print(f"wrote {report.CSV_FILE}, {report.JSON_FILE}, {report.PLOT_FILE} to {out}")
    return 0


def make_main(argv: list[str]) -> int:
    from mjx_hands.study import make  # rendering needs the simulator: only when asked for

    return make.main(argv)


COMMANDS = {"make": make_main, "serve": serve_main, "report": report_main}


def main(argv: list[str] | None = None) -> int:
    return cli.dispatch(argv, COMMANDS, USAGE)


if __name__ == "__main__":
    raise SystemExit(main())
