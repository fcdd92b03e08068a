"""The chapter 3 control law in thesis units (digest 001 §2.1.2-2.1.6): u = -u^a + u^r + u^OA (+ a target term,
erratum #2). Every term is linear in one gain, so ``law_basis`` returns the four gain-free vectors and the law is
``gains . basis + extra``: an optimiser evaluates many gain vectors at the cost of one.

Every function takes leading batch dimensions (``...``): one agent on a robot, or every agent of many runs at once
in the numerical model, through the same arithmetic (the same numbers either way, element by element).
"""

from __future__ import annotations

import numpy as np

OA_LAWS = ("literal", "bounded")


def repulsion(x_i: np.ndarray, others: np.ndarray, r_s: float, delta: float,
              near: np.ndarray | None = None) -> np.ndarray:
    """Eq. 3.4 summed over the neighbours (eq. 3.5) without its gain: sum_j exp(-x_ij^2 / (delta r_s^2)) (x_i - x_j).
    ``x_i`` (..., 2), ``others`` (..., m, 2); ``near`` (..., m) keeps only the neighbours it marks."""
    if others.shape[-2] == 0:
        return np.zeros(np.shape(x_i))
    diff = x_i[..., None, :] - others
    w = np.exp(-np.sum(diff * diff, axis=-1) / (delta * r_s * r_s))
    if near is not None:
        w = np.where(near, w, 0.0)
    return (w[..., None] * diff).sum(axis=-2)


def obstacle_points(x_i: np.ndarray, heading: np.ndarray | float, ranges: np.ndarray,
                    angles: np.ndarray) -> np.ndarray:
    """Eq. 3.20: the world point x_i + d [cos(theta + beta), sin(theta + beta)] of each reading (..., k, 2); a
    reading with no echo (``inf``) gives an infinite point."""
    ok = np.isfinite(ranges)
    d = np.where(ok, ranges, 0.0)
    p = x_i[..., None, :] + d[..., None] * ray_directions(heading, angles)
    return np.where(ok[..., None], p, np.inf)


def ray_directions(heading: np.ndarray | float, angles: np.ndarray) -> np.ndarray:
    """The unit vector of each sonar (..., k, 2): its mounting angle ``angles`` (k,) from the ``heading`` (...)."""
    a = np.asarray(angles, float) + np.asarray(heading, float)[..., None]
    return np.stack([np.cos(a), np.sin(a)], axis=-1)


def obstacle_avoidance(x_i: np.ndarray, points: np.ndarray, dists: np.ndarray, r_s: float,
                       mode: str = "per_sensor", law: str = "literal", dirs: np.ndarray | None = None) -> np.ndarray:
    """Eq. 3.21 without its gain for each reading within r_s (``per_sensor``), or the nearest one only
    (``nearest``); zero when none is within r_s (target A2). ``points`` (..., k, 2) and ``dists`` (..., k) from
    ``obstacle_points`` (``inf`` for no echo).

    ``law`` "literal": exp(-d^2 / r_s^2) (x_i - O), as printed: its size d exp(-d^2 / r_s^2) peaks at d = r_s / sqrt 2
    and vanishes at contact. "bounded" [R]: exp(-d^2 / r_s^2) r_s (x_i - O) / d, the same direction and the same size
    at the trigger d = r_s, growing monotonically to r_s at contact (see docs/roy.md, "The obstacle term"). Its
    direction (x_i - O) / d is the reading's ray reversed: given the rays' unit vectors ``dirs`` (..., k, 2), it is
    taken from them, so it stays defined at contact (d = 0)."""
    if law not in OA_LAWS:
        raise ValueError(f"oa_law: expected one of {', '.join(OA_LAWS)}, got {law!r}")
    near = dists <= r_s
    if mode == "nearest":
        k = np.argmin(np.where(np.isfinite(dists), dists, np.inf), axis=-1)
        near = near & (np.arange(dists.shape[-1]) == k[..., None])
    d = np.where(near, dists, r_s)
    w = np.where(near, np.exp(-d * d / (r_s * r_s)), 0.0)
    if law == "bounded" and dirs is not None:
        w, diff = w * r_s, np.where(near[..., None], -dirs, 0.0)
    else:
        if law == "bounded":
            w = w * (r_s / np.maximum(d, 1e-9))
        diff = np.where(near[..., None], x_i[..., None, :] - np.where(near[..., None], points, 0.0), 0.0)
    return (w[..., None] * diff).sum(axis=-2)


