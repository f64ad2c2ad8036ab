"""Experiment grids on disk, as a library: a grid folder holds ``grid.json`` (its members:
variant, seed, run folder) and one run folder per member (``metrics.csv``,
``config.json``); ``python -m mjx_hands.experiments`` trains, reports and archives them."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

GRID_FILE = "grid.json"
HEADLINE = "eval/success_final"
"""The authors' metric: the required contacts touch at the last step."""


def read_rows(path: Path) -> list[dict[str, float]]:
    """A metrics.csv as one dict of floats per row (empty cells left out)."""
    with path.open() as f:
        return [
            {k: float(v) for k, v in r.items() if k is not None and v not in ("", None)}
            for r in csv.DictReader(f)
        ]


def load_grid(grid_dir: Path) -> dict[str, Any]:
    """A grid's record and each member's evaluation rows:
    ``{'task', 'dir', 'members': [{'variant', 'seed', 'evals': [row, ...]}]}``."""
    path = Path(grid_dir) / GRID_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{grid_dir} is not an experiment grid ({GRID_FILE} missing)")
    record = json.loads(path.read_text())
    loaded = []
    for m in record["members"]:
        metrics = Path(grid_dir) / m["run_dir"] / "metrics.csv"
        rows = read_rows(metrics) if metrics.is_file() else []
        loaded.append(m | {"evals": [r for r in rows if HEADLINE in r]})
    train = record.get("train", {})
    profile = train.get("env", train).get("profile", "project")  # flat before env was its own
    for m in loaded:
        m["source"] = str(grid_dir)
    return {"task": record["task"], "profile": profile, "dir": str(grid_dir), "members": loaded}
