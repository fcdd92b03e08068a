"""Bacterial foraging optimisation, the thesis' "BG"/"BF" (Appendix 2, digest 001 §2.1.9, Table 3.2), in Passino's
form: chemotaxis (a tumble, then up to ``n_s`` swims while the cost falls), the cell-to-cell term J_cc, reproduction
(the healthier half cloned over the other), elimination-dispersal with probability ``p_ed``. The step C and the J_cc
coefficients are not in the thesis: C = ``step`` x the box's range, J_cc Passino's defaults (erratum #6)."""

from __future__ import annotations

import numpy as np

from swarm_logic.families.roy.pso import Objective


def j_cc(pos: np.ndarray, d_att: float, w_att: float, h_rep: float, w_rep: float) -> np.ndarray:
    """Passino's cell-to-cell attractant and repellent for each bacterium (S, D) -> (S,)."""
    d2 = np.sum((pos[:, None, :] - pos[None, :, :]) ** 2, axis=2)
    return np.sum(-d_att * np.exp(-w_att * d2) + h_rep * np.exp(-w_rep * d2), axis=1)


def bfo(f: Objective, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, bacteria: int = 100, n_c: int = 5,
        n_s: int = 4, n_re: int = 4, n_ed: int = 2, p_ed: float = 0.25, step: float = 0.05, d_att: float = 0.1,
        w_att: float = 0.2, h_rep: float = 0.1, w_rep: float = 10.0, x0: np.ndarray | None = None,
        ) -> tuple[np.ndarray, float, np.ndarray]:
    """The best point found, its value (J alone, without J_cc) and the final population sorted by health (for
    BGPSO). The first bacterium starts at ``x0`` (the warm start), the rest uniform in the box."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = step * (hi - lo)
    pos = rng.uniform(lo, hi, (bacteria, len(lo)))
    if x0 is not None:
        pos[0] = np.clip(x0, lo, hi)
    raw = f(pos)
    best_i = int(np.argmin(raw))
    best, best_f = pos[best_i].copy(), float(raw[best_i])
    order = np.arange(bacteria)
    for _ in range(n_ed):
        for _ in range(n_re):
            health = np.zeros(bacteria)
            for _ in range(n_c):
                raw = f(pos)
                cost = raw + j_cc(pos, d_att, w_att, h_rep, w_rep)
                health += cost
                tumble = rng.uniform(-1.0, 1.0, pos.shape)
                direction = tumble / np.maximum(np.linalg.norm(tumble, axis=1, keepdims=True), 1e-12)
                swimming = np.ones(bacteria, bool)
                for _ in range(1 + n_s):  # the tumble's move, then the swims
                    trial = np.clip(pos + c * direction, lo, hi)
                    t_raw = f(trial)
                    t_cost = t_raw + j_cc(trial, d_att, w_att, h_rep, w_rep)
                    k = int(np.argmin(t_raw))
                    if t_raw[k] < best_f:
                        best, best_f = trial[k].copy(), float(t_raw[k])
                    moved = swimming & (t_cost < cost)
                    pos[moved], cost[moved] = trial[moved], t_cost[moved]
                    swimming = moved
                    if not np.any(swimming):
                        break
            order = np.argsort(health)  # reproduction: the healthier half (least accumulated cost) splits
            half = bacteria // 2
            pos = np.concatenate([pos[order[:half]], pos[order[:bacteria - half]]])
        disperse = rng.random(bacteria) < p_ed
        pos[disperse] = rng.uniform(lo, hi, (int(disperse.sum()), len(lo)))
    raw = f(pos)
    k = int(np.argmin(raw))
    if raw[k] < best_f:
        best, best_f = pos[k].copy(), float(raw[k])
    return best, best_f, pos[np.argsort(raw)]
