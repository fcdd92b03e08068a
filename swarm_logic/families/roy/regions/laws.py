"""The agents' local laws of chapters 4-6 (Roy 2022 eqs. 4.4-4.6, 4.41, 5.2, 6.5), vectorised over agents: a pull
toward a centre (the region's, or each agent's own: an (N, 2) array) plus an exponential repulsion
exp(-|x_ij| / s_ij) (x_i - x_j) over a set of pairs, saturated at v_max. Pairs come from the formation graph, or from
a cKDTree (all pairs within a cut-off, or the k nearest), never from a Python loop over pairs.

Theorem 1's gain and entry-time bound (erratum 13) and the bound that the proof actually supports are here too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from swarm_logic.families.roy.regions.records import check_fields

NEIGHBOURS = ("knn", "all")
CH6_MODES = ("nearest", "sum", "knn")


def saturate(u: np.ndarray, v_max: float | None) -> np.ndarray:
    """Each row of ``u`` (N, 2) scaled down to length ``v_max`` if longer (``None``: unsaturated)."""
    if v_max is None:
        return u
    n = np.hypot(u[:, 0], u[:, 1])
    s = np.where(n > v_max, v_max / np.maximum(n, 1e-300), 1.0)
    return u * s[:, None]


def unique_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``a`` (N, c) that differ bit for bit: ``first`` the index of each one's first occurrence and
    ``same`` (N,) which of them each row is (``a[first][same]`` is ``a``). Work done once per distinct row and copied
    gives the same bits as done per row: swarms stack agents on one spot (a pull that converges to its float centre)."""
    a = np.ascontiguousarray(a)
    if not len(a):
        return np.zeros(0, int), np.zeros(0, int)
    v = a.reshape(len(a), -1).view(np.dtype((np.void, a.dtype.itemsize * int(np.prod(a.shape[1:])))))
    _, first, same = np.unique(v.ravel(), return_index=True, return_inverse=True)
    return first, same.ravel()


def kernel_sum(
    x: np.ndarray, i: np.ndarray, j: np.ndarray, scale: np.ndarray | float, others: np.ndarray | None = None
) -> np.ndarray:
    """sum over the pairs (i, j) of exp(-|x_i - y_j| / scale) (x_i - y_j), per agent i (N, 2); y = ``others`` (default
    ``x``). Each pair acts on i only: pass both orders for a symmetric pair."""
    y = x if others is None else others
    d = x[i] - y[j]
    r = np.hypot(d[:, 0], d[:, 1])
    w = np.exp(-r / scale)
    n = len(x)
    return np.stack([np.bincount(i, w * d[:, 0], n), np.bincount(i, w * d[:, 1], n)], axis=1)


