"""Static-trained against robust-trained policies, side by side: one table, the heatmaps
next to each other.

    python -m mjx_hands.partner_report static=OUT_A robust=OUT_B --out DIR

Each ``LABEL=FOLDER`` is the ``--out`` folder of ``mjx_hands.robustness --sweep all`` (and,
where it was run there, of ``mjx_hands.naturalness``) over one setup's runs of one task;
``LABEL=FOLDER,FOLDER,...`` pools the runs of several such folders (e.g. one per seed,
swept in different sessions on the same episodes).
Every setup was scored on the same episodes against the same partner
(``env.scoring_env``), so rows compare like with like. Writes ``side_by_side.md`` /
``.json`` and ``orientation_side_by_side.png`` into ``--out``.

Rows: success at the end at the nominal pose; averaged over the yaw x pitch cells within
+-30, +-45 and +-60 degrees; at each speed of the motion sweep; against the static target
and the recorded partner; under sensing error and action delay; then the naturalness
metrics (lower is closer to the demonstrations); last, where the folders hold the runs'
metrics.csv, the training minutes to success at the end of 0.9 in the run's own
evaluations (against its own training partners). A run that resumed another setup's run
trained against other partners (the same first rows, other ``partners`` in config.json:
static then robust; or its sibling folder ``static``, as ``benchmarks/partners/seeds.sh``
archives a seed) counts from that run's start, and reaches the mark only in
evaluations after it; without the other run's metrics.csv it counts from its start. Values are mean +- standard error over the setup's
runs (one run: the binomial error over its episodes; one policy's naturalness, or one
run's minutes: "(n = 1)").
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np
import tyro

from mjx_hands import grids, robustness

REGIONS_DEG = (30.0, 45.0, 60.0)
"""Half-widths of the yaw x pitch squares whose cells are averaged, degrees."""


@dataclasses.dataclass(frozen=True)
class ReportArgs:
    """Static-trained against robust-trained policies, side by side."""

    setups: tyro.conf.Positional[tuple[str, ...]]
    """LABEL=FOLDER[,FOLDER...] per setup: folders written by ``robustness --sweep all
    --out`` (several: their runs pooled)."""
    out: str = "partner_report"
    """Folder for side_by_side.md / .json and orientation_side_by_side.png."""


Folders = tuple[Path, ...]
"""One setup's sweep folders, whose runs are pooled."""

SHARED_KEYS = (
    "task", "episodes", "seed", "angles_deg", "speeds", "turn_period", "motion_box",
    "conditions", "partner_lag", "noise_mm", "delays",
)
"""Keys that pooled folders must agree on (the same conditions, the same episodes)."""


def parse_setups(specs: tuple[str, ...]) -> dict[str, Folders]:
    """{label: folders} from ``LABEL=FOLDER[,FOLDER...]`` strings; ValueError naming a bad one."""
    setups = {}
    for spec in specs:
        label, sep, folders = spec.partition("=")
        if not sep or not label or not folders:
            raise ValueError(f"setup {spec!r}: expected LABEL=FOLDER[,FOLDER...] (e.g. static=runs/a)")
        if label in setups:
            raise ValueError(f"setup label {label!r} given twice")
        names = folders.split(",")
        if "" in names or len(set(names)) < len(names):
            raise ValueError(f"setup {label!r}: {folders!r} has an empty or repeated folder")
        for folder in names:
            if not (Path(folder) / f"{robustness.ORIENTATION_FILE}.json").is_file():
                raise ValueError(
                    f"setup {label!r}: {folder} holds no {robustness.ORIENTATION_FILE}.json "
                    "(run python -m mjx_hands.robustness RUNS --sweep all --out FOLDER first)"
                )
        setups[label] = tuple(Path(f) for f in folders.split(","))
    if not setups:
        raise ValueError("give at least one LABEL=FOLDER")
    return setups


def region_mask(angles_deg: np.ndarray, limit_deg: float) -> np.ndarray:
    """(n, n) bool: the cells (rows pitch, columns yaw) with |yaw| and |pitch| <= limit."""
    inside = np.abs(angles_deg) <= limit_deg + 1e-9
    return inside[:, None] & inside[None, :]


