"""The Lennard-Jones interaction between searchers (Khan eq. 1; K-3) as a radial speed: positive pulls towards the
neighbour, negative pushes away."""

from __future__ import annotations

import math


def generalised_lj(d: float, delta: float, gain: float, k: float) -> float:
    """ARGoS's flocking form f(d) = -(G/d) [(delta/d)^2k - (delta/d)^k]: zero at ``delta``, repulsive inside it,
    attractive beyond. With ``k`` = 6 it is the 12-6 shape of eq. 1 with its minimum at ``delta``."""
    r = (delta / d) ** k
    return -(gain / d) * (r * r - r)


def classic_lj(d: float, epsilon: float, sigma: float) -> float:
    """-dV/dd of eq. 1, V = 4 eps [(sigma/d)^12 - (sigma/d)^6], with the sign of ``generalised_lj`` (positive
    attracts): zero at 2^(1/6) sigma."""
    r6 = (sigma / d) ** 6
    return -(24.0 * epsilon / d) * (2.0 * r6 * r6 - r6)


def lj_vector(neighbours: list[tuple[float, float]], force: object, cutoff: float) -> tuple[float, float]:
    """The mean of ``force(d)`` along each bearing over the (range, bearing) pairs within ``cutoff`` (ARGoS
    flocking: divided by their number); (0, 0) with none. One pass: linear in the neighbours (K-U3)."""
    fx = fy = 0.0
    n = 0
    for d, b in neighbours:
        if 0.0 < d < cutoff:
            f = force(d)  # type: ignore[operator]
            fx += f * math.cos(b)
            fy += f * math.sin(b)
            n += 1
    return (fx / n, fy / n) if n else (0.0, 0.0)