def _both(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.concatenate([p[:, 0], p[:, 1]]), np.concatenate([p[:, 1], p[:, 0]])


def _pull(x: np.ndarray, centre: np.ndarray, k: float) -> np.ndarray:
    return -k * (x - np.asarray(centre, dtype=float))


def _law(
    x: np.ndarray,
    centre: np.ndarray,
    k_pull: float,
    k_rep: float,
    pairs: tuple[np.ndarray, np.ndarray],
    scale: np.ndarray | float,
    safety: Safety | None,
    v_max: float | None,
) -> np.ndarray:
    """-k_pull (x_i - c_i) + k_rep sum_pairs kernel (+ the safety term), saturated: the shape every law here shares."""
    u = _pull(x, centre, k_pull)
    if len(pairs[0]):
        u = u + k_rep * kernel_sum(x, pairs[0], pairs[1], scale)
    if safety is not None:
        u = u + safety.term(x)
    return saturate(u, v_max)


@dataclass(frozen=True)
class Safety:
    """Erratum 16's all-pairs safety repulsion: every pair closer than ``factor`` x the robot diameter (2 ``r_robot``)
    repels with gain ``k`` and the same kernel, scale the trigger distance (the formation term ignores
    non-neighbours, which could otherwise collide)."""

    r_robot: float = 0.5
    factor: float = 1.2
    k: float = 5.0

    def __post_init__(self) -> None:
        check_fields(self, ("r_robot", "factor", "k"))

    @property
    def distance(self) -> float:
        return 2.0 * self.r_robot * self.factor

    def term(self, x: np.ndarray) -> np.ndarray:
        i, j = _both(cKDTree(x).query_pairs(self.distance, output_type="ndarray"))
        return self.k * kernel_sum(x, i, j, self.distance) if len(i) else np.zeros_like(x)


def formation_law(
    x: np.ndarray,
    centre: np.ndarray,
    k_c: float,
    k_f: float,
    desired: np.ndarray,
    safety: Safety | None = Safety(),
    v_max: float | None = None,
) -> np.ndarray:
    """Eq. 4.6: u_i = -k_c (x_i - O_c) + k_f sum_j exp(-|x_ij| / [rho o Delta]_ij) (x_i - x_j) over the graph's
    edges (``desired`` = rho o Delta (N, N); a zero entry, a non-neighbour, exerts none), plus the ``safety`` term
    (``None``: the law as printed)."""
    x = np.asarray(x, dtype=float)
    i, j = np.nonzero(np.asarray(desired) > 0)
    return _law(x, centre, k_c, k_f, (i, j), np.asarray(desired, dtype=float)[i, j], safety, v_max)


def neighbour_pairs(x: np.ndarray, neighbours: str, k: int, cutoff: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The (i, j) pairs a repulsion sums over: "knn", each agent's ``k`` nearest; "all", every pair (within
    ``cutoff`` when given, through a cKDTree; ``None``: every pair, O(N^2))."""
    n = len(x)
    if neighbours not in NEIGHBOURS:
        raise ValueError(f"neighbours: expected one of {', '.join(NEIGHBOURS)}, got {neighbours!r}")
    if n < 2:
        return np.zeros(0, int), np.zeros(0, int)
    if neighbours == "knn":
        kk = min(k, n - 1)
        _, idx = cKDTree(x).query(x, k=kk + 1)
        own = idx == np.arange(n)[:, None]
        # drop each row's own index (normally column 0; a tie with a coincident agent may reorder it)
        drop = np.where(own.any(axis=1), np.argmax(own, axis=1), kk)
        keep = np.ones_like(idx, bool)
        keep[np.arange(n), drop] = False
        return np.repeat(np.arange(n), kk), idx[keep]
    if cutoff is None:
        i, j = np.nonzero(~np.eye(n, dtype=bool))
        return i, j
    return _both(cKDTree(x).query_pairs(cutoff, output_type="ndarray"))


def scalable_law(
    x: np.ndarray,
    centre: np.ndarray,
    k_c: float,
    k_f: float,
    r_s: float,
    neighbours: str = "knn",
    k: int = 6,
    cutoff_scales: float | None = 12.0,
    safety: Safety | None = None,
    v_max: float | None = None,
) -> np.ndarray:
    """Eq. 4.41: u_i = -k_c (x_i - O_e) + k_f sum_j exp(-|x_ij| / R_s) (x_i - x_j), R_s = sqrt(a b / N) (Theorem 3,
    ``cohesion_radius``). Neighbours (the thesis leaves Delta for 50 agents open): "knn" the ``k`` nearest (default
    6), or "all", truncated at ``cutoff_scales`` R_s (12: a dropped pair weighs below 12 e^-12 R_s = 7e-5 R_s; for
    1000 agents in a disc at the cohesion density the largest error is 4e-4 of the largest repulsion, at a quarter of
    the exact law's cost; ``None``: every pair, O(N^2))."""
    x = np.asarray(x, dtype=float)
    cutoff = None if cutoff_scales is None else cutoff_scales * r_s
    return _law(x, centre, k_c, k_f, neighbour_pairs(x, neighbours, k, cutoff), r_s, safety, v_max)


def packing_law(
    x: np.ndarray,
    circle_centres: np.ndarray,
    k_a: float = 22.4,
    k_r: float = 190.45,
    r_s: float = 1.0,
    cutoff_scales: float | None = 20.0,
    v_max: float | None = None,
) -> np.ndarray:
    """Eq. 5.2: u_i = -k_a (x_i - c_s^i) + k_r sum_j exp(-|x_ij| / (2 r_s)) (x_i - x_j), every agent toward its own
    circle centre (N, 2); Table 5.1's gains. All pairs, truncated at ``cutoff_scales`` x 2 r_s (``None``: none)."""
    x = np.asarray(x, dtype=float)
    cutoff = None if cutoff_scales is None else cutoff_scales * 2 * r_s
    return _law(x, circle_centres, k_a, k_r, neighbour_pairs(x, "all", 0, cutoff), 2 * r_s, None, v_max)


def split_merge_law(
    x: np.ndarray,
    centre: np.ndarray,
    obstacles: np.ndarray | None = None,
    mode: str = "nearest",
    k_c: float = 12.0,
    k_f: float = 2.5,
    r_s: float = 1.0,
    radius_scales: float = 3.0,
    v_max: float | None = None,
    neighbours: int = 8,
    min_sep: float = 0.0,
) -> np.ndarray:
    """Eq. 6.5: u_i = -k_c (x_i - O_e) + k_f exp(-|x_i - r| / r_s) (x_i - r), Table 6.1's gains; ``centre`` (2,) or
    each agent's sub-region centre (N, 2). The printed sum over j does not depend on j (erratum 22): ``mode``
    "nearest", r the closest agent or obstacle point; "sum", every agent and obstacle point within ``radius_scales``
    r_s; "knn", the ``neighbours`` nearest of those (nearest first): the sum's spacing at a cost linear in N, where
    a dense swarm's full sum has hundreds of pairs per agent.

    ``min_sep`` (erratum 22, r_s as a kept distance): §6.2.3 defines r_s as "the minimum distance ... required to be
    maintained" from r(t), which the printed kernel cannot hold (it vanishes at contact, at most k_f r_s / e per
    neighbour against the pull's k_c per unit). With ``min_sep`` > 0 an agent closer than
    ``min_sep`` r_s is pushed away from it at k (min_sep r_s - |x_ij|), k = k_c or enough to reach ``v_max`` 10 %
    inside, and the push has the first share of ``v_max`` (avoidance first, then convergence; agents only, the
    obstacles keep the printed kernel); 0, the law as printed."""
    if mode not in CH6_MODES:
        raise ValueError(f"mode: expected one of {', '.join(CH6_MODES)}, got {mode!r}")
    if not (isinstance(min_sep, (int, float)) and math.isfinite(min_sep) and min_sep >= 0):
        raise ValueError(f"min_sep: must be a finite number >= 0, got {min_sep!r}")
    x = np.asarray(x, dtype=float)
    n = len(x)
    obs = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, dtype=float).reshape(-1, 2)
    obs = obs[np.isfinite(obs).all(axis=1)]
    pts = np.concatenate([x, obs])
    u = _pull(x, centre, k_c)
    if len(pts) < 2:
        return saturate(u, v_max)
    tree = cKDTree(pts)
    if mode == "nearest":
        _, idx = tree.query(x, k=2)
        other = np.where(idx[:, 0] == np.arange(n), idx[:, 1], idx[:, 0])
        u = u + k_f * kernel_sum(pts[:n], np.arange(n), other, r_s, others=pts)
    elif mode == "knn":
        if not (isinstance(neighbours, int) and neighbours >= 1):
            raise ValueError(f"neighbours: must be an integer >= 1, got {neighbours!r}")
        k = min(neighbours + 1, len(pts))
        # agents on one spot (bit for bit) have the same neighbours and the same sum: each spot's is worked out once
        # (dropping another agent of the spot instead of oneself drops the same zero term)
        first, same = unique_rows(x)
        _, idx = tree.query(x[first], k=k, distance_upper_bound=radius_scales * r_s)
        idx = idx.reshape(len(first), k)
        i = np.repeat(np.arange(len(first)), k).reshape(len(first), k)
        keep = (idx < len(pts)) & (idx != first[:, None])
        u = u + k_f * kernel_sum(x[first], i[keep], idx[keep], r_s, others=pts)[same]
    else:
        lists = tree.query_ball_point(x, radius_scales * r_s)
        i = np.repeat(np.arange(n), [len(v) for v in lists])
        j = np.concatenate([np.asarray(v, int) for v in lists]) if len(i) else np.zeros(0, int)
        keep = j != i
        u = u + k_f * kernel_sum(x, i[keep], j[keep], r_s, others=pts)
    if min_sep > 0 and n > 1:
        u = _keep_apart(x, u, min_sep * r_s, k_c, v_max)
    return saturate(u, v_max)


def _keep_apart(x: np.ndarray, u: np.ndarray, sep: float, k: float, v_max: float | None) -> np.ndarray:
    """``u`` plus, for every pair of agents closer than ``sep``, a push away from the other at k (sep - d), k at least
    10 ``v_max`` / ``sep`` (a pair 10 % inside ``sep`` pushes at ``v_max``); the push takes its share of ``v_max``
    first, and u the rest (coincident agents part along a fixed direction per index: the golden angle times i)."""
    i, j = _both(cKDTree(x).query_pairs(sep, output_type="ndarray"))
    if not len(i):
        return u
    away = x[i] - x[j]
    r = np.hypot(away[:, 0], away[:, 1])
    ang = i * 2.399963229728653
    unit = np.where((r > 0)[:, None], away / np.maximum(r, 1e-300)[:, None], np.stack([np.cos(ang), np.sin(ang)], 1))
    n = len(x)
    w = (k if v_max is None else max(k, 10.0 * v_max / sep)) * (sep - r)
    push = saturate(np.stack([np.bincount(i, w * unit[:, 0], n), np.bincount(i, w * unit[:, 1], n)], axis=1), v_max)
    if v_max is None:
        return u + push
    left = np.maximum(v_max - np.hypot(push[:, 0], push[:, 1]), 0.0)  # the push first, the rest of v_max for u
    scale = np.minimum(1.0, left / np.maximum(np.hypot(u[:, 0], u[:, 1]), 1e-300))
    return push + u * scale[:, None]


# --- Theorem 1 (eqs. 4.7-4.21, erratum 13) ----------------------------------------------------------------------------


def theorem1_kc(n: int, k_f: float, rho: float, r_c: float) -> float:
    """Erratum 13: the convergence gain the thesis never gives, from r_c = N k_f rho e^-1 / k_c (eq. 4.16)."""
    return n * k_f * rho * math.exp(-1.0) / r_c


def theorem1_rc(n: int, k_f: float, rho: float, k_c: float) -> float:
    """Eq. 4.16: the containment radius r_c = N k_f rho e^-1 / k_c."""
    return n * k_f * rho * math.exp(-1.0) / k_c


def entry_time_bound(x0: np.ndarray, centre: np.ndarray, k_c: float, r_c: float) -> np.ndarray:
    """Eq. 4.21 per agent: tau_i = -(1 / 2 k_c) ln(r_c^2 / |x_i(0) - O_c|^2) (0 for an agent already inside): the
    pure convergence term's entry time, which the proof claims as a bound with the formation term on."""
    e0 = np.hypot(*(np.asarray(x0, dtype=float) - np.asarray(centre, dtype=float)).T)
    return np.where(e0 > r_c, np.log(np.maximum(e0, r_c) / r_c) / k_c, 0.0)


def entry_time_bound_proved(
    x0: np.ndarray, centre: np.ndarray, k_c: float, r_c: float, degree: np.ndarray, n: int
) -> np.ndarray:
    """The bound the proof supports once eq. 4.17's dropped term is kept: each formation neighbour pushes at most
    rho / e (the maximum of s e^(-s / rho)), so d|e_i|/dt <= -k_c |e_i| + k_c q_i r_c with q_i = deg_i / N < 1
    (eq. 4.16's r_c), and agent i enters B_rc(O_c) by tau_i' = (1 / k_c) ln((|e_i(0)| - q_i r_c) / ((1 - q_i) r_c))
    >= tau_i, and never leaves it (it is driven into the ball of radius q_i r_c)."""
    e0 = np.hypot(*(np.asarray(x0, dtype=float) - np.asarray(centre, dtype=float)).T)
    q = np.asarray(degree, dtype=float) / n
    return np.where(e0 > r_c, np.log((np.maximum(e0, r_c) - q * r_c) / ((1 - q) * r_c)) / k_c, 0.0)
