"""MANET graph tools for the RDPSO connectivity term (§4.4, §5.2) and the swarm-connectivity metric (§7.2).

Matrix functions (``adjacency``, ``multihop_matrix``, ``fiedler``) take numpy arrays and run once per subgroup per
iteration. The per-robot functions (``connectivity_vector``, ``choose_neighbours``) use plain floats and tuples.

Link values follow the thesis: distances in metres ("distance" mode, threshold d_max) or RSSI in dBm ("rssi" mode,
threshold q_min); 0 or NaN in a link matrix means "no link".
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np

from swarm_logic.graph import components

__all__ = ["components"]  # the MANET's pieces: one definition, in swarm_logic.graph

MODES = ("distance", "rssi")


def _check_mode(mode: str) -> None:
    if mode not in MODES:
        raise ValueError(f"unknown link mode {mode!r}; allowed: {', '.join(MODES)}")


def linked(link: Any, mode: str, threshold: float) -> Any:
    """Eq. 4.12's link rule, for one link measure or an array of them: l <= d_max (distance) or l >= q_min (rssi)."""
    return link <= threshold if mode == "distance" else link >= threshold


def adjacency(links: np.ndarray, mode: str, threshold: float) -> np.ndarray:
    """Adjacency matrix A_c of eq. 4.12: a_ij = 1 if l_ij <= d_max (distance) or l_ij >= q_min (rssi), a_ii = 0.

    Entries equal to 0 or NaN are missing links. Row i describes what robot i measures of robot j, so an
    asymmetric RSSI matrix gives an asymmetric A_c.
    """
    _check_mode(mode)
    lk = np.asarray(links, dtype=float)
    if lk.ndim != 2 or lk.shape[0] != lk.shape[1]:
        raise ValueError(f"links must be a square N x N array, got shape {lk.shape}")
    present = lk != 0.0  # NaN != 0 is True, but NaN fails both threshold comparisons below
    with np.errstate(invalid="ignore"):
        ok = linked(lk, mode, threshold)
    a = (present & ok).astype(np.int64)
    np.fill_diagonal(a, 0)
    return a


def multihop_matrix(a: np.ndarray) -> np.ndarray:
    """Multi-hop connectivity matrix C^(N_s-1) (Algorithm 4.3, eq. 4.13-4.15): c_ij = minimum hop count i -> j.

    0 on the diagonal and for unreachable pairs. Computed by breadth-first search from every robot, which yields
    the minimum hop counts that eq. 4.13-4.15 define; the printed recursion (C^(k-1) B^(k-1) > 0) taken literally
    can label a pair at 4 hops as 3 on a path graph, so it is not transcribed.
    """
    am = np.asarray(a)
    n = am.shape[0]
    nbrs = [np.flatnonzero(am[i]).tolist() for i in range(n)]
    c = np.zeros((n, n), dtype=np.int64)
    for src in range(n):
        hops = [-1] * n
        hops[src] = 0
        q = deque([src])
        while q:
            u = q.popleft()
            h = hops[u] + 1
            for v in nbrs[u]:
                if hops[v] < 0:
                    hops[v] = h
                    q.append(v)
        c[src] = [max(h, 0) for h in hops]
    return c


def fiedler(a: np.ndarray) -> float:
    """Algebraic connectivity lambda_2 of L = D - A (eq. 5.14-5.15): > 0 iff the graph is connected.

    The Laplacian spectrum is defined for undirected graphs, so an asymmetric A is symmetrised by the element-wise
    minimum: a link counts only if it works both ways. 0.0 for fewer than two robots.
    """
    am = np.asarray(a, dtype=float)
    n = am.shape[0]
    if n < 2:
        return 0.0
    sym = np.minimum(am, am.T)
    np.fill_diagonal(sym, 0.0)
    lap = np.diag(sym.sum(axis=1)) - sym
    return float(np.linalg.eigvalsh(lap)[1])


def connectivity_metric(a: np.ndarray) -> float:
    """Swarm connectivity C_s = lambda_2 / N_s, 0 if lambda_2 < 0 (eq. 7.24); 1 for a complete graph.

    Clamped to [0, 1] against rounding. A lone robot (N_s < 2) gives 0.
    """
    n = np.asarray(a).shape[0]
    if n < 2:
        return 0.0
    lam = fiedler(a)
    if lam <= 0.0:
        return 0.0
    return min(lam / n, 1.0)


def connectivity_vector(px: float, py: float, chosen: Sequence[tuple[float, float, float]], mode: str,
                        d_max: float, q_min: float, k_q: float = 1.0) -> tuple[float, float]:
    """Connectivity force Q_n of eq. 5.12 (chi_4 = x_n + Q_n) toward the chosen neighbours (x, y, link value).

    distance mode: sum (L - d_max) u, attraction beyond d_max and repulsion inside it;
    rssi mode: sum k_q (q_min - L) u, attraction when the signal is weaker than q_min. k_q [m/dB] converts the
    dB error into metres (the thesis uses it unscaled, i.e. k_q = 1).
    u is the unit vector from (px, py) to the neighbour; a neighbour at the same position contributes nothing.
    """
    qx = 0.0
    qy = 0.0
    rssi = mode == "rssi"
    if not rssi and mode != "distance":
        _check_mode(mode)
    for x, y, link in chosen:
        dx = x - px
        dy = y - py
        dist = math.hypot(dx, dy)
        if dist == 0.0:
            continue
        g = (k_q * (q_min - link) if rssi else (link - d_max)) / dist
        qx += g * dx
        qy += g * dy
    return qx, qy


def choose_neighbours(candidates: Sequence[tuple[Hashable, float]], k: int, mode: str) -> list:
    """Up to k neighbour ids, nearest first (Algorithm 5.2 / §4.4 neighbour rule).

    candidates are (id, link value) of robots that have not chosen this robot. Nearest means ascending distance
    or descending RSSI; ties go to the smaller id so every robot makes the same choice from the same data.
    Candidates with a NaN link value are skipped.
    """
    _check_mode(mode)
    if k <= 0:
        return []
    sign = 1.0 if mode == "distance" else -1.0
    valid = [(sign * v, i) for i, v in candidates if v == v]
    valid.sort()
    return [i for _, i in valid[:k]]
