"""RDPSO motion law with fractional-order (Grünwald-Letnikov) velocity memory, and its stability checks.

The per-robot update (eq. 4.5-4.6, 4.11) is

    v[t+1] = sum_k w_k v[t+1-k] + sum_i rho_i r_i (chi_i - x[t]),   x[t+1] = x[t] + v[t+1],   |v| <= dx_max

``memory_weights`` gives the w_k, ``memory_term`` applies them, ``clamp`` enforces the step limit. The rest is the
convergence analysis of chapter 7 (eq. 7.1-7.17), used to warn about parameter sets outside the attraction domain.

Two memory forms exist. The thesis derives the exact GL expansion (eq. 4.8) but uses, everywhere downstream
(eq. 4.11, the characteristic polynomial eq. 7.3, the deceleration bound eq. 7.11), a form whose terms after the
first are shifted by one factor: alpha, alpha/2, alpha(1-alpha)/6, alpha(1-alpha)(2-alpha)/24. "thesis" is that
form (the default, since the published stability bounds belong to it); "exact_gl" is eq. 4.8.

Per-step functions (``memory_term``, ``clamp``) work on plain float tuples: they run for every robot every
iteration and numpy's per-call overhead would dominate for 2-D vectors.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from swarm_logic.geometry import clamp

__all__ = ["clamp"]  # a step's length limit (eq. 4.6): one definition, in swarm_logic.geometry

FORMS = ("thesis", "exact_gl")

# Deceleration bound as printed (eq. 7.11). The exact root of eq. 7.10 is 0.631994...; at 0.632 the memory weights
# sum to 1 + 1.2e-5, which the thesis treats as the bound itself (its S1 parameter set uses alpha = 0.632).
ALPHA_MAX_PRINTED = 0.632

# Spectral radius must be below 1 by this margin to count as asymptotically stable: roots exactly on the unit circle
# (e.g. the lambda = 1 root at s = 0) must not pass as stable through rounding.
_STABLE_MARGIN = 1e-9


def _check_form(form: str) -> None:
    if form not in FORMS:
        raise ValueError(f"unknown fractional memory form {form!r}; allowed: {', '.join(FORMS)}")


def _exact_gl(alpha: float, n: int) -> list[float]:
    """w_k = -(-1)^k Gamma(alpha+1) / (Gamma(k+1) Gamma(alpha-k+1)), k = 1..n (eq. 4.8).

    Computed by the recurrence c_k = c_{k-1} (k-1-alpha)/k of the generalised binomial coefficients, which has no
    Gamma poles when alpha is an integer (alpha = 1 gives 1, 0, 0, ...).
    """
    out: list[float] = []
    c = 1.0
    for k in range(1, n + 1):
        c *= (k - 1 - alpha) / k
        out.append(-c)
    return out


def memory_weights(alpha: float, form: str = "thesis", r: int = 4) -> tuple[float, ...]:
    """Weights on v[t], v[t-1], ..., v[t-r+1] of the fractional memory term.

    "thesis": eq. 4.11, (alpha, alpha/2, alpha(1-alpha)/6, alpha(1-alpha)(2-alpha)/24). The thesis gives no rule
    for other truncation orders (its shifted pattern is not a GL series), so r must be 4 for this form.
    "exact_gl": the first r exact Grünwald-Letnikov weights of eq. 4.8, alpha, alpha(1-alpha)/2, ... (any r >= 1).
    """
    _check_form(form)
    if form == "thesis":
        if r != 4:
            raise ValueError(f"form 'thesis' (eq. 4.11) is only defined for r = 4, got r = {r}; use 'exact_gl'")
        a = alpha
        return (a, a / 2.0, a * (1.0 - a) / 6.0, a * (1.0 - a) * (2.0 - a) / 24.0)
    if r < 1:
        raise ValueError(f"truncation order r must be >= 1, got {r}")
    return tuple(_exact_gl(alpha, r))


def gl_increments(alpha: float, dx_max: float, n: int) -> list[float]:
    """|w_k| * dx_max for k = 1..n: the largest displacement each exact GL term can add (Prop. 4.1)."""
    return [abs(w) * dx_max for w in _exact_gl(alpha, n)]


def truncation_order(alpha: float, dx_max: float, delta: float) -> int:
    """Truncation order r of Prop. 4.1: the smallest tau whose GL increment is below the resolution delta, minus 1.

    Terms that cannot move the robot by one encoder pulse (delta, m/pulse) are useless, so the series stops there.
    """
    if not (dx_max > 0.0 and delta > 0.0):
        raise ValueError(f"dx_max and delta must be > 0, got dx_max={dx_max}, delta={delta}")
    if not 0.0 < alpha <= 1.0:
        raise ValueError(f"alpha = {alpha} is outside (0, 1]")
    c = 1.0
    for tau in range(1, 1_000_001):
        c *= (tau - 1 - alpha) / tau
        if abs(c) * dx_max < delta:
            return tau - 1
    raise ValueError(f"no GL term below delta={delta} within 10^6 terms")  # pragma: no cover - coefficients decay


def memory_term(weights: tuple[float, ...], history: Iterable[tuple[float, float]]) -> tuple[float, float]:
    """sum_k w_k v[t+1-k] for 2-D velocities; history is newest first, missing (start-up) entries count as 0."""
    mx = 0.0
    my = 0.0
    for w, v in zip(weights, history, strict=False):
        mx += w * v[0]
        my += w * v[1]
    return mx, my


def _thesis_memory_sum(alpha: float) -> float:
    return alpha + alpha / 2.0 + alpha * (1.0 - alpha) / 6.0 + alpha * (1.0 - alpha) * (2.0 - alpha) / 24.0


def deceleration_alpha_max() -> float:
    """alpha at which the eq. 4.11 memory weights sum to 1 (eq. 7.10); below it a robot at rest-point slows down.

    The sum 1.75a - 7a^2/24 + a^3/24 is increasing on (0, 1), so bisection finds the unique root 0.63199.
    """
    lo, hi = 0.0, 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _thesis_memory_sum(mid) < 1.0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-15:
            break
    return 0.5 * (lo + hi)


def _check_alpha(alpha: float) -> None:
    if not (isinstance(alpha, int | float) and math.isfinite(alpha) and 0.0 < alpha <= 1.0):
        raise ValueError(f"alpha = {alpha!r} is outside (0, 1] (fractional order, eq. 4.8)")


def attraction_domain(alpha: float) -> tuple[float, float]:
    """Bounds on s = sum rho_i r_i of the global attraction domain from the Jury conditions (eq. 7.4).

    (0, alpha + 2) for alpha <= 0.6 (lower bound exclusive), ((15/4) alpha - 9/4, alpha + 2) for 0.6 < alpha <= 1.
    """
    _check_alpha(alpha)
    if alpha <= 0.6:
        return 0.0, alpha + 2.0
    return 3.75 * alpha - 2.25, alpha + 2.0


def _poly_tail(weights: tuple[float, ...]) -> list[float]:
    """Coefficients of lambda^(r-1) .. lambda^0 of the position recurrence, without the s-dependent lambda^r term.

    Substituting v[t-k] = x[t-k] - x[t-k-1] into the memory law gives x[t+1] + (-1 - w_1 + s) x[t]
    + sum_k (w_k - w_{k+1}) x[t-k] + w_r x[t-r] = s chi (eq. 7.1 for the eq. 4.11 weights).
    """
    r = len(weights)
    return [weights[k] - weights[k + 1] for k in range(r - 1)] + [weights[-1]]


def characteristic_roots(alpha: float, s: float) -> np.ndarray:
    """Roots of the characteristic polynomial eq. 7.3 (eq. 4.11 memory) for s = sum rho_i r_i."""
    w = memory_weights(alpha, "thesis")
    return np.roots([1.0, -1.0 - w[0] + s, *_poly_tail(w)])


def _max_root_moduli(weights: tuple[float, ...], s_values: np.ndarray) -> np.ndarray:
    """Spectral radius of the recurrence for each s, via batched companion-matrix eigenvalues."""
    tail = _poly_tail(weights)
    n = len(tail) + 1
    comp = np.zeros((len(s_values), n, n))
    comp[:, 0, 0] = 1.0 + weights[0] - s_values
    comp[:, 0, 1:] = -np.asarray(tail)
    idx = np.arange(n - 1)
    comp[:, idx + 1, idx] = 1.0
    return np.abs(np.linalg.eigvals(comp)).max(axis=1)


def _stable_range(weights: tuple[float, ...], step: float) -> tuple[float, float]:
    if step <= 0.0:
        raise ValueError(f"step must be > 0, got {step}")
    # Past s = 1 + sum|w| + 2 the lambda^r coefficient alone pushes a root outside the unit circle.
    s_hi = 3.0 + 2.0 * sum(abs(w) for w in weights)
    grid = np.arange(0.0, s_hi + step, step)
    stable = _max_root_moduli(weights, grid) < 1.0 - _STABLE_MARGIN
    if not stable.any():
        raise ValueError("no stable range of sum(rho r) for these memory weights")
    first = int(np.argmax(stable))
    last = first
    while last + 1 < len(grid) and stable[last + 1]:
        last += 1

    def is_stable(s: float) -> bool:
        return bool(_max_root_moduli(weights, np.array([s]))[0] < 1.0 - _STABLE_MARGIN)

    def edge(bad: float, good: float) -> float:
        for _ in range(60):
            mid = 0.5 * (bad + good)
            if is_stable(mid):
                good = mid
            else:
                bad = mid
            if abs(good - bad) < 1e-10:
                break
        return 0.5 * (bad + good)

    lo = float(grid[first]) if first == 0 else edge(float(grid[first - 1]), float(grid[first]))
    hi = float(grid[last]) if last == len(grid) - 1 else edge(float(grid[last + 1]), float(grid[last]))
    return lo, hi


def numeric_stable_range(alpha: float, step: float = 0.001) -> tuple[float, float]:
    """Interval of s = sum rho_i r_i where every root of eq. 7.3 lies strictly inside the unit circle.

    Scans s from 0 on a grid of the given step and refines both edges by bisection. eq. 7.4 is a slightly
    conservative inner approximation of this range (e.g. alpha = 0.5: numeric upper edge 2.552 vs 2.5).
    """
    _check_alpha(alpha)
    return _stable_range(memory_weights(alpha, "thesis"), step)


def validate_parameters(alpha: float, rho: tuple[float, float, float, float]) -> None:
    """Refuse parameter sets that are not RDPSO parameters at all (as opposed to merely risky ones).

    alpha must be in (0, 1] (fractional order, eq. 4.8); rho must hold four finite coefficients >= 0 (eq. 4.5;
    0 is allowed, e.g. rho3 = 0 in an obstacle-free world).
    """
    _check_alpha(alpha)
    if len(rho) != 4:
        raise ValueError(f"rho must have 4 coefficients (rho1..rho4), got {len(rho)}")
    for i, v in enumerate(rho, start=1):
        if not (isinstance(v, int | float) and math.isfinite(v)):
            raise ValueError(f"rho{i} = {v!r} is not a finite number")
        if v < 0.0:
            raise ValueError(f"rho{i} = {v} is negative; coefficients must be >= 0 (eq. 4.5)")


def check_parameters(alpha: float, rho: tuple[float, float, float, float], form: str = "thesis") -> list[str]:
    """Stability warnings for (alpha, rho); empty when inside the thesis's design region A_p.

    Checks, with the random factors r_i at their worst case 1 (eq. 7.17) and at their mean 1/2:
    - deceleration (eq. 7.10-7.11): memory weights summing to >= 1 keep a robot moving at the equilibrium;
      for the thesis form this is alpha > 0.632;
    - acceleration from rest (eq. 7.14/7.17): pole 1 - sum(rho r) leaves the unit circle when sum(rho) >= 2;
    - attraction domain eq. 7.4 (thesis form) or the numeric root scan (exact_gl form): upper bound on sum(rho),
      and the eq. 7.4 lower bound (alpha > 0.6) against the mean sum(rho)/2.
    Invalid values raise ValueError (see ``validate_parameters``).
    """
    _check_form(form)
    validate_parameters(alpha, rho)
    out: list[str] = []
    total = float(sum(rho))
    mean = total / 2.0
    if form == "thesis":
        if alpha > ALPHA_MAX_PRINTED + 1e-12:
            out.append(f"alpha = {alpha:g} > {ALPHA_MAX_PRINTED} violates the deceleration bound (eq. 7.10-7.11): "
                       f"the memory weights sum to {_thesis_memory_sum(alpha):.4f} >= 1")
    else:
        wsum = sum(memory_weights(alpha, form))
        if wsum >= 1.0 - 1e-12:
            out.append(f"alpha = {alpha:g} violates the deceleration bound (eq. 7.10-7.11): the exact GL memory "
                       f"weights sum to {wsum:.4f} >= 1")
    if total <= 0.0:
        out.append("sum(rho) = 0: no attraction at all, the acceleration pole sits on the unit circle (eq. 7.14)")
    elif total >= 2.0:
        where = "inside" if 0.0 < mean < 2.0 else "also outside"
        out.append(f"sum(rho) = {total:g} >= 2 leaves the particular attraction domain A_p in the worst case r_i = 1 "
                   f"(eq. 7.14/7.17); the mean E[sum rho r] = sum(rho)/2 = {mean:g} is {where}")
    if form == "thesis":
        lo, hi = attraction_domain(alpha)
        name = "eq. 7.4"
    else:
        name = "the numeric root scan of the exact GL recurrence"
        try:
            lo, hi = _stable_range(memory_weights(alpha, form), 0.001)
        except ValueError:
            out.append(f"no sum(rho r) makes the exact GL recurrence asymptotically stable at alpha = {alpha:g} "
                       f"({name})")
            return out
    if total > hi:
        out.append(f"sum(rho) = {total:g} > {hi:g} exceeds the upper bound of the attraction domain ({name}) "
                   f"in the worst case r_i = 1")
    if lo > 0.0 and mean < lo:
        out.append(f"mean sum(rho r) = sum(rho)/2 = {mean:g} < {lo:g}, below the lower bound of the attraction "
                   f"domain ({name}) for alpha = {alpha:g}")
    return out
