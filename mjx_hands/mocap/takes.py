"""Importing and exporting takes: one door for a lab's recordings (BVH folders or Motive
CSV files, by the mapping's ``format``) into the project's demonstrations, and out again
with the project's skeleton (round trips, viewing in other tools)."""

from __future__ import annotations

from pathlib import Path

from mjx_hands.mocap import bvh, motive, skeleton
from mjx_hands.mocap.capture import Take, to_demonstration
from mjx_hands.mocap.demonstration import Demonstration, MocapError
from mjx_hands.mocap.mapping import Mapping, mapping_toml

READERS = {"bvh": bvh.read_take, "motive": motive.read_take}
WRITERS = {"bvh": bvh.write_take, "motive": motive.write_take}
SUFFIX = {"bvh": "", "motive": ".csv"}
"""A take's path after its name: a BVH take is a folder, a Motive take a CSV file."""


def read_take(path: str | Path, mapping: Mapping) -> Take:
    """One take in the mapping's format."""
    return READERS[mapping.format](path, mapping)


def import_takes(paths: list[str | Path], mapping: Mapping, task: str) -> list[Demonstration]:
    """Demonstrations of ``task`` from the takes at ``paths`` (names must be unique)."""
    if not paths:
        raise MocapError("no takes to import")
    demos = [to_demonstration(read_take(p, mapping), task, mapping) for p in paths]
    names = [d.name for d in demos]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise MocapError(f"takes with the same name {repeated}: rename the files or folders")
    return demos


def take_name(demo: Demonstration) -> str:
    """A file-safe take name for a demonstration (its name after the task)."""
    return demo.name.split("/", 1)[-1].replace("/", "-")


def export_demos(demos: list[Demonstration], out: str | Path, fmt: str) -> Path:
    """Write ``demos`` as takes of the project's skeleton into ``out`` with the mapping
    that reads them back (``out/mapping.toml``, their contact windows included)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    windows = {}
    for demo in demos:
        name = take_name(demo)
        WRITERS[fmt](demo, out / f"{name}{SUFFIX[fmt]}")
        windows[name] = (demo.contact_begin, demo.contact_end)
    mapping = out / "mapping.toml"
    mapping.write_text(mapping_toml(skeleton.mapping(fmt, windows)))
    return mapping


def take_paths(folder: str | Path, fmt: str) -> list[Path]:
    """The takes of an exported folder, in name order."""
    folder = Path(folder)
    if fmt == "bvh":
        return sorted(p for p in folder.iterdir() if p.is_dir())
    return sorted(folder.glob("*.csv"))
