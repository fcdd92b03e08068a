"""Statistics of long series in fixed memory: what a session keeps for its summary must not grow with its length
(a soak of hours would otherwise hold a float per quantum or per range)."""

from __future__ import annotations

import math

import numpy as np


class LogHistogram:
    """Quantiles of a long series of values >= 0 in fixed memory: ``per_decade`` bins a decade from ``lo`` to
    ``lo * 10**decades`` (200 a decade: a value is known to 1.2 %); a value at most ``lo`` counts as ``lo``, one
    beyond the top as the top. Barrier times in us keep 1601 counters, not a float per quantum."""

    def __init__(self, lo: float = 1.0, decades: int = 8, per_decade: int = 200) -> None:
        if not (lo > 0 and decades > 0 and per_decade > 0):
            raise ValueError("LogHistogram needs lo > 0, decades > 0 and per_decade > 0")
        self.lo, self.per_decade = float(lo), int(per_decade)
        self.counts = np.zeros(decades * self.per_decade + 1, dtype=np.int64)
        self.n = 0

    def add(self, v: float) -> None:
        k = int(math.log10(v / self.lo) * self.per_decade) if v > self.lo else 0
        self.counts[min(k, len(self.counts) - 1)] += 1
        self.n += 1

    def merge(self, other: LogHistogram) -> None:
        """Add ``other``'s counts (the same bins) to this one."""
        if (other.lo, other.per_decade, other.counts.size) != (self.lo, self.per_decade, self.counts.size):
            raise ValueError("only histograms of the same bins merge")
        self.counts += other.counts
        self.n += other.n

    def quantile(self, q: float) -> float | None:
        """The ``q`` quantile (the middle of its bin, in the value's unit; ``lo`` for the lowest bin), None with no
        value."""
        if not self.n:
            return None
        k = int(np.searchsorted(np.cumsum(self.counts), q * self.n))
        return self.lo if k == 0 else self.lo * 10 ** ((k + 0.5) / self.per_decade)


class Moments:
    """Count, mean, root mean square, extremes and the last value of a series, in fixed memory."""

    __slots__ = ("last", "max", "n", "sum", "sumsq")

    def __init__(self) -> None:
        self.n, self.sum, self.sumsq = 0, 0.0, 0.0
        self.max = -math.inf
        self.last = math.nan

    def add(self, v: float) -> None:
        self.n += 1
        self.sum += v
        self.sumsq += v * v
        self.max = max(self.max, v)
        self.last = v

    def merge(self, other: Moments) -> None:
        self.n += other.n
        self.sum += other.sum
        self.sumsq += other.sumsq
        self.max = max(self.max, other.max)

    @property
    def mean(self) -> float:
        return self.sum / self.n if self.n else 0.0

    @property
    def rms(self) -> float:
        return math.sqrt(self.sumsq / self.n) if self.n else 0.0
