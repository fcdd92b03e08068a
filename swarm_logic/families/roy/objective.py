"""The per-agent gain objective Theta_i (eq. 3.22, digest 001 §2.1.7) over many gain vectors at once.

Literal (erratum #3 mode a): k_a ||x_bar - T|| + k_v ||v_i - v_bar|| + k_r sum_j (x_ij / 2r_s - 1) + 1 / (k_OA d^2),
a norm on term 2, d the nearest reading (``d_max`` when nothing echoes). Linear in three gains: its minimum lies on
the bounds (the digest's degeneracy), kept as the thesis prints it.

Look-ahead (erratum #3 mode b): each candidate moves the agent one ``dt`` (semi-implicit Euler of eq. 3.1 under
eqs. 3.3-3.5, 3.21), then Theta's state terms are scored at the predicted state, unweighted by the gains:
||x_bar' - T|| + ||v_i' - v_bar'|| + sum_j (x'_ij / 2r_s - 1)^2 + 1 / d'^2 (the cohesion term squared so spacing
*at* 2 r_s is the minimum rather than collapse; d' the predicted distance to the sensed points, ``d_max`` if none).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MODES = ("lookahead", "literal")


@dataclass(frozen=True)
class AgentState:
    """What agent i knows at one step, in thesis units: itself, the swarm means over ``n`` agents (itself
    included), the others' positions, the sensed obstacle points, the law's gain-free basis and extra term."""

    x_i: np.ndarray
    v_i: np.ndarray
    x_bar: np.ndarray
    v_bar: np.ndarray
    n: int
    others: np.ndarray  # (m, 2)
    points: np.ndarray  # (k, 2) obstacle points of the finite readings (eq. 3.20)
    d_near: float  # the nearest reading, d_max when none
    basis: np.ndarray  # (4, 2), ``potential.law_basis``
    extra: np.ndarray  # (2,), the target term (zeros without one)
    target: np.ndarray
    r_s: float
    dt: float
    d_max: float
    v_max: float = np.inf


def theta(gains: np.ndarray, s: AgentState, mode: str = "lookahead") -> np.ndarray:
    """Theta for each row of ``gains`` (P, 4) -> (P,); ValueError for an unknown ``mode``."""
    k = np.atleast_2d(np.asarray(gains, float))
    if mode == "literal":
        t1 = float(np.hypot(*(s.x_bar - s.target)))
        t2 = float(np.hypot(*(s.v_i - s.v_bar)))
        t3 = float(np.sum(np.hypot(*(s.x_i[None, :] - s.others).T) / (2 * s.r_s) - 1)) if len(s.others) else 0.0
        return k[:, 0] * t1 + k[:, 1] * t2 + k[:, 2] * t3 + 1.0 / (k[:, 3] * s.d_near ** 2)
    if mode != "lookahead":
        raise ValueError(f"objective: expected one of {', '.join(MODES)}, got {mode!r}")
    u = k @ s.basis + s.extra  # (P, 2)
    v = s.v_i[None, :] + u * s.dt
    speed = np.hypot(v[:, 0], v[:, 1])
    over = speed > s.v_max
    if np.any(over):
        v[over] *= (s.v_max / speed[over])[:, None]
    x = s.x_i[None, :] + v * s.dt
    x_bar = s.x_bar[None, :] + (x - s.x_i[None, :]) / s.n
    v_bar = s.v_bar[None, :] + (v - s.v_i[None, :]) / s.n
    t1 = np.hypot(*(x_bar - s.target[None, :]).T)
    t2 = np.hypot(*(v - v_bar).T)
    if len(s.others):
        dij = np.hypot(x[:, None, 0] - s.others[None, :, 0], x[:, None, 1] - s.others[None, :, 1])
        t3 = np.sum((dij / (2 * s.r_s) - 1) ** 2, axis=1)
    else:
        t3 = np.zeros(len(k))
    if len(s.points):
        dp = np.hypot(x[:, None, 0] - s.points[None, :, 0], x[:, None, 1] - s.points[None, :, 1]).min(axis=1)
        d = np.minimum(np.maximum(dp, 1e-6), s.d_max)
    else:
        d = np.full(len(k), s.d_max)
    return t1 + t2 + t3 + 1.0 / d ** 2
