"""Table I of the study: the raters' preference for the imitation policy, per task.

Every answer (0..4 on the page) becomes its signed preference for the imitation policy,
-2..+2, through key.json's left/right assignment (:func:`layout.answer_value`). Per task
(and over all tasks) and per kind of start (``regular``, ``non_smooth`` and ``all``) the
table gives the number of answers, the share of each value, the mean, its standard
error and two two-sided tests of "mean 0" (no preference): Student's one-sample t-test
and the exact sign test (ties dropped). Like the paper, every answer counts as one
observation, although a rater's answers are not independent of each other.

Writes ``table1.csv``, ``table1.json`` and ``table1.png`` (stacked bars of the shares
with the mean beside them).
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy import stats

from mjx_hands.study import layout, store

VALUES: tuple[int, ...] = (-2, -1, 0, 1, 2)
KIND_ALL = "all"
TASK_ALL = "all"
CSV_FILE = "table1.csv"
JSON_FILE = "table1.json"
PLOT_FILE = "table1.png"


def share_key(value: int) -> str:
    """Column of the share of answers with signed value ``value``: share_-2 ... share_+2."""
    return f"share_{value:+d}" if value else "share_0"


class Rating(NamedTuple):
    """One answer joined with its pair and key: ``value`` in -2..+2 favours imitation."""

    rater: str
    pair_id: str
    task: str
    kind: str
    answer: int
    value: int


# ----------------------------------------------------------------- statistics
def one_sample_t_test(values: Sequence[float], mu: float = 0.0) -> tuple[float, float]:
    """Two-sided one-sample t-test of mean(values) == mu: (t, p), df = n - 1.

    NaN for fewer than two values; a sample without spread compares exactly (t = 0 and
    p = 1 when its mean is ``mu``, else t = +-inf and p = 0).
    """
    x = np.asarray(values, float)
    if x.size < 2:
        return math.nan, math.nan
    diff = float(x.mean()) - mu
    sd = float(x.std(ddof=1))
    if sd == 0.0:
        return (0.0, 1.0) if diff == 0.0 else (math.copysign(math.inf, diff), 0.0)
    result = stats.ttest_1samp(x, mu)
    return float(result.statistic), float(result.pvalue)


def sign_test(values: Sequence[float]) -> float:
    """Exact two-sided sign test of median 0: p of a split at least as uneven as the
    observed positives vs negatives under Binomial(m, 1/2); zeros dropped (p = 1 if none
    remain)."""
    x = np.asarray(values, float)
    positive, negative = int((x > 0).sum()), int((x < 0).sum())
    m = positive + negative
    if m == 0:
        return 1.0
    return float(stats.binomtest(positive, m, 0.5).pvalue)


# --------------------------------------------------------------------- table
def load_ratings(study: layout.Study, answers: Sequence[store.Answer]) -> list[Rating]:
    """``answers`` joined with the study's pairs and key; ValueError for an answer to a
    pair the study does not list (the database belongs to another study)."""
    unknown = sorted({a.pair_id for a in answers if study.pair(a.pair_id) is None})
    if unknown:
        raise ValueError(
            f"{study.answers_path} holds answers to pairs {unknown} that "
            f"{study.dir / layout.STUDY_FILE} does not list: answers and study do not match"
        )
    ratings = []
    for a in answers:
        pair = study.pair(a.pair_id)
        assert pair is not None
        value = layout.answer_value(a.answer, study.key[a.pair_id].left)
        ratings.append(Rating(a.rater, a.pair_id, pair.task, pair.kind, a.answer, value))
    return ratings


def summarize(values: Sequence[int]) -> dict[str, Any]:
    """n, the share of each value -2..+2 (``share_-2`` ...), mean, standard error, the
    t statistic, its df and p, and the sign test's p, of signed preferences."""
    x = np.asarray(values, float)
    n = int(x.size)
    t, p_t = one_sample_t_test(x)
    return {
        "n": n,
        **{share_key(v): float((x == v).mean()) for v in VALUES},
        "mean": float(x.mean()),
        "se": float(x.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan,
        "t": t,
        "df": n - 1,
        "p_t": p_t,
        "p_sign": sign_test(x),
    }


def table1(study: layout.Study, ratings: Sequence[Rating]) -> list[dict[str, Any]]:
    """Rows of Table I: per task in study order, then all tasks together; per kind
    (regular, non_smooth, all); groups without answers are left out. Each row:
    ``task``, ``kind``, ``pairs`` (rated pairs), ``raters`` and :func:`summarize`'s fields."""
    tasks = list(dict.fromkeys(p.task for p in study.pairs))
    rows = []
    for task in [*tasks, TASK_ALL]:
        for kind in [*layout.KINDS, KIND_ALL]:
            group = [
                r for r in ratings if task in (TASK_ALL, r.task) and kind in (KIND_ALL, r.kind)
            ]
            if not group:
                continue
            rows.append(
                {
                    "task": task,
                    "kind": kind,
                    "pairs": len({r.pair_id for r in group}),
                    "raters": len({r.rater for r in group}),
                    **summarize([r.value for r in group]),
                }
            )
    return rows


def _finite_or_none(value: Any) -> Any:
    return None if isinstance(value, float) and not math.isfinite(value) else value


def write_csv(rows: Sequence[dict[str, Any]], path: Path) -> None:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if _finite_or_none(v) is None else v for k, v in row.items()})


