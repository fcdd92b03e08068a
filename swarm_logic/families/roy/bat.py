"""The bat algorithm of chapter 3 (eqs. 3.23-3.25, Table 3.3; digest 001 §2.1.11), each bat a gain vector.

Yang's control flow (the flowchart, Fig. 3.10, is lost; erratum #5): f_i = f_min + beta (f_max - f_min),
v_i <- v_i + f_i (x_i - x_*), x_i <- x_i + v_i; if rand > r_i a local walk x_* + zeta mean(A) around the best; the
new point is accepted if it improves and rand < A_i, and then A_i <- alpha A_i and the pulse rate is updated.
``mode`` "literal": the thesis' r_i = r_i(0) (1 - e^-gamma) (no t) with its alpha = 0.05, gamma = 0.95;
"standard": Yang's r_i = r_i(0) (1 - e^(-gamma t)) with alpha = gamma = 0.9.
Our reading of eq. 3.24 [R]: v accumulates f (x - x_*) as printed and the bat moves by x - v, i.e. towards the best
(x + v, as printed, drives every bat away from it). The walk's step is zeta mean(A) in gain units, as printed.
"""

from __future__ import annotations

import numpy as np

from swarm_logic.families.roy.pso import Objective

BAT_MODES = ("literal", "standard")


def bat(f: Objective, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, bats: int = 25, iters: int = 50,
        f_min: float = 0.0, f_max: float = 1.0, a0: float = 1.0, alpha: float = 0.05, gamma: float = 0.95,
        mode: str = "literal", x0: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The best point found and its value; ValueError for an unknown ``mode``. r_i(0) ~ U[0, 1] (Table 3.3)."""
    if mode not in BAT_MODES:
        raise ValueError(f"bat mode: expected one of {', '.join(BAT_MODES)}, got {mode!r}")
    if mode == "standard":
        alpha, gamma = 0.9, 0.9
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dim = len(lo)
    x = rng.uniform(lo, hi, (bats, dim))
    if x0 is not None:
        x[0] = np.clip(x0, lo, hi)
    v = np.zeros_like(x)
    fit = f(x)
    loud = np.full(bats, a0)
    r0 = rng.random(bats)
    pulse = r0 * (1 - np.exp(-gamma)) if mode == "literal" else np.zeros(bats)
    b = int(np.argmin(fit))
    best, best_f = x[b].copy(), float(fit[b])
    for t in range(1, iters + 1):
        freq = f_min + (f_max - f_min) * rng.random(bats)
        v = v + (x - best[None, :]) * freq[:, None]
        cand = np.clip(x - v, lo, hi)  # x - v: with v built from (x - x_*), each bat moves towards the best
        walk = rng.random(bats) > pulse
        if np.any(walk):
            zeta = rng.uniform(-1.0, 1.0, (int(walk.sum()), dim))
            cand[walk] = np.clip(best[None, :] + zeta * loud.mean(), lo, hi)
        cf = f(cand)
        accept = (cf <= fit) & (rng.random(bats) < loud)
        x[accept], fit[accept] = cand[accept], cf[accept]
        loud[accept] *= alpha
        if mode == "literal":
            pulse[accept] = r0[accept] * (1 - np.exp(-gamma))
        else:
            pulse[accept] = r0[accept] * (1 - np.exp(-gamma * t))
        k = int(np.argmin(cf))
        if cf[k] < best_f:
            best, best_f = cand[k].copy(), float(cf[k])
    return best, best_f