def mean_se(per_run: np.ndarray, samples: int) -> tuple[float, float]:
    """Mean and standard error of per-run success rates (R,): over runs, or for one run
    the binomial error over its ``samples`` episodes."""
    mean = float(np.mean(per_run))
    if len(per_run) > 1:
        return mean, float(np.std(per_run, ddof=1) / math.sqrt(len(per_run)))
    return mean, math.sqrt(mean * (1.0 - mean) / samples)


def read_json(folders: Folders, name: str) -> dict | None:
    """Sweep ``name`` of a setup: one folder's summary, or several folders' pooled (their
    per-run arrays and naturalness policies concatenated, the means over all runs).
    None where no folder has it; ValueError where only some do or they disagree."""
    paths = [folder / f"{name}.json" for folder in folders]
    found = [p for p in paths if p.is_file()]
    if not found:
        return None
    if len(found) < len(paths):
        missing = ", ".join(str(p) for p in paths if not p.is_file())
        raise ValueError(f"{missing} missing: every pooled folder needs the same sweeps")
    parts = [json.loads(p.read_text()) for p in found]
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    for path, part in zip(found[1:], parts[1:]):
        differ = [k for k in SHARED_KEYS if part.get(k) != first.get(k)]
        if (part.get("checkpoint") or {}).get("kind") != (first.get("checkpoint") or {}).get("kind"):
            differ.append("checkpoint kind")
        if differ:
            raise ValueError(f"{path} differs from {found[0]} in {', '.join(differ)}: pool like sweeps")
    pooled = dict(first)
    if "policies" in first:  # naturalness
        pooled["policies"] = [policy for part in parts for policy in part["policies"]]
        return pooled
    for key in (k for k in first if k.endswith("_per_run")):
        runs = np.concatenate([np.asarray(part[key], np.float64) for part in parts])
        pooled[key] = runs.tolist()
        pooled[key.removesuffix("_per_run")] = runs.mean(axis=0).tolist()
        pooled.pop(key.removesuffix("_per_run") + "_se", None)  # partners' rows compute their own
    pooled["runs"] = sum(int(part["runs"]) for part in parts)
    pooled["run_dirs"] = [d for part in parts for d in part.get("run_dirs", [])]
    pooled.pop("checkpoint", None)  # per folder; its kind agrees (checked above)
    return pooled


TRAINING_MARK = 0.9
"""Success at the end whose first evaluation the training-cost row times."""
TRAINING_ROW = f"training minutes to {TRAINING_MARK:g} at the end"


Run = tuple[list[dict[str, float]], object]
"""A run's metrics.csv rows and the partner models it last trained with (config.json's
``partners``; None where unknown)."""


def same_rows(a: list[dict[str, float]], b: list[dict[str, float]]) -> bool:
    """Whether two runs' metrics rows hold the same epochs and evaluations (NaN equal to
    NaN). Timings are left out: a static run retrained on another machine or beside other
    jobs (``benchmarks/partners/seeds.sh`` accepts it where its evaluations reproduce the
    archived ones) is the same run at other speeds."""
    same = lambda x, y: x == y or (math.isnan(x) and math.isnan(y))
    kept = lambda row: {k: v for k, v in row.items() if k == "epoch" or k.startswith("eval/")}
    same_row = lambda r, q: r.keys() == q.keys() and all(same(v, q[k]) for k, v in r.items())
    return len(a) == len(b) and all(same_row(kept(r), kept(q)) for r, q in zip(a, b))


def stage_start(run: Run, others: list[Run]) -> int:
    """Epoch after which ``run`` trained against its own partner models: the last epoch of
    the longest other run it begins with (it resumed that run) that trained against other
    partners (or whose partners are unknown), else 0."""
    rows, partners = run
    start = 0
    for other, other_partners in others:
        resumed = other and len(other) < len(rows) and same_rows(rows[: len(other)], other)
        changed = partners is None or other_partners is None or other_partners != partners
        if resumed and changed:
            start = max(start, int(other[-1]["epoch"]))
    return start


def minutes_to_mark(rows: list[dict[str, float]], after_epoch: int) -> float | None:
    """Wall minutes at the first evaluation past ``after_epoch`` with success at the end
    >= :data:`TRAINING_MARK`; None where none reaches it."""
    for row in rows:
        if row["epoch"] > after_epoch and row.get(grids.HEADLINE, -1.0) >= TRAINING_MARK:
            return row["time/wall_seconds"] / 60.0
    return None


