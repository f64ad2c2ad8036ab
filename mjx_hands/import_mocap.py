"""Bring a lab's motion capture into the project, or take demonstrations out of it.

    python -m mjx_hands.import_mocap import --task fist_bump --mapping MAP.toml \\
        --out mocap_data/fist_bump.npz TAKE [TAKE ...]
    python -m mjx_hands.import_mocap export --task handshake --source optitrack \\
        --format bvh --out exported/handshake

``import`` reads BVH takes (a folder with the actor's and the target's skeleton files) or
OptiTrack Motive CSV takes, maps them onto the project's hands by the mapping file
(``mjx_hands.mocap.mapping``: skeleton names, units, palm axes, frame rate, contact
windows), validates them as every loader does and writes the project's npz
(``mocap_data/README.md``) and a report of what was mapped (``<out>.report.json``).
``export`` writes demonstrations as takes of the project's skeleton with the mapping
that reads them back.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Annotated, Literal

import tyro

from mjx_hands import cli, mocap, tasks
from mjx_hands.mocap import mapping as mapping_lib
from mjx_hands.mocap import takes


@dataclasses.dataclass(frozen=True)
class ImportArgs:
    """Import takes into the project's npz."""

    takes: Annotated[tuple[str, ...], tyro.conf.Positional, tyro.conf.arg(metavar="TAKE")]
    """BVH take folders or Motive CSV files."""
    task: str
    """The registered task the takes demonstrate."""
    mapping: str
    """The mapping file (TOML; see mjx_hands.mocap.mapping)."""
    out: str
    """The npz to write (e.g. mocap_data/<task>.npz)."""


@dataclasses.dataclass(frozen=True)
class ExportArgs:
    """Export demonstrations as takes of the project's skeleton."""

    task: str
    out: str
    """Folder of the takes and their mapping.toml."""
    format: Literal["bvh", "motive"] = "bvh"
    source: Literal["optitrack", "synthetic", "auto"] = "auto"
    """Whose demonstrations: the authors' recordings, the project's files, or either."""
    demos: Literal["authors", "all"] = "all"
    """Of the recordings: the rows the authors trained on, or all."""


def run_import(argv: list[str]) -> int:
    args = tyro.cli(ImportArgs, args=argv, description=ImportArgs.__doc__)
    try:
        tasks.spec(args.task)
        mapping = mapping_lib.load_mapping(args.mapping)
        demos = takes.import_takes(list(args.takes), mapping, args.task)
    except (ValueError, mocap.MocapError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    mocap.save_npz(demos, out)
    takes.write_import_report(demos, mapping, args.takes, out)
    print(f"wrote {out} ({len(demos)} demonstrations) and {out.with_suffix('.report.json')}")
    return 0


def run_export(argv: list[str]) -> int:
    args = tyro.cli(ExportArgs, args=argv, description=ExportArgs.__doc__)
    try:
        demos = mocap.load_demonstrations(args.task, source=args.source)
        if args.demos == "authors" and demos[0].source == "optitrack":
            rows = set(tasks.spec(args.task).authors_demos)
            demos = [d for d in demos if int(d.name.rsplit("/", 1)[-1]) in rows]
    except (ValueError, mocap.MocapError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    mapping = takes.export_demos(demos, args.out, args.format)
    print(f"wrote {len(demos)} takes and {mapping}")
    return 0


COMMANDS = {"import": run_import, "export": run_export}


def main(argv: list[str] | None = None) -> int:
    return cli.dispatch(argv, COMMANDS, __doc__)


if __name__ == "__main__":
    sys.exit(main())
