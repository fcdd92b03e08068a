"""The binary cooperative bat algorithm (Zhang, ISA Trans. 96, 2020), which chapter 7 (Table 7.5) compares with BAT, as
a gain optimiser: each gain is ``bits`` bits over [lo, hi], each bit has a velocity, and a bit is set from its velocity
mapped into [0, 1].

The thesis' only description: the velocity is mapped into a probability and the bit set to one or zero by comparing
it with a random number (the S-shaped, sigmoid, ``transfer``). Zhang's paper is not at hand, so the control flow is
that of the binary bat algorithm (BBA; Mirjalili, Mirjalili & Yang, Neural Comput. Appl. 2014), which also gives the
V-shaped ``transfer`` (a bit flips with probability |2/pi arctan(pi/2 v)|), with Yang's loudness and pulse rate:
f_i = f_min + beta (f_max - f_min), v_i <- v_i + f_i (x_i - x_*) per bit; if rand > r_i a local walk around the best;
the candidate is accepted if it is no worse and rand < A_i, and then A_i <- alpha A_i, r_i <- r_i(0) (1 - e^(-gamma t))
(r_i = 0, Yang's value at t = 0, until a bat's first acceptance).
Zhang's cooperative term (the bats sharing information over a communication topology) is not described, so absent.
Our readings [R]:
- sigmoid: bit = 1 when rand < S(-v), S(z) = 1 / (1 + e^-z): with v accumulating f (x - x_*), bits move towards the
  best, as BAT's x - v (``bat``); S(v) as printed drives them away. The V-shaped map is even in v, so it needs no sign.
- the local walk: the best's bits, each flipped with probability mean(A) / ``bits`` (about mean(A) bits a gain).
- decode: gain = lo + (hi - lo) n / (2^bits - 1), n the gain's bits read most significant first.
- the warm start ``x0`` is encoded into the first bat but scored at x0 itself, so a call that finds nothing strictly
  better returns x0 unchanged (the gains do not snap to the grid).

``binary_bat_batch`` runs B independent problems at once (f maps (B, P, D) -> (B, P)) from uniforms drawn beforehand,
``binary_bat_draws`` per problem, in a fixed layout; ``binary_bat`` is one problem drawing from a generator. The same
uniforms give the same result whether a problem runs alone or in a batch.
"""

from __future__ import annotations

import numpy as np

from swarm_logic.families.roy.pso import BatchObjective, Objective, box, single

BINARY_TRANSFERS = ("sigmoid", "v_shaped")


def binary_bat_draws(bats: int, iters: int, dim: int, bits: int) -> int:
    """How many uniforms one problem takes: the start's bits (bats x dim x bits), r_0 (bats), and per iteration every
    bat's beta, then every bat's walk test, then every bat's acceptance test, then every bat's transfer uniform per bit,
    then every bat's walk-flip uniform per bit."""
    n = dim * bits
    return bats * n + bats + iters * bats * (3 + 2 * n)


def encode(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, bits: int) -> np.ndarray:
    """Points (..., D) in [lo, hi] as their nearest grid points' bits (..., D x bits), 0./1., most significant first."""
    top = 2**bits - 1
    n = np.rint((box(np.asarray(x, float), lo, hi) - lo) / (hi - lo) * top).astype(np.int64)
    shifts = np.arange(bits - 1, -1, -1)
    b = (n[..., None] >> shifts) & 1
    return b.reshape(*n.shape[:-1], -1).astype(float)


def decode(b: np.ndarray, lo: np.ndarray, hi: np.ndarray, bits: int) -> np.ndarray:
    """Bits (..., D x bits) as the points (..., D) of the grid lo + (hi - lo) n / (2^bits - 1)."""
    weights = 2.0 ** np.arange(bits - 1, -1, -1)
    n = b.reshape(*b.shape[:-1], -1, bits) @ weights
    return lo + (hi - lo) * n / (2**bits - 1)


