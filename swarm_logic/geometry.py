"""Plane geometry the swarm logic shares."""

from __future__ import annotations

import math


def wrap(a: float) -> float:
    """Angle ``a`` folded into (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))


def clamp(vx: float, vy: float, dx_max: float) -> tuple[float, float]:
    """Scale (vx, vy) down to length dx_max if longer, keeping its direction (|v| <= dx_max): the RDPSO's eq. 4.6, and
    every baseline's step."""
    n2 = vx * vx + vy * vy
    if n2 <= dx_max * dx_max:
        return vx, vy
    s = dx_max / math.sqrt(n2)
    return vx * s, vy * s


# The spiral of Theodorus (Couceiro 2013, eq. 5.1-5.2): robots placed along it are d_max apart, each leg
# perpendicular to the last robot's radius. The simulator's spiral placement and the RDPSO's deployment use it.


def check_sigma(sigma: int) -> None:
    if sigma not in (1, -1):
        raise ValueError(f"sigma (spiral turn direction) must be +1 or -1, got {sigma!r}")


def theodorus_angles(n: int, sigma: int = 1) -> list[float]:
    """phi_1..phi_n of eq. 5.1: phi_m = sigma sum_{k=1..m} arctan(1/sqrt(k)) [rad] (45°, 80.26°, 110.26°, ...)."""
    check_sigma(sigma)
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    out: list[float] = []
    acc = 0.0
    for k in range(1, n + 1):
        acc += math.atan(1.0 / math.sqrt(k))
        out.append(sigma * acc)
    return out


def theodorus_spiral(n: int, d_max: float, x0: tuple[float, float] = (0.0, 0.0), phi0: float = 0.0,
                     sigma: int = 1) -> list[tuple[float, float]]:
    """Positions of robots 1..n on the spiral of Theodorus with legs d_max (eq. 5.2).

    x_m = x0 + d_max sqrt(m+1) [cos(phi_m + phi0), sin(phi_m + phi0)]: consecutive robots are d_max apart and
    robot m is d_max sqrt(m+1) from the centre x0.
    """
    return [(x0[0] + d_max * math.sqrt(m + 1) * math.cos(phi + phi0),
             x0[1] + d_max * math.sqrt(m + 1) * math.sin(phi + phi0))
            for m, phi in enumerate(theodorus_angles(n, sigma), start=1)]

