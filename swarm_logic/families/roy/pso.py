"""Particle swarm optimisation as the thesis' Appendix 1 (digest 001 §2.1.8, Table 3.1): each particle a gain
vector, vel <- w vel + c1 r1 (pbest - pos) + c2 r2 (gbest - pos), pos <- pos + vel, kept in the box [lo, hi]."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Objective = Callable[[np.ndarray], np.ndarray]  # (P, D) -> (P,), lower is better


def pso(f: Objective, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, particles: int = 50,
        iters: int = 50, c1: float = 1.5, c2: float = 1.5, w: float = 0.5, x0: np.ndarray | None = None,
        init: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The best point found and its value. Particles start uniform in the box, the first at ``x0`` (a warm start:
    the last step's gains) or, given ``init`` (e.g. BFO's final population, BGPSO), at its first rows."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pos = rng.uniform(lo, hi, (particles, len(lo)))
    if init is not None:
        m = min(len(init), particles)
        pos[:m] = np.clip(init[:m], lo, hi)
    elif x0 is not None:
        pos[0] = np.clip(x0, lo, hi)
    vel = np.zeros_like(pos)
    val = f(pos)
    pbest, pval = pos.copy(), val.copy()
    g = int(np.argmin(pval))
    for _ in range(iters):
        r1, r2 = rng.random(pos.shape), rng.random(pos.shape)
        vel = w * vel + c1 * r1 * (pbest - pos) + c2 * r2 * (pbest[g] - pos)
        pos = np.clip(pos + vel, lo, hi)
        val = f(pos)
        better = val < pval
        pbest[better], pval[better] = pos[better], val[better]
        g = int(np.argmin(pval))
    return pbest[g].copy(), float(pval[g])
