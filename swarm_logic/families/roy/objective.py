"""The per-agent gain objective Theta_i (eq. 3.22, digest 001 §2.1.7) over many gain vectors at once, and what an
agent knows when it scores them (``AgentState``, built by ``observe``).

Literal (erratum #3 mode a): k_a ||x_bar - T|| + k_v ||v_i - v_bar|| + k_r sum_j (x_ij / 2r_s - 1) + 1 / (k_OA d^2),
a norm on term 2, d the nearest reading (``d_max`` when nothing echoes). Linear in three gains: its minimum lies on
the bounds (the digest's degeneracy), kept as the thesis prints it.

Look-ahead (erratum #3 mode b): each candidate's u, held for the horizon h (``lookahead_s``; 0 = one ``dt``, the
digest's one-step reading), moves the agent (v' = sat(v + u h), x' = x + v' h), then Theta's state terms are
scored at the predicted state, unweighted by the gains:
w ||x_bar' - T|| + ||v_i' - v_bar'|| + sum_j (x'_ij / 2r_s - 1)^2 + 1 / d'^2 (the cohesion term squared so spacing
*at* 2 r_s is the minimum rather than collapse; d' the predicted distance to the sensed points, ``d_max`` if none).
w = 1 (``progress`` "centroid", the digest's reading) or n ("swarm": the agent's own move counts in full towards
the swarm's progress, as it does in the other terms; with w = 1 a move shifts the first term n times less than
the second, and the optimiser neglects the target).

Weighted look-ahead ("weighted"): eq. 3.22 as printed, gains as weights, scored at the look-ahead's predicted state:
k_a ||x_bar' - T|| + k_v ||v_i' - v_bar'|| + k_r sum_j (x'_ij / 2r_s - 1) + 1 / (k_OA d'^2), the gains entering
both through the motion and as weights (still linear in the weights: the minimum runs to the bounds).

Spacing look-ahead ("spacing"): the look-ahead with the cohesion term summed only over the predicted pairs closer
than 2 r_s (the pairs eq. 3.26's formation matrix counts), so it penalises crowding and never rewards an agent for
pulling its far neighbours closer: 6 agents cannot all be 2 r_s from all 5 others, and "lookahead"'s compromise
packs them.

Every array carries leading batch dimensions S (none for one agent on a robot; (runs, agents) in the numerical
model's batched runner), through the same arithmetic.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm_logic.families.roy import potential

MODES = ("lookahead", "literal", "weighted", "spacing")


@dataclass(frozen=True)
class AgentState:
    """What agent i knows at one step, in thesis units: itself, the swarm means over ``n`` agents (itself
    included), the others' positions (those ``near`` marks are its neighbours), the sensed obstacle points (inf for
    no echo), the law's gain-free basis and extra term. Arrays (S..., ...)."""

    x_i: np.ndarray  # (S, 2)
    v_i: np.ndarray
    x_bar: np.ndarray
    v_bar: np.ndarray
    n: int
    others: np.ndarray  # (S, m, 2)
    points: np.ndarray  # (S, k, 2) obstacle points of the readings (eq. 3.20), inf where nothing echoes
    d_near: np.ndarray  # (S,) the nearest reading, d_max when none
    basis: np.ndarray  # (S, 4, 2), ``potential.law_basis``
    extra: np.ndarray  # (S, 2), the target term (zeros without one)
    target: np.ndarray  # (2,)
    r_s: float
    dt: float
    d_max: float
    v_max: float = np.inf
    near: np.ndarray | None = None  # (S, m) the neighbours among ``others``; None: all of them
    horizon: float | None = None  # the look-ahead's h; None: dt
    progress: str = "centroid"  # the look-ahead's first term: ||x_bar' - T|| ("centroid") or n times it ("swarm")


def observe(x_i: np.ndarray, v_i: np.ndarray, xs: np.ndarray, vs: np.ndarray, heading: np.ndarray | float,
            ranges: np.ndarray, angles: np.ndarray, p: dict[str, Any]) -> AgentState:
    """The state from raw readings in thesis units: own position and velocity (S, 2), the others' (S, m, 2), the
    heading (S,), the sonar ranges (S, k) (inf: no echo) at ``angles`` (k,), and the controller's parameters ``p``
    (``RoyApf.resolve``). Means over all agents, itself included (erratum #4)."""
    n = xs.shape[-2] + 1
    x_bar = (xs.sum(axis=-2) + x_i) / n
    v_bar = (vs.sum(axis=-2) + v_i) / n
    near = None
    if p["neighbour_radius"] > 0 and n > 1:
        dj = xs - x_i[..., None, :]
        near = np.hypot(dj[..., 0], dj[..., 1]) <= p["neighbour_radius"]
    r_s, delta, d_max = float(p["r_s"]), float(p["delta"]), float(p["d_max"])
    points = potential.obstacle_points(x_i, heading, ranges, angles)
    oa = potential.obstacle_avoidance(x_i, points, ranges, r_s, p["oa_mode"], p["oa_law"],
                                      potential.ray_directions(heading, angles))
    target = np.array([p["target_x"], p["target_y"]], float)
    if p["target_term"] == "saturated":
        extra = potential.target_term(x_i, v_i, target, p["k_target"], p["target_sat"], p["target_damping"])
    else:
        extra = np.zeros(np.shape(x_i))
    basis = potential.law_basis(x_i, v_i, x_bar, v_bar, xs, oa, r_s, delta, near)
    d_near = np.maximum(np.minimum(np.min(ranges, axis=-1, initial=np.inf), d_max), 1e-6)
    h = float(p["lookahead_s"]) or None
    return AgentState(x_i, v_i, x_bar, v_bar, n, xs, points, d_near, basis, extra, target, r_s,
                      float(p["period_s"]), d_max, float(p["v_max"]), near, h, p["progress"])


