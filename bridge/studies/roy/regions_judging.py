"""What the roy-regions judges share (the experiment's own, and those of its chapter and cell-kind modules): a
verdict, a figure as a report cell shows it, a scenario's whole runs, "no runs" with its reason, and a test every
run passes."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from bridge.experiments.runner import Outcome, TrialResult
from bridge.experiments.stats import ok

Verdict = tuple[str, bool | None, str]  # what we measured, pass/fail (None: not judged), the note


def fmt(x: Any, nd: int = 2) -> str:
    """A figure with ``nd`` decimals, "-" for none or NaN."""
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{nd}f}"


def whole(outcomes: list[Outcome], scenario: str, **cell: Any) -> list[TrialResult]:
    """The results of a scenario's whole runs in the cells matching ``cell``: a smoke run's stop early."""
    return ok([o for o in outcomes if not o.trial.smoke], scenario=scenario, **cell)


def no_runs(outcomes: list[Outcome], need: str, smoke: str = "smoke run: the missions stop early") -> Verdict:
    """Not judged for want of whole runs: ``smoke`` in a smoke run, else ``need`` says what is missing."""
    return "no runs", None, smoke if any(o.trial.smoke for o in outcomes) else need


def every(res: list[TrialResult], test: Callable[[dict[str, Any]], bool]) -> bool:
    """Whether there are runs and every one's metrics pass ``test``."""
    return bool(res) and all(test(r.metrics) for r in res)
