"""argparse value types shared by every ``swarm-sitl`` subcommand: one place, one wording of each error."""

from __future__ import annotations

import argparse
from typing import Any


def speed(v: str) -> float | str:
    """An argparse type: a real-time factor > 0, or ``max`` (as fast as the machine goes)."""
    if v == "max":
        return "max"
    try:
        f = float(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--speed: expected a positive number or 'max', got {v!r}") from None
    if f <= 0:
        raise argparse.ArgumentTypeError("--speed must be > 0")
    return f


def at_least_one(v: str) -> int:
    """An argparse type: a whole number >= 1 (counts: robots, trials, inputs)."""
    try:
        n = int(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {v!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {n}")
    return n


def numbers(cast: type, least: float, example: str) -> Any:
    """An argparse type: comma-separated numbers, each at least ``least`` (e.g. ``1,2``)."""

    def parse(v: str) -> list:
        try:
            out = [cast(x) for x in v.split(",")]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected numbers such as {example}, got {v!r}") from None
        if not all(x >= least for x in out):
            raise argparse.ArgumentTypeError(f"each must be >= {least}, got {v}")
        return out

    return parse


def positive(v: str) -> float:
    """An argparse type: a number of seconds > 0 (timeouts, wall limits)."""
    try:
        f = float(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0, got {v!r}") from None
    if not f > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {v}")
    return f