def theta(gains: np.ndarray, s: AgentState, mode: str = "lookahead") -> np.ndarray:
    """Theta for each row of ``gains`` (S..., P, 4) -> (S..., P); ValueError for an unknown ``mode``."""
    k = np.asarray(gains, float)
    if k.ndim == 1:
        k = k[None, :]
    if mode == "literal":
        e = s.x_bar - s.target
        t1 = np.hypot(e[..., 0], e[..., 1])
        e = s.v_i - s.v_bar
        t2 = np.hypot(e[..., 0], e[..., 1])
        if s.others.shape[-2]:
            dj = s.x_i[..., None, :] - s.others
            c = np.hypot(dj[..., 0], dj[..., 1]) / (2 * s.r_s) - 1
            t3 = np.sum(c if s.near is None else np.where(s.near, c, 0.0), axis=-1)
        else:
            t3 = np.zeros(np.shape(t1))
        d2 = np.asarray(s.d_near) ** 2
        return (k[..., 0] * t1[..., None] + k[..., 1] * t2[..., None] + k[..., 2] * t3[..., None]
                + 1.0 / (k[..., 3] * d2[..., None]))
    if mode not in MODES:
        raise ValueError(f"objective: expected one of {', '.join(MODES)}, got {mode!r}")
    h = s.dt if s.horizon is None else s.horizon
    u0, u1 = potential.control_xy(k, s.basis[..., None, :, :], s.extra[..., None, :])  # (S, P) each
    v0, v1 = potential.saturate_xy(s.v_i[..., None, 0] + u0 * h, s.v_i[..., None, 1] + u1 * h, s.v_max)
    x0 = s.x_i[..., None, 0] + v0 * h
    x1 = s.x_i[..., None, 1] + v1 * h
    e0 = s.x_bar[..., None, 0] + (x0 - s.x_i[..., None, 0]) / s.n - s.target[0]  # x_bar' - T
    e1 = s.x_bar[..., None, 1] + (x1 - s.x_i[..., None, 1]) / s.n - s.target[1]
    t1 = np.sqrt(e0 * e0 + e1 * e1)
    if s.progress == "swarm":
        t1 = t1 * s.n
    f0 = v0 - (s.v_bar[..., None, 0] + (v0 - s.v_i[..., None, 0]) / s.n)  # v_i' - v_bar'
    f1 = v1 - (s.v_bar[..., None, 1] + (v1 - s.v_i[..., None, 1]) / s.n)
    t2 = np.sqrt(f0 * f0 + f1 * f1)
    t3 = np.zeros(np.shape(t1))
    m = s.others.shape[-2]
    for j in range(m):  # the cohesion term, neighbour by neighbour (m is small)
        g0 = x0 - s.others[..., None, j, 0]
        g1 = x1 - s.others[..., None, j, 1]
        c = np.sqrt(g0 * g0 + g1 * g1) * (0.5 / s.r_s) - 1
        if mode == "spacing":
            c = np.minimum(c, 0.0)
        if mode != "weighted":
            c = c * c
        t3 = t3 + (c if s.near is None else np.where(s.near[..., None, j], c, 0.0))
    # the obstacle term: the nearest sensed point; readings no agent of the batch has are infinitely far for all
    d2 = np.full(np.shape(t1), np.inf)
    for q in np.flatnonzero(np.isfinite(s.points[..., 0]).reshape(-1, s.points.shape[-2]).any(axis=0)):
        g0 = x0 - s.points[..., None, q, 0]
        g1 = x1 - s.points[..., None, q, 1]
        d2 = np.minimum(d2, g0 * g0 + g1 * g1)
    d = np.minimum(np.maximum(np.sqrt(d2), 1e-6), s.d_max)
    if mode == "weighted":
        return k[..., 0] * t1 + k[..., 1] * t2 + k[..., 2] * t3 + 1.0 / (k[..., 3] * d * d)
    return t1 + t2 + t3 + 1.0 / (d * d)
