"""The statistics every report uses: mean and standard error, Welch's t-test and the
Holm-Bonferroni correction (a library: the grids' report, naturalness and the rating
study's report read it)."""

from __future__ import annotations

import math

import numpy as np

ALPHA = 0.05
"""Two-sided significance level of the reports' tests."""


def mean_se(values) -> tuple[float, float]:
    """Mean and standard error (sample std / sqrt(n); 0 for one value) of the finite values."""
    x = np.asarray([v for v in values if math.isfinite(v)], float)
    if x.size == 0:
        return math.nan, math.nan
    se = float(x.std(ddof=1) / math.sqrt(x.size)) if x.size > 1 else 0.0
    return float(x.mean()), se


def welch(a, b) -> tuple[float, float]:
    """Welch's two-sided t-test of mean(a) != mean(b): (t, p). Samples without spread
    compare exactly: p = 1 when the means are equal, else 0."""
    from scipy import stats

    a, b = np.asarray(a, float), np.asarray(b, float)
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if len(a) < 2 or len(b) < 2:
        return math.nan, math.nan
    if a.std() == 0 and b.std() == 0:
        same = a.mean() == b.mean()
        return (0.0, 1.0) if same else (math.copysign(math.inf, a.mean() - b.mean()), 0.0)
    result = stats.ttest_ind(a, b, equal_var=False)
    return float(result.statistic), float(result.pvalue)


def holm(p_values: list[float]) -> list[float]:
    """Holm-Bonferroni adjusted p-values (same order; NaN stays NaN): the family-wise
    error over all of the statements' tests stays below ``ALPHA`` when each adjusted p is
    compared with it."""
    finite = sorted((p, i) for i, p in enumerate(p_values) if math.isfinite(p))
    adjusted = [math.nan] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(finite):
        running = max(running, min(1.0, (len(finite) - rank) * p))
        adjusted[i] = running
    return adjusted
