"""The bat algorithm of chapter 3 (eqs. 3.23-3.25, Table 3.3; digest 001 §2.1.11), each bat a gain vector.

Yang's control flow (the flowchart, Fig. 3.10, is lost; erratum #5): f_i = f_min + beta (f_max - f_min),
v_i <- v_i + f_i (x_i - x_*), x_i <- x_i + v_i; if rand > r_i a local walk x_* + zeta mean(A) around the best; the
new point is accepted if it improves and rand < A_i, and then A_i <- alpha A_i and the pulse rate is updated.
``mode`` "literal": the thesis' r_i = r_i(0) (1 - e^-gamma) (no t) with its alpha = 0.05, gamma = 0.95;
"standard": Yang's r_i = r_i(0) (1 - e^(-gamma t)) with alpha = gamma = 0.9.
Our reading of eq. 3.24 [R]: v accumulates f (x - x_*) as printed and the bat moves by x - v, i.e. towards the best
(x + v, as printed, drives every bat away from it). The walk's step is zeta mean(A) in gain units, as printed.

``bat_batch`` runs B independent problems at once (f maps (B, P, D) -> (B, P)) from uniforms drawn beforehand,
``bat_draws`` per problem, in a fixed layout; ``bat`` is one problem drawing from a generator. The same uniforms give
the same result whether a problem runs alone or in a batch.
"""

from __future__ import annotations

import numpy as np

from swarm_logic.families.roy.pso import BatchObjective, Objective, box, single

BAT_MODES = ("literal", "standard")


def bat_draws(bats: int, iters: int, dim: int) -> int:
    """How many uniforms one problem takes: the start (bats x dim), r_0 (bats), and per iteration beta, the walk's
    test and the acceptance test of every bat, then every bat's zeta (dim)."""
    return bats * dim + bats + iters * bats * (dim + 3)


def bat_batch(f: BatchObjective, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, bats: int = 25, iters: int = 50,
              f_min: float = 0.0, f_max: float = 1.0, a0: float = 1.0, alpha: float = 0.05, gamma: float = 0.95,
              mode: str = "literal", x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The best point (B, D) and its value (B,) of each of B problems; ``u`` (B, ``bat_draws``) uniforms in [0, 1),
    ``x0`` (B, D) warm starts (the first bat). ValueError for an unknown ``mode``. r_i(0) ~ U[0, 1] (Table 3.3)."""
    if mode not in BAT_MODES:
        raise ValueError(f"bat mode: expected one of {', '.join(BAT_MODES)}, got {mode!r}")
    if mode == "standard":
        alpha, gamma = 0.9, 0.9
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dim = len(lo)
    b_n = len(u)
    k0 = bats * dim
    x = lo + (hi - lo) * u[:, :k0].reshape(b_n, bats, dim)
    if x0 is not None:
        x[:, 0] = box(x0, lo, hi)
    r0 = u[:, k0:k0 + bats]
    steps = u[:, k0 + bats:].reshape(b_n, iters, bats * (dim + 3))
    v = np.zeros_like(x)
    fit = f(x)
    loud = np.full((b_n, bats), a0)
    pulse = r0 * (1 - np.exp(-gamma)) if mode == "literal" else np.zeros((b_n, bats))
    rows = np.arange(b_n)
    b = np.argmin(fit, axis=1)
    best, best_f = x[rows, b].copy(), fit[rows, b].copy()
    for t in range(1, iters + 1):
        s = steps[:, t - 1]
        freq = f_min + (f_max - f_min) * s[:, :bats]
        v = v + (x - best[:, None, :]) * freq[..., None]
        cand = box(x - v, lo, hi)  # x - v: with v built from (x - x_*), each bat moves towards the best
        walk = s[:, bats:2 * bats] > pulse
        zeta = 2.0 * s[:, 3 * bats:].reshape(b_n, bats, dim) - 1.0
        cand = np.where(walk[..., None], box(best[:, None, :] + zeta * loud.mean(axis=1)[:, None, None], lo, hi),
                        cand)
        cf = f(cand)
        accept = (cf <= fit) & (s[:, 2 * bats:3 * bats] < loud)
        x = np.where(accept[..., None], cand, x)
        fit = np.where(accept, cf, fit)
        loud = np.where(accept, loud * alpha, loud)
        if mode == "literal":
            pulse = np.where(accept, r0 * (1 - np.exp(-gamma)), pulse)
        else:
            pulse = np.where(accept, r0 * (1 - np.exp(-gamma * t)), pulse)
        k = np.argmin(cf, axis=1)
        better = cf[rows, k] < best_f
        best = np.where(better[:, None], cand[rows, k], best)
        best_f = np.where(better, cf[rows, k], best_f)
    return best, best_f


def bat(f: Objective, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, bats: int = 25, iters: int = 50,
        f_min: float = 0.0, f_max: float = 1.0, a0: float = 1.0, alpha: float = 0.05, gamma: float = 0.95,
        mode: str = "literal", x0: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """One problem: the best point found and its value, the uniforms drawn from ``rng`` in one call."""
    u = rng.random((1, bat_draws(bats, iters, len(lo))))
    best, val = bat_batch(single(f), lo, hi, u, bats, iters, f_min, f_max, a0, alpha, gamma, mode,
                          None if x0 is None else np.asarray(x0, float)[None, :])
    return best[0], float(val[0])