def plot(rows: Sequence[dict[str, Any]], path: Path, title: str) -> None:
    """Stacked horizontal bars of the answer shares per (task, kind), mean beside them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = plt.get_cmap("RdBu")(np.linspace(0.1, 0.9, len(VALUES)))
    names = {
        -2: "-2 (no imitation much more natural)",
        0: "0",
        2: "+2 (imitation much more natural)",
    }
    fig, ax = plt.subplots(figsize=(10, 0.45 * len(rows) + 1.4), layout="constrained")
    y = np.arange(len(rows))[::-1]
    left = np.zeros(len(rows))
    for value, color in zip(VALUES, colors):
        shares = np.asarray([r[share_key(value)] for r in rows])
        label = names.get(value, f"{value:+d}")
        ax.barh(y, shares, left=left, color=color, edgecolor="white", label=label)
        left += shares
    for yi, r in zip(y, rows):
        se = "" if not math.isfinite(r["se"]) else f" ± {r['se']:.2f}"
        p = "" if not math.isfinite(r["p_t"]) else f", p={r['p_t']:.2g}"
        ax.text(1.02, yi, f"mean {r['mean']:+.2f}{se} (n={r['n']}{p})", va="center", fontsize=9)
    ax.set_yticks(y, [f"{r['task']} ({r['kind']})" for r in rows])
    ax.set_xlim(0, 1)
    ax.set_xlabel("share of answers")
    ax.set_title(title)
    fig.legend(loc="outside lower center", ncol=len(VALUES), fontsize=8, frameon=False)
    # bbox_inches="tight" keeps the mean texts right of the axes in the picture.
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def write_report(
    study_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str] | None = None
) -> list[dict[str, Any]]:
    """Table I of the study in ``study_dir`` into ``out_dir`` (default: the study folder)
    as table1.csv/.json/.png; returns its rows. ValueError when nobody answered yet."""
    study = layout.read_study(study_dir)
    answers = store.read_answers(study.answers_path)
    if not answers:
        raise ValueError(
            f"{study.answers_path}: no answers yet; serve the study "
            f"(python -m mjx_hands.study serve {study.dir}) and collect ratings first"
        )
    ratings = load_ratings(study, answers)
    rows = table1(study, ratings)
    out = Path(study.dir if out_dir is None else out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(rows, out / CSV_FILE)
    record = {
        "study": study.name,
        "answers": len(ratings),
        "raters": len({r.rater for r in ratings}),
        "values": "signed preference for the imitation policy, -2..+2",
        "rows": [{k: _finite_or_none(v) for k, v in row.items()} for row in rows],
    }
    (out / JSON_FILE).write_text(json.dumps(record, indent=2) + "\n")
    plot(rows, out / PLOT_FILE, f"{study.name}: preference for the imitation policy")
    return rows


def format_rows(rows: Sequence[dict[str, Any]]) -> str:
    """The table as aligned text lines for the terminal."""
    lines = [f"{'task':<12}{'kind':<12}{'n':>5}{'mean':>8}{'se':>7}{'p (t)':>9}{'p (sign)':>10}"]
    for r in rows:
        se = f"{r['se']:.2f}" if math.isfinite(r["se"]) else "-"
        p_t = f"{r['p_t']:.3g}" if math.isfinite(r["p_t"]) else "-"
        lines.append(
            f"{r['task']:<12}{r['kind']:<12}{r['n']:>5}{r['mean']:>+8.2f}{se:>7}{p_t:>9}"
            f"{r['p_sign']:>10.3g}"
        )
    return "\n".join(lines)
