"""Bacterial foraging optimisation, the thesis' "BG"/"BF" (Appendix 2, digest 001 §2.1.9, Table 3.2), in Passino's
form: chemotaxis (a tumble, then up to ``n_s`` swims while the cost falls), the cell-to-cell term J_cc, reproduction
(the healthier half cloned over the other), elimination-dispersal with probability ``p_ed``. The step C and the J_cc
coefficients are not in the thesis: C = ``step`` x the box's range, J_cc Passino's defaults (erratum #6).

``bfo_batch`` runs B independent problems at once from uniforms drawn beforehand (``bfo_draws`` per problem);
``bfo`` is one problem drawing from a generator. The same uniforms give the same result alone or in a batch.
"""

from __future__ import annotations

import numpy as np

from swarm_logic.families.roy.pso import BatchObjective, Objective, box, single


def j_cc(pos: np.ndarray, d_att: float, w_att: float, h_rep: float, w_rep: float) -> np.ndarray:
    """Passino's cell-to-cell attractant and repellent for each bacterium (..., S, D) -> (..., S)."""
    d2 = 0.0
    for k in range(pos.shape[-1]):
        c = pos[..., k]
        diff = c[..., :, None] - c[..., None, :]
        d2 = d2 + diff * diff
    return np.sum(-d_att * np.exp(-w_att * d2) + h_rep * np.exp(-w_rep * d2), axis=-1)


def bfo_draws(bacteria: int, n_c: int, n_re: int, n_ed: int, dim: int) -> int:
    """How many uniforms one problem takes: the start, a tumble per chemotactic step, and per elimination-dispersal
    event each bacterium's test and new position."""
    return bacteria * dim + n_ed * (n_re * n_c * bacteria * dim + bacteria + bacteria * dim)


def bfo_batch(f: BatchObjective, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, bacteria: int = 100, n_c: int = 5,
              n_s: int = 4, n_re: int = 4, n_ed: int = 2, p_ed: float = 0.25, step: float = 0.05,
              d_att: float = 0.1, w_att: float = 0.2, h_rep: float = 0.1, w_rep: float = 10.0,
              x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The best point (B, D), its value (B,) (J alone, without J_cc) and the final population sorted by J
    (B, S, D) (for BGPSO) of each problem. The first bacterium starts at ``x0`` (B, D), the rest uniform in the
    box."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dim = len(lo)
    b_n, s_n = len(u), bacteria
    c = step * (hi - lo)
    k = s_n * dim
    pos = lo + (hi - lo) * u[:, :k].reshape(b_n, s_n, dim)
    if x0 is not None:
        pos[:, 0] = box(x0, lo, hi)
    rows = np.arange(b_n)
    raw = f(pos)
    i = np.argmin(raw, axis=1)
    best, best_f = pos[rows, i].copy(), raw[rows, i].copy()
    for _ in range(n_ed):
        tumbles = u[:, k:k + n_re * n_c * s_n * dim].reshape(b_n, n_re, n_c, s_n, dim)
        k += n_re * n_c * s_n * dim
        for r in range(n_re):
            health = np.zeros((b_n, s_n))
            for j in range(n_c):
                raw = f(pos)
                cost = raw + j_cc(pos, d_att, w_att, h_rep, w_rep)
                health = health + cost
                tumble = 2.0 * tumbles[:, r, j] - 1.0
                direction = tumble / np.maximum(np.linalg.norm(tumble, axis=-1, keepdims=True), 1e-12)
                swimming = np.ones((b_n, s_n), bool)
                for _ in range(1 + n_s):  # the tumble's move, then the swims
                    trial = box(pos + c * direction, lo, hi)
                    t_raw = f(trial)
                    t_cost = t_raw + j_cc(trial, d_att, w_att, h_rep, w_rep)
                    m = np.argmin(t_raw, axis=1)
                    better = t_raw[rows, m] < best_f
                    best = np.where(better[:, None], trial[rows, m], best)
                    best_f = np.where(better, t_raw[rows, m], best_f)
                    moved = swimming & (t_cost < cost)
                    pos = np.where(moved[..., None], trial, pos)
                    cost = np.where(moved, t_cost, cost)
                    swimming = moved
                    if not np.any(swimming):
                        break
            order = np.argsort(health, axis=1, kind="stable")  # the healthier half (least accumulated cost) splits
            half = s_n // 2
            pos = np.take_along_axis(pos, np.concatenate([order[:, :half], order[:, :s_n - half]], axis=1)[..., None],
                                     axis=1)
        test = u[:, k:k + s_n]
        fresh = lo + (hi - lo) * u[:, k + s_n:k + s_n + s_n * dim].reshape(b_n, s_n, dim)
        k += s_n + s_n * dim
        pos = np.where((test < p_ed)[..., None], fresh, pos)
    raw = f(pos)
    i = np.argmin(raw, axis=1)
    better = raw[rows, i] < best_f
    best = np.where(better[:, None], pos[rows, i], best)
    best_f = np.where(better, raw[rows, i], best_f)
    return best, best_f, np.take_along_axis(pos, np.argsort(raw, axis=1, kind="stable")[..., None], axis=1)


def bfo(f: Objective, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, bacteria: int = 100, n_c: int = 5,
        n_s: int = 4, n_re: int = 4, n_ed: int = 2, p_ed: float = 0.25, step: float = 0.05, d_att: float = 0.1,
        w_att: float = 0.2, h_rep: float = 0.1, w_rep: float = 10.0, x0: np.ndarray | None = None,
        ) -> tuple[np.ndarray, float, np.ndarray]:
    """One problem: the best point, its value and the sorted final population, the uniforms drawn from ``rng``."""
    u = rng.random((1, bfo_draws(bacteria, n_c, n_re, n_ed, len(lo))))
    best, val, pop = bfo_batch(single(f), lo, hi, u, bacteria, n_c, n_s, n_re, n_ed, p_ed, step, d_att, w_att,
                               h_rep, w_rep, None if x0 is None else np.asarray(x0, float)[None, :])
    return best[0], float(val[0]), pop[0]