def target_term(x_i: np.ndarray, v_i: np.ndarray, target: np.ndarray, k_target: float, sat: float,
                damping: float) -> np.ndarray:
    """Erratum #2's target term [R]: -k_T sat(x_i - T) - k_D v_i, the offset clipped to length ``sat`` so the pull
    is bounded, the damping so the swarm stops at T (the law damps only velocity differences)."""
    e = x_i - target
    n = np.hypot(e[..., 0], e[..., 1])
    if sat > 0:
        e = np.where((n > sat)[..., None], e * (sat / np.maximum(n, 1e-300))[..., None], e)
    return -k_target * e - damping * v_i


def law_basis(x_i: np.ndarray, v_i: np.ndarray, x_bar: np.ndarray, v_bar: np.ndarray, others: np.ndarray,
              oa: np.ndarray, r_s: float, delta: float, near: np.ndarray | None = None) -> np.ndarray:
    """The (..., 4, 2) vectors the gains (k_a, k_v, k_r, k_OA) multiply in eq. 3.5 + eq. 3.21: -(x_i - x_bar),
    -(v_i - v_bar), the repulsion sum, the obstacle term ``oa`` (``obstacle_avoidance``)."""
    return np.stack([-(x_i - x_bar), -(v_i - v_bar), repulsion(x_i, others, r_s, delta, near), oa], axis=-2)


def control_xy(gains: np.ndarray, basis: np.ndarray,
               extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """u's two components for gains (..., 4) and basis (..., 4, 2) (+ ``extra`` (..., 2)), broadcast: a population
    (S, P, 4) against a basis (S, 1, 4, 2). The sum runs k_a, k_v, k_r, k_OA, then the extra term."""
    g0, g1, g2, g3 = (gains[..., i] for i in range(4))
    u = [g0 * basis[..., 0, c] + g1 * basis[..., 1, c] + g2 * basis[..., 2, c] + g3 * basis[..., 3, c]
         for c in (0, 1)]
    if extra is not None:
        u = [u[0] + extra[..., 0], u[1] + extra[..., 1]]
    return u[0], u[1]


def control(gains: np.ndarray, basis: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
    """u = gains . basis + ``extra`` (the target term): gains (..., 4), basis (..., 4, 2) -> (..., 2)."""
    return np.stack(control_xy(np.asarray(gains, float), basis, extra), axis=-1)


def saturate_xy(v0: np.ndarray, v1: np.ndarray, v_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(v0, v1) scaled down to length ``v_max`` where longer."""
    speed = np.sqrt(v0 * v0 + v1 * v1)
    over = speed > v_max
    scale = v_max / np.where(over, speed, 1.0)
    return np.where(over, v0 * scale, v0), np.where(over, v1 * scale, v1)


def saturate(v: np.ndarray, v_max: float) -> np.ndarray:
    """``v`` (..., 2) scaled down to length ``v_max`` where longer."""
    return np.stack(saturate_xy(v[..., 0], v[..., 1], v_max), axis=-1)


def pair_spacing(k_a: float, k_r: float, r_s: float = 1.0, delta: float = 4.0) -> float:
    """The two-agent equilibrium (digest §2.1.4 [D]): d* = r_s sqrt(delta ln(2 k_r / k_a)); ValueError unless
    2 k_r > k_a (no equilibrium otherwise)."""
    if not 2 * k_r > k_a > 0:
        raise ValueError(f"k_a, k_r: a pair has an equilibrium only when 2 k_r > k_a > 0, got {k_a}, {k_r}")
    return r_s * float(np.sqrt(delta * np.log(2 * k_r / k_a)))
