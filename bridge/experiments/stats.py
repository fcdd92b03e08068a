"""The statistics experiments judge and report with: which trials count, a metric's values over them, medians,
quartiles, means, pooled means and tests.

One module, so every experiment (and the report's tables) computes a figure the same way and no experiment module
borrows another's helpers. Nothing here knows an experiment: a metric is a name in ``TrialResult.metrics``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from bridge.experiments.runner import Outcome, TrialResult


def ok(outcomes: list[Outcome], **cell: Any) -> list[TrialResult]:
    """The results of the trials that ran without error, in the cells whose values match ``cell``."""
    return [o.result for o in outcomes if o.result is not None
            and all(o.trial.cell.get(k) == v for k, v in cell.items())]


def values(results: list[TrialResult], metric: str) -> np.ndarray:
    """A metric's values as floats over the results that have it (None: left out; bools as 0/1)."""
    return np.array([float(r.metrics[metric]) for r in results if r.metrics.get(metric) is not None], float)


def finite_values(outcomes: list[Outcome], metric: str) -> np.ndarray:
    """A numeric metric's finite values (bools as 0/1) over the successful trials; text, NaN and inf left out."""
    vals = [o.result.metrics.get(metric) for o in outcomes if o.result is not None]
    nums = np.array([float(v) for v in vals if isinstance(v, int | float)], dtype=float)
    return nums[np.isfinite(nums)]


def median(results: list[TrialResult], metric: str) -> float:
    """A metric's median over the results (NaN when none has it)."""
    v = values(results, metric)
    return float(np.median(v)) if len(v) else math.nan


def mean(results: list[TrialResult], metric: str) -> float:
    """A metric's mean over the results (NaN when none has it); of a bool metric, the share that is true."""
    v = values(results, metric)
    return float(np.mean(v)) if len(v) else math.nan


def iqr(results: list[TrialResult], metric: str) -> float:
    """A metric's interquartile range (75th - 25th percentile) over the results (NaN when none has it)."""
    v = values(results, metric)
    return float(np.subtract(*np.percentile(v, [75, 25]))) if len(v) else math.nan


def quartiles(v: np.ndarray) -> tuple[float, float, float]:
    """The 25th, 50th and 75th percentiles of a non-empty sample."""
    q25, q50, q75 = np.percentile(v, [25, 50, 75])
    return q25, q50, q75


def mean_pm_sd(v: np.ndarray, nd: int = 1) -> str:
    """``mean +- sample sd`` to ``nd`` decimals (sd 0 for a single value)."""
    return f"{np.mean(v):.{nd}f} +- {np.std(v, ddof=1) if len(v) > 1 else 0.0:.{nd}f}"


def pooled_mean_sd(results: list[TrialResult], key: str) -> tuple[float, float, int]:
    """Mean and sample sd over all samples of all trials, from each trial's ``{key}_mean``, ``{key}_sd`` and
    ``{key}_n`` (its own samples' mean, sd and count); (NaN, NaN, 0) without samples."""
    parts = [(r.metrics.get(f"{key}_mean"), r.metrics.get(f"{key}_sd"), r.metrics.get(f"{key}_n")) for r in results]
    parts = [(float(m), float(s), int(n)) for m, s, n in parts if m is not None and n]
    total = sum(n for *_, n in parts)
    if not total:
        return math.nan, math.nan, 0
    mu = sum(m * n for m, _, n in parts) / total
    ss = sum((n - 1) * s * s + n * (m - mu) ** 2 for m, s, n in parts)
    return mu, math.sqrt(ss / max(1, total - 1)), total


def mann_whitney(a: np.ndarray, b: np.ndarray, alternative: str = "two-sided") -> float:
    """The Mann-Whitney U test's p-value; 1 when a sample has fewer than 2 values or all values are equal."""
    from scipy import stats

    if len(a) < 2 or len(b) < 2 or (np.all(a == a[0]) and np.all(b == a[0])):
        return 1.0
    return float(stats.mannwhitneyu(a, b, alternative=alternative).pvalue)
