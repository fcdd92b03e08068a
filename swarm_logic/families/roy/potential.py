"""The chapter 3 control law in thesis units (digest 001 §2.1.2-2.1.6): u = -u^a + u^r + u^OA (+ a target term,
erratum #2). Every term is linear in one gain, so ``law_basis`` returns the four gain-free vectors and the law is
``gains @ basis + extra``: an optimiser evaluates many gain vectors at the cost of one."""

from __future__ import annotations

import numpy as np


def repulsion(x_i: np.ndarray, others: np.ndarray, r_s: float, delta: float) -> np.ndarray:
    """Eq. 3.4 summed over the neighbours (eq. 3.5) without its gain: sum_j exp(-x_ij^2 / (delta r_s^2)) (x_i - x_j)."""
    if len(others) == 0:
        return np.zeros(2)
    diff = x_i[None, :] - others
    w = np.exp(-np.sum(diff * diff, axis=1) / (delta * r_s * r_s))
    return (w[:, None] * diff).sum(axis=0)


def obstacle_points(x_i: np.ndarray, heading: float, ranges: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Eq. 3.20: the world point of each finite reading, x_i + d [cos(theta + beta), sin(theta + beta)]."""
    ok = np.isfinite(ranges)
    d, a = ranges[ok], angles[ok] + heading
    return x_i[None, :] + d[:, None] * np.stack([np.cos(a), np.sin(a)], axis=1)


def obstacle_avoidance(x_i: np.ndarray, points: np.ndarray, dists: np.ndarray, r_s: float,
                       mode: str = "per_sensor") -> np.ndarray:
    """Eq. 3.21 without its gain: exp(-d^2 / r_s^2) (x_i - O) for each reading within r_s (``per_sensor``), or for
    the nearest one only (``nearest``); zero when none is within r_s (target A2)."""
    near = dists <= r_s
    if not np.any(near):
        return np.zeros(2)
    p, d = points[near], dists[near]
    if mode == "nearest":
        k = int(np.argmin(d))
        p, d = p[k:k + 1], d[k:k + 1]
    w = np.exp(-d * d / (r_s * r_s))
    return (w[:, None] * (x_i[None, :] - p)).sum(axis=0)


def target_term(x_i: np.ndarray, v_i: np.ndarray, target: np.ndarray, k_target: float, sat: float,
                damping: float) -> np.ndarray:
    """Erratum #2's target term [R]: -k_T sat(x_i - T) - k_D v_i, the offset clipped to length ``sat`` so the pull
    is bounded, the damping so the swarm stops at T (the law damps only velocity differences)."""
    e = x_i - target
    n = float(np.hypot(e[0], e[1]))
    if n > sat > 0:
        e = e * (sat / n)
    return -k_target * e - damping * v_i


def law_basis(x_i: np.ndarray, v_i: np.ndarray, x_bar: np.ndarray, v_bar: np.ndarray, others: np.ndarray,
              oa: np.ndarray, r_s: float, delta: float) -> np.ndarray:
    """The (4, 2) vectors the gains (k_a, k_v, k_r, k_OA) multiply in eq. 3.5 + eq. 3.21: -(x_i - x_bar),
    -(v_i - v_bar), the repulsion sum, the obstacle term ``oa`` (``obstacle_avoidance``)."""
    return np.stack([-(x_i - x_bar), -(v_i - v_bar), repulsion(x_i, others, r_s, delta), oa])


def control(gains: np.ndarray, basis: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
    """u for one gain vector (4,) -> (2,) or many (P, 4) -> (P, 2): gains @ basis + ``extra`` (the target term)."""
    u = np.asarray(gains, float) @ basis
    return u if extra is None else u + extra


def pair_spacing(k_a: float, k_r: float, r_s: float = 1.0, delta: float = 4.0) -> float:
    """The two-agent equilibrium (digest §2.1.4 [D]): d* = r_s sqrt(delta ln(2 k_r / k_a)); ValueError unless
    2 k_r > k_a (no equilibrium otherwise)."""
    if not 2 * k_r > k_a > 0:
        raise ValueError(f"k_a, k_r: a pair has an equilibrium only when 2 k_r > k_a > 0, got {k_a}, {k_r}")
    return r_s * float(np.sqrt(delta * np.log(2 * k_r / k_a)))