def read_run(folder: Path) -> Run:
    """``folder``'s metrics rows and the partner models of its config.json (None: none)."""
    config = folder / "config.json"
    partners = json.loads(config.read_text()).get("partners") if config.is_file() else None
    return grids.read_rows(folder / "metrics.csv"), partners


def training_minutes(setups: dict[str, Folders]) -> dict[str, list[float | None]]:
    """{label: per-run minutes to the mark (None: not reached)} of the setups whose every
    folder holds a metrics.csv; a run's stage starts after the other setups' runs it
    resumed against other partners (:func:`stage_start`)."""
    folders = {
        label: list(fs) for label, fs in setups.items() if all((f / "metrics.csv").is_file() for f in fs)
    }
    runs = {label: [read_run(f) for f in fs] for label, fs in folders.items()}

    def starts(label: str, folder: Path) -> list[Run]:
        """The runs ``folder``'s run may have resumed: the other setups' and its sibling
        static run (``benchmarks/partners/seeds.sh``'s layout), where that is not in the
        table."""
        others = [o for k, rs in runs.items() if k != label for o in rs]
        sibling = folder.parent / "static"
        if sibling != folder and (sibling / "metrics.csv").is_file():
            others.append(read_run(sibling))
        return others

    return {
        label: [
            minutes_to_mark(run[0], stage_start(run, starts(label, folder)))
            for run, folder in zip(runs[label], folders[label])
        ]
        for label in runs
    }


def training_row(minutes: list[float | None]) -> list:
    """[mean minutes of the runs that reached the mark, se (None for one), reached, runs]."""
    reached = np.asarray([m for m in minutes if m is not None], np.float64)
    if reached.size == 0:
        return [None, None, 0, len(minutes)]
    se = float(np.std(reached, ddof=1) / math.sqrt(reached.size)) if reached.size > 1 else None
    return [float(reached.mean()), se, int(reached.size), len(minutes)]


def setup_rows(folder: Folders) -> dict[str, tuple[float, float | None]]:
    """{condition: (mean, se)} of one setup, success at the end and naturalness (se None
    for one policy's naturalness)."""
    rows: dict[str, tuple[float, float]] = {}
    orientation = read_json(folder, robustness.ORIENTATION_FILE)
    angles = np.asarray(orientation["angles_deg"])
    grids = np.asarray(orientation["success_final_per_run"])  # (R, n, n)
    episodes = orientation["episodes"]
    centre = len(angles) // 2
    rows["nominal pose"] = mean_se(grids[:, centre, centre], episodes)
    for limit in REGIONS_DEG:
        mask = region_mask(angles, limit)
        if limit <= angles.max() + 1e-9:
            per_run = grids[:, mask].mean(axis=1)
            rows[f"yaw x pitch within +-{limit:g} deg"] = mean_se(per_run, episodes * mask.sum())
    motion = read_json(folder, robustness.MOTION_FILE)
    if motion is not None:
        per_run = np.asarray(motion["success_final_per_run"])
        for i, speed in enumerate(motion["speeds"]):
            rows[f"moving at {speed:g} m/s"] = mean_se(per_run[:, i], motion["episodes"])
    partner = read_json(folder, robustness.PARTNER_FILE)
    if partner is not None:
        per_run = np.asarray(partner["success_final_per_run"])
        for i, name in enumerate(partner["conditions"]):
            label = "static target" if name == "static" else f"{name} partner"
            rows[label] = mean_se(per_run[:, i], partner["episodes"])
    sensing = read_json(folder, robustness.SENSING_FILE)
    if sensing is not None:
        noise = np.asarray(sensing["noise_success_final_per_run"])
        for i, mm in enumerate(sensing["noise_mm"]):
            if mm > 0:
                rows[f"sensing error {mm:g} mm"] = mean_se(noise[:, i], sensing["episodes"])
        delay = np.asarray(sensing["delay_success_final_per_run"])
        for i, steps in enumerate(sensing["delays"]):
            if steps > 0:
                rows[f"action delay {steps} step(s)"] = mean_se(delay[:, i], sensing["episodes"])
    natural = read_json(folder, "naturalness")
    if natural is not None:
        for metric in ("dtw", "jerk"):
            values = np.asarray([p[metric] for p in natural["policies"]], np.float64)
            # One policy has no spread to report (None), not a standard error of 0.
            se = float(np.std(values, ddof=1) / math.sqrt(len(values))) if len(values) > 1 else None
            rows[f"naturalness: {metric}"] = (float(values.mean()), se)
    return rows


