"""The statistics experiments share (bridge/experiments/stats.py): which trials count and the figures over them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.experiments.runner import Outcome, Trial, TrialResult
from bridge.experiments.stats import (
    finite_values,
    iqr,
    mann_whitney,
    mean,
    mean_pm_sd,
    median,
    ok,
    quartiles,
    values,
)


def _outcome(cell: dict, metrics: dict | None) -> Outcome:
    trial = Trial("t", cell, 0, 1, True, "")
    return Outcome(trial, None if metrics is None else TrialResult(metrics), None if metrics else "boom")


def test_ok_keeps_the_successful_trials_of_matching_cells() -> None:
    outs = [_outcome({"n": 1}, {"x": 1.0}), _outcome({"n": 2}, {"x": 2.0}), _outcome({"n": 1}, None)]
    assert [r.metrics["x"] for r in ok(outs)] == [1.0, 2.0]
    assert [r.metrics["x"] for r in ok(outs, n=1)] == [1.0]


def test_values_and_figures_leave_out_missing_metrics() -> None:
    rs = [TrialResult({"x": v}) for v in (1.0, None, 3.0, True)]
    assert values(rs, "x").tolist() == [1.0, 3.0, 1.0]
    assert median(rs, "x") == 1.0 and mean(rs, "x") == pytest.approx(5 / 3)
    assert iqr(rs, "x") == pytest.approx(1.0)
    assert all(math.isnan(f(rs, "y")) for f in (median, mean, iqr))


def test_finite_values_drop_text_and_non_finite_numbers() -> None:
    outs = [_outcome({}, {"x": v}) for v in (1.0, math.inf, math.nan, "a", False)]
    assert finite_values(outs, "x").tolist() == [1.0, 0.0]


def test_quartiles_pm_and_mann_whitney() -> None:
    assert quartiles(np.array([1.0, 2.0, 3.0, 4.0, 5.0])) == (2.0, 3.0, 4.0)
    assert mean_pm_sd(np.array([1.0, 3.0])) == "2.0 +- 1.4" and mean_pm_sd(np.array([2.0])) == "2.0 +- 0.0"
    assert mann_whitney(np.array([1.0]), np.array([2.0, 3.0])) == 1.0  # too few to test
    assert mann_whitney(np.ones(5), np.ones(5)) == 1.0  # all equal
    assert mann_whitney(np.arange(10.0), np.arange(10.0) + 20, "less") < 0.001
