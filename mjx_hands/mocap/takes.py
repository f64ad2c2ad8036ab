"""Importing and exporting takes: one door for a lab's recordings (BVH folders or Motive
CSV files, by the mapping's ``format``) into the project's demonstrations, and out again
with the project's skeleton (round trips, viewing in other tools)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from mjx_hands.mocap import bvh, motive, skeleton
from mjx_hands.mocap.capture import Take, to_demonstration
from mjx_hands.mocap.demonstration import Demonstration, MocapError
from mjx_hands.mocap.mapping import HandMapping, Mapping, mapping_toml
from mjx_hands.shadow_hand import HAND_JOINTS

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


def import_report(
    demos: list[Demonstration], mapping: Mapping, paths, beside: Path
) -> dict:
    """What was mapped from where, and what each take became (paths relative to
    ``beside``, the folder of the npz, so that the report can be committed with it)."""

    def where(path) -> str:
        return os.path.relpath(path, beside)

    def hand(h: HandMapping) -> dict:
        return {
            "palm": h.palm,
            "joints": {
                j: (
                    f"{s.node}.{s.axis} x {s.sign:g} + {s.offset:g}"
                    if s.node
                    else f"{s.offset:g} (constant)"
                )
                for j, s in h.joints.items()
            },
        }

    return {
        "mapping": where(mapping.source),
        "format": mapping.format,
        "fps": mapping.fps,
        "actor": hand(mapping.actor),
        "target": hand(mapping.target),
        "constant_joints": {
            name: [j for j in HAND_JOINTS if getattr(mapping, name).joints[j].node is None]
            for name in ("actor", "target")
        },
        "takes": [
            {
                "path": where(p),
                "name": d.name,
                "frames": d.num_frames,
                "fps": d.fps,
                "contact_window": [d.contact_begin, d.contact_end],
                "closest_palm_distance_m": float(
                    np.linalg.norm(d.actor_points[:, 0], axis=-1).min()
                ),
            }
            for p, d in zip(paths, demos)
        ],
    }


def write_import_report(demos: list[Demonstration], mapping: Mapping, paths, npz: Path) -> Path:
    """:func:`import_report` as JSON beside the npz (``<npz>.report.json``)."""
    path = Path(npz).with_suffix(".report.json")
    path.write_text(json.dumps(import_report(demos, mapping, paths, path.parent), indent=1) + "\n")
    return path
