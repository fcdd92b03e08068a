"""Initial-deployment geometry: spiral of Theodorus and the Extended Spiral of Theodorus (EST), §5.1.

Index convention (the thesis's own, eq. 5.1-5.5): robot n = 1, 2, ... sits at the far vertex of the n-th right
triangle of the spiral, at radius d_max sqrt(n+1) and angle phi_n = sigma sum_{k=1..n} arctan(1/sqrt k). The leg
from robot n to robot n+1 is perpendicular to robot n's radius, which makes consecutive robots exactly d_max apart;
the spiral's unit vertex (radius d_max, angle phi_0) is the centre-side start of the spiral and holds no robot.
"""

from __future__ import annotations

import math

from swarm_logic.geometry import check_sigma, theodorus_angles, theodorus_spiral

__all__ = ["theodorus_angles", "theodorus_spiral"]  # plane geometry: one definition, in swarm_logic.geometry


def est_next(x_i: tuple[float, float], x_i1: tuple[float, float], theta_i1: float | None, d: float, i: int,
             sigma: int) -> tuple[float, float]:
    """Desired position of scout i+2 from scouts i and i+1 (EST, eq. 5.3-5.5), with the spiral index i >= 1.

    eq. 5.3: centre x0 = x_i - d sqrt(i+1) [cos(theta_{i+1} - sigma 90°), sin(...)], i.e. one radius back from
    scout i, perpendicular to the leg i -> i+1 whose heading is theta_{i+1} (the ranger's heading when it unloaded
    scout i+1, its pose theta_{i+1}[0]);
    eq. 5.4: orientation phi0 = phi'_i - phi_i, phi'_i being the bearing of x_i seen from x0;
    eq. 5.5: x_{i+2} = x0 + d sqrt(i+3) [cos(phi_{i+2} + phi0), sin(...)], phi from eq. 5.1 with the same sigma.

    With i counted as in eq. 5.2 (scout i at radius sqrt(i+1), so the first pair is i = 1 at sqrt 2) the equations
    hold as printed: with exact legs they reproduce the ideal spiral, and the result equals
    x_{i+1} + d R(sigma 90°) (x_{i+1} - x0)/|x_{i+1} - x0|. Note that eq. 5.3-5.5 do not use x_{i+1} itself, only
    the leg heading; ``x_i1`` supplies that heading (bearing x_i -> x_i1) when ``theta_i1`` is None. ``d`` is the
    measured leg length |x_{i+1} - x_i| (each pair gets its own spiral, so unequal legs are allowed).
    """
    check_sigma(sigma)
    if i < 1:
        raise ValueError(f"spiral index i must be >= 1 (scout i at radius sqrt(i+1)), got {i}")
    if theta_i1 is None:
        theta_i1 = math.atan2(x_i1[1] - x_i[1], x_i1[0] - x_i[0])
    radial = theta_i1 - sigma * (math.pi / 2.0)
    r_i = d * math.sqrt(i + 1)
    cx = x_i[0] - r_i * math.cos(radial)  # eq. 5.3
    cy = x_i[1] - r_i * math.sin(radial)
    phi_prime = math.atan2(x_i[1] - cy, x_i[0] - cx)
    # eq. 5.1 partial sums: phi_{i+2} - phi_i only needs the two extra terms.
    phi_i = sigma * sum(math.atan(1.0 / math.sqrt(k)) for k in range(1, i + 1))
    phi_i2 = phi_i + sigma * (math.atan(1.0 / math.sqrt(i + 1)) + math.atan(1.0 / math.sqrt(i + 2)))
    phi0 = phi_prime - phi_i  # eq. 5.4
    r2 = d * math.sqrt(i + 3)
    return cx + r2 * math.cos(phi_i2 + phi0), cy + r2 * math.sin(phi_i2 + phi0)  # eq. 5.5


def k_first_distance_ratio(k: int) -> float:
    """d/d_max for the first pair of a k-connected deployment (eq. 5.7, law of cosines).

    d = d_max / sqrt(4 + k - sqrt(8k + 16) cos(sum_{j=2..k+1} arctan(1/sqrt j))): 1.000, 0.525, 0.373, 0.301,
    0.262 for k = 1..5 (eq. 5.8 approximates it by 1/k).
    """
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k}")
    ang = sum(math.atan(1.0 / math.sqrt(j)) for j in range(2, k + 2))
    return 1.0 / math.sqrt(4.0 + k - math.sqrt(8.0 * k + 16.0) * math.cos(ang))


def k_first_threshold_dbm(q_min_dbm: float, k: int) -> float:
    """RSSI at which the ranger unloads scout 2 for k-connectivity: k q_min in linear units (eq. 5.6, 5.13).

    10 log10(k 10^(q_min/10)) = q_min + 10 log10 k, e.g. k = 2, q_min = -75 dBm -> -71.99 dBm.
    """
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k}")
    return q_min_dbm + 10.0 * math.log10(k)
