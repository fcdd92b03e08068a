"""Particle swarm optimisation as the thesis' Appendix 1 (digest 001 §2.1.8, Table 3.1): each particle a gain
vector, vel <- w vel + c1 r1 (pbest - pos) + c2 r2 (gbest - pos), pos <- pos + vel, kept in the box [lo, hi].

``pso_batch`` runs B independent problems at once from uniforms drawn beforehand (``pso_draws`` per problem);
``pso`` is one problem drawing from a generator. The same uniforms give the same result alone or in a batch.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Objective = Callable[[np.ndarray], np.ndarray]  # (P, D) -> (P,), lower is better
BatchObjective = Callable[[np.ndarray], np.ndarray]  # (B, P, D) -> (B, P): B problems at once


def box(a: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``a`` clipped into [lo, hi] (np.clip's numbers, faster; scalar bounds when the box is a cube)."""
    if lo.ndim and np.all(lo == lo[0]) and np.all(hi == hi[0]):
        lo, hi = lo[0], hi[0]
    return np.minimum(np.maximum(a, lo), hi)


def single(f: Objective) -> BatchObjective:
    """One problem's objective as a batch of one."""
    return lambda k: np.asarray(f(k[0]), float)[None, :]


def pso_draws(particles: int, iters: int, dim: int) -> int:
    """How many uniforms one problem takes: the start, then r1 and r2 for every particle and iteration."""
    return particles * dim * (1 + 2 * iters)


def pso_batch(f: BatchObjective, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, particles: int = 50,
              iters: int = 50, c1: float = 1.5, c2: float = 1.5, w: float = 0.5, x0: np.ndarray | None = None,
              init: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The best point (B, D) and value (B,) of each problem. Particles start uniform in the box, the first at
    ``x0`` (B, D) (a warm start: the last step's gains) or, given ``init`` (B, M, D) (e.g. BFO's final population,
    BGPSO), at its first rows."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dim = len(lo)
    b_n = len(u)
    k0 = particles * dim
    pos = lo + (hi - lo) * u[:, :k0].reshape(b_n, particles, dim)
    if init is not None:
        m = min(init.shape[1], particles)
        pos[:, :m] = box(init[:, :m], lo, hi)
    elif x0 is not None:
        pos[:, 0] = box(x0, lo, hi)
    r = u[:, k0:].reshape(b_n, iters, 2, particles, dim)
    vel = np.zeros_like(pos)
    val = f(pos)
    pbest, pval = pos.copy(), val.copy()
    rows = np.arange(b_n)
    g = np.argmin(pval, axis=1)
    for t in range(iters):
        vel = w * vel + c1 * r[:, t, 0] * (pbest - pos) + c2 * r[:, t, 1] * (pbest[rows, g][:, None, :] - pos)
        pos = box(pos + vel, lo, hi)
        val = f(pos)
        better = val < pval
        pbest = np.where(better[..., None], pos, pbest)
        pval = np.where(better, val, pval)
        g = np.argmin(pval, axis=1)
    return pbest[rows, g].copy(), pval[rows, g].copy()


def pso(f: Objective, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, particles: int = 50,
        iters: int = 50, c1: float = 1.5, c2: float = 1.5, w: float = 0.5, x0: np.ndarray | None = None,
        init: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """One problem: the best point found and its value, the uniforms drawn from ``rng`` in one call."""
    u = rng.random((1, pso_draws(particles, iters, len(lo))))
    best, val = pso_batch(single(f), lo, hi, u, particles, iters, c1, c2, w,
                          None if x0 is None else np.asarray(x0, float)[None, :],
                          None if init is None else np.asarray(init, float)[None])
    return best[0], float(val[0])
