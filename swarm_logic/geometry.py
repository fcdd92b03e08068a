"""Plane geometry the swarm logic shares."""

from __future__ import annotations

import math


def wrap(a: float) -> float:
    """Angle ``a`` folded into (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))