def side_by_side(setups: dict[str, Folders]) -> dict:
    """{'task', 'setups', 'rows': [{'condition', label: [mean, se] or None, ...}]} over
    every condition any setup has, in first-seen order (se None for one policy's
    naturalness; the training-cost row :func:`training_row`'s [mean, se, reached, runs]);
    all setups of one task."""
    tasks = {
        label: read_json(folder, robustness.ORIENTATION_FILE)["task"]
        for label, folder in setups.items()
    }
    if len(set(tasks.values())) > 1:
        raise ValueError(f"the setups are of different tasks: {tasks}")
    per_setup = {label: setup_rows(folder) for label, folder in setups.items()}
    for label, minutes in training_minutes(setups).items():
        per_setup[label][TRAINING_ROW] = training_row(minutes)
    conditions = list(dict.fromkeys(c for rows in per_setup.values() for c in rows))
    rows = [
        {"condition": c} | {label: per_setup[label].get(c) for label in setups} for c in conditions
    ]
    return {
        "task": next(iter(tasks.values())),
        "setups": {k: ",".join(str(f) for f in v) for k, v in setups.items()},
        "rows": rows,
    }


def markdown(report: dict) -> str:
    labels = list(report["setups"])
    lines = [
        f"| {report['task']}: condition | " + " | ".join(labels) + " |",
        "|---|" + "---:|" * len(labels),
    ]
    for row in report["rows"]:
        natural = row["condition"].startswith("naturalness")
        cells = []
        for label in labels:
            value = row[label]
            if value is None:
                cells.append("")
            elif row["condition"] == TRAINING_ROW:
                cells.append(training_cell(*value))
            else:
                digits = ".4g" if natural else ".2f"
                spread = "(n = 1)" if value[1] is None else f"± {value[1]:{digits}}"
                cells.append(f"{value[0]:{digits}} {spread}")
        lines.append(f"| {row['condition']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def training_cell(mean: float | None, se: float | None, reached: int, runs: int) -> str:
    """The training-cost cell: mean +- se minutes, and how many runs reached the mark."""
    if mean is None:
        return f"not reached ({runs} run(s))"
    text = f"{mean:.1f} " + ("(n = 1)" if se is None else f"± {se:.1f}")
    return text if reached == runs else f"{text}; {reached} of {runs} reached it"


def plot_heatmaps(setups: dict[str, Folders], path: Path) -> None:
    """Success at the end over yaw x pitch, one heatmap per setup on one colour scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        1, len(setups), figsize=(5.2 * len(setups), 4.6), constrained_layout=True, squeeze=False
    )
    for ax, (label, folder) in zip(axes[0], setups.items()):
        summary = read_json(folder, robustness.ORIENTATION_FILE)
        angles = np.asarray(summary["angles_deg"])
        grid = np.asarray(summary["success_final"])
        image = ax.imshow(grid, origin="lower", vmin=0, vmax=1, cmap="viridis")
        ticks = np.arange(len(angles))
        ax.set_xticks(ticks, [f"{a:g}" for a in angles])
        ax.set_yticks(ticks, [f"{a:g}" for a in angles])
        ax.set_xlabel("yaw, degrees")
        ax.set_ylabel("pitch, degrees")
        for (i, j), value in np.ndenumerate(grid):
            ax.text(j, i, f"{value:.2f}", ha="center", va="center", fontsize=7,
                    color="black" if value > 0.6 else "white")  # fmt: skip
        ax.set_title(f"{label} ({summary['runs']} run(s), {summary['episodes']} episodes a cell)")
    fig.colorbar(image, ax=axes[0].tolist(), label="success at the end")
    fig.suptitle(f"{summary['task']}: success at the end against the target's orientation")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = tyro.cli(ReportArgs, args=sys.argv[1:] if argv is None else argv, description=__doc__)
    try:
        setups = parse_setups(args.setups)
        report = side_by_side(setups)
    except (ValueError, KeyError, json.JSONDecodeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "side_by_side.json").write_text(json.dumps(report, indent=1))
    text = markdown(report)
    (out / "side_by_side.md").write_text(text)
    plot_heatmaps(setups, out / "orientation_side_by_side.png")
    print(text, end="")
    print(f"{out / 'side_by_side.md'}, .json, orientation_side_by_side.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