def binary_bat_batch(
    f: BatchObjective,
    lo: np.ndarray,
    hi: np.ndarray,
    u: np.ndarray,
    bats: int = 25,
    iters: int = 50,
    bits: int = 8,
    f_min: float = 0.0,
    f_max: float = 1.0,
    a0: float = 1.0,
    alpha: float = 0.9,
    gamma: float = 0.9,
    transfer: str = "sigmoid",
    x0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The best point (B, D) and its value (B,) of each of B problems; ``u`` (B, ``binary_bat_draws``) uniforms in
    [0, 1), ``x0`` (B, D) warm starts (the first bat). ValueError for an unknown ``transfer``. r_i(0) ~ U[0, 1]."""
    if transfer not in BINARY_TRANSFERS:
        raise ValueError(f"binary bat transfer: expected one of {', '.join(BINARY_TRANSFERS)}, got {transfer!r}")
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    n_bits = len(lo) * bits
    b_n = len(u)
    k0 = bats * n_bits
    x = (u[:, :k0].reshape(b_n, bats, n_bits) < 0.5).astype(float)
    pts = decode(x, lo, hi, bits)
    if x0 is not None:
        pts[:, 0] = box(np.asarray(x0, float), lo, hi)
        x[:, 0] = encode(pts[:, 0], lo, hi, bits)
    r0 = u[:, k0 : k0 + bats]
    steps = u[:, k0 + bats :].reshape(b_n, iters, bats * (3 + 2 * n_bits))
    v = np.zeros_like(x)
    fit = f(pts)
    loud = np.full((b_n, bats), a0)
    pulse = np.zeros((b_n, bats))
    rows = np.arange(b_n)
    b = np.argmin(fit, axis=1)
    best, best_bits, best_f = pts[rows, b].copy(), x[rows, b].copy(), fit[rows, b].copy()
    for t in range(1, iters + 1):
        s = steps[:, t - 1]
        freq = f_min + (f_max - f_min) * s[:, :bats]
        v = v + (x - best_bits[:, None, :]) * freq[..., None]
        draw = s[:, 3 * bats : 3 * bats + bats * n_bits].reshape(b_n, bats, n_bits)
        if transfer == "sigmoid":
            cand = (draw < 0.5 * (1.0 - np.tanh(0.5 * v))).astype(float)  # S(-v), without overflow
        else:
            cand = np.abs(x - (draw < np.abs(2.0 / np.pi * np.arctan(np.pi / 2.0 * v))))
        walk = s[:, bats : 2 * bats] > pulse
        flips = s[:, 3 * bats + bats * n_bits :].reshape(b_n, bats, n_bits) < (loud.mean(axis=1) / bits)[:, None, None]
        cand = np.where(walk[..., None], np.abs(best_bits[:, None, :] - flips), cand)
        cpts = decode(cand, lo, hi, bits)
        cf = f(cpts)
        accept = (cf <= fit) & (s[:, 2 * bats : 3 * bats] < loud)
        x = np.where(accept[..., None], cand, x)
        fit = np.where(accept, cf, fit)
        loud = np.where(accept, loud * alpha, loud)
        pulse = np.where(accept, r0 * (1 - np.exp(-gamma * t)), pulse)
        k = np.argmin(cf, axis=1)
        better = cf[rows, k] < best_f
        best = np.where(better[:, None], cpts[rows, k], best)
        best_bits = np.where(better[:, None], cand[rows, k], best_bits)
        best_f = np.where(better, cf[rows, k], best_f)
    return best, best_f


def binary_bat(
    f: Objective,
    lo: np.ndarray,
    hi: np.ndarray,
    rng: np.random.Generator,
    bats: int = 25,
    iters: int = 50,
    bits: int = 8,
    x0: np.ndarray | None = None,
    **settings: float | str,
) -> tuple[np.ndarray, float]:
    """One problem: the best point found and its value, the uniforms drawn from ``rng`` in one call; ``settings``
    are ``binary_bat_batch``'s f_min, f_max, a0, alpha, gamma and transfer."""
    u = rng.random((1, binary_bat_draws(bats, iters, len(lo), bits)))
    x0 = None if x0 is None else np.asarray(x0, float)[None, :]
    best, val = binary_bat_batch(single(f), lo, hi, u, bats, iters, bits, x0=x0, **settings)
    return best[0], float(val[0])
