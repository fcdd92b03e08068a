"""The figures Roy (2022) scores chapters 4-7 with (digest 001 §5.5), on arrays of agent positions, for swarms of
up to a thousand agents (pairs are found with a k-d tree, never all N^2 of them).

- ``travel_variance_index``: TVI, eq. 4.51 (``path_lengths`` gives each agent's travel from a track).
- ``structural_density``: D(t) with chapter 4's (eq. 4.50), 5's (eqs. 5.13-5.14) or 6's (eq. 6.25) link rule.
- ``formation_error_ef``: chapter 4's e_f (eq. 4.22) against rho o Delta; ``formation_error``: chapter 7's FE
  (eq. 7.1, erratum 27), with ``pair_shares``, its two halves (the chapter 3 co-simulation scores with them).
- ``obstacle_sensing``: SO and SOI (eqs. 4.48-4.49) from each sensed point's owner and obstacle.
- ``unused_area``: UA (eq. 5.12).
- ``summarise``, ``region_statistics``: mean, sd, COV and the quartiles of a series (Tables 6.2, 6.3, 7.7 and the
  region area statistics of §4.2 and §7.4).
- ``linear_fit``: time against N with R^2 (targets C8, C10).

Non-finite positions belong to no pair; every function returns plain numbers (``as_dict`` for the dataclasses).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np
from scipy.spatial import cKDTree

LinkRule = Literal["ch4", "ch5", "ch6"]
# (low, low included, high, high included) in units of the rule's scale: R_s for chapter 4, r_s for 5 and 6
LINK_RULES: dict[str, tuple[float, bool, float, bool]] = {
    "ch4": (1.0, True, 2.0, False),  # eq. 4.50: R_s <= x_ij < 2 R_s
    "ch5": (2.0, False, 4.0, True),  # eqs. 5.13-5.14: 2 r_s < x_ij <= 4 r_s
    "ch6": (0.0, True, 2.0, True),  # eq. 6.25: x_ij <= 2 r_s
}


def _finite(xy: np.ndarray) -> np.ndarray:
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    return p[np.isfinite(p).all(axis=1)]


def pair_lengths(xy: np.ndarray, within: float) -> np.ndarray:
    """The distances of the unordered pairs of finite positions (N, 2) that are at most ``within`` apart (a k-d tree
    finds them, each length is then ``hypot`` of the pair's difference, as a dense computation would give)."""
    p = _finite(xy)
    if len(p) < 2 or not within >= 0:
        return np.zeros(0)
    pairs = cKDTree(p).query_pairs(within * (1 + 1e-9) + 1e-300, output_type="ndarray")
    d = np.hypot(p[pairs[:, 0], 0] - p[pairs[:, 1], 0], p[pairs[:, 0], 1] - p[pairs[:, 1], 1])
    return d[d <= within]


def _count_between(d: np.ndarray, lo: float, lo_in: bool, hi: float, hi_in: bool) -> int:
    above = d >= lo if lo_in else d > lo
    below = d <= hi if hi_in else d < hi
    return int(np.count_nonzero(above & below))


def structural_density(xy: np.ndarray, scale: float, rule: LinkRule = "ch6", groups: np.ndarray | None = None) -> float:
    """D(t) = sum_i sum_j g_ij / (N (N - 1)): the share of ordered pairs i != j linked by ``rule`` (``LINK_RULES``)
    with ``scale`` R_s (chapter 4, R_s = sqrt(ab / N)) or r_s (chapters 5, 6); 0 for fewer than two agents.

    ``groups`` (N,) sub-swarm ids: only pairs within a sub-swarm count, D = sum_g links_g / sum_g Q_g (Q_g - 1) (the
    reading of §6.5.1's "inside the virtual region" under which D rises after a split; agents with a negative id
    belong to none); None: every pair of the N agents, eq. 6.25 as printed."""
    if groups is not None:
        g = np.asarray(groups).reshape(-1)
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        if len(g) != len(p):
            raise ValueError(f"structural_density: groups must have one id per agent ({len(p)}), got {len(g)}")
        links = pairs = 0.0
        for k in np.unique(g[g >= 0]):
            q = int(np.count_nonzero(g == k))
            links += structural_density(p[g == k], scale, rule) * q * (q - 1)
            pairs += q * (q - 1)
        return links / pairs if pairs else 0.0
    if rule not in LINK_RULES:
        raise ValueError(f"structural_density: rule must be one of {tuple(LINK_RULES)}, got {rule!r}")
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"structural_density: scale must be finite and > 0, got {scale}")
    n = len(np.asarray(xy).reshape(-1, 2))
    if n < 2:
        return 0.0
    lo, lo_in, hi, hi_in = LINK_RULES[rule]
    links = _count_by_tree(xy, lo * scale, hi * scale)
    if links is None:  # a pair lies on a bound (to 1e-9): count exactly, with each bound's own inclusion
        links = _count_between(pair_lengths(xy, hi * scale), lo * scale, lo_in, hi * scale, hi_in)
    return 2 * links / (n * (n - 1))


def _count_by_tree(xy: np.ndarray, lo: float, hi: float) -> int | None:
    """The unordered pairs of finite positions with lo < x_ij < hi, counted by the k-d tree without listing them (a
    packed swarm of 1000 has most of its half million pairs within 2 r_s), when no pair lies within 1e-9 (relative) of
    either bound, so that whether a bound is included cannot matter; None otherwise."""
    p = _finite(xy)
    if len(p) < 2:
        return 0
    tree = cKDTree(p)
    bounds = [b for b in (lo, hi) if b > 0]
    radii = np.array([r for b in bounds for r in (b * (1 - 1e-9), b * (1 + 1e-9))])
    counts = (tree.count_neighbors(tree, radii) - len(p)) // 2  # ordered pairs, self-pairs included
    if np.any(counts[0::2] != counts[1::2]):
        return None
    below_hi = int(counts[-1])
    below_lo = int(counts[0]) if lo > 0 else 0
    return below_hi - below_lo


def pair_shares(xy: np.ndarray, r_s: float) -> tuple[float, float]:
    """The shares of the ordered pairs i != j closer than 2 r_s and farther than 3 r_s (0, 0 for fewer than 2)."""
    n = len(np.asarray(xy).reshape(-1, 2))
    if n < 2:
        return 0.0, 0.0
    m = len(_finite(xy))
    d = pair_lengths(xy, 3 * r_s)
    pairs = n * (n - 1)
    close = 2 * int(np.count_nonzero(d < 2 * r_s))
    far = m * (m - 1) - 2 * len(d)
    return float(close) / pairs, float(far) / pairs


def formation_error(xy: np.ndarray, r_s: float, rule: Literal["repaired", "literal"] = "repaired") -> float:
    """Eq. 7.1: FE = 1 - #{ordered pairs i != j in formation} / (N (N - 1)), 0 best, 1 worst; 0 for fewer than two
    agents. "repaired" (erratum 27, the default): a pair is in formation when 2 r_s <= x_ij <= 3 r_s; "literal": as
    printed, 2 r_s >= x_ij >= 3 r_s, which no pair meets (FE = 1)."""
    if rule not in ("repaired", "literal"):
        raise ValueError(f"formation_error: rule must be 'repaired' or 'literal', got {rule!r}")
    if rule == "literal":
        return 1.0 if len(np.asarray(xy).reshape(-1, 2)) >= 2 else 0.0
    close, far = pair_shares(xy, r_s)
    return close + far


def formation_error_ef(xy: np.ndarray, rho: float | np.ndarray, adjacency: np.ndarray) -> float:
    """Chapter 4's formation error (eq. 4.22): e_f = sum_i sum_{j in N_i} ((rho o Delta)_ij^2 - x_ij^2)^2 over the
    ordered pairs with Delta_ij != 0 (each edge twice, as the double sum runs); ``rho`` a scalar or (N, N)."""
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    adj = np.asarray(adjacency)
    if adj.shape != (len(p), len(p)):
        raise ValueError(f"formation_error_ef: adjacency must be ({len(p)}, {len(p)}), got {adj.shape}")
    i, j = np.nonzero(adj)
    r = np.broadcast_to(np.asarray(rho, dtype=float), adj.shape)[i, j]
    d2 = (p[i, 0] - p[j, 0]) ** 2 + (p[i, 1] - p[j, 1]) ** 2
    return float(np.sum((r * r - d2) ** 2))


def path_lengths(track: np.ndarray) -> np.ndarray:
    """Each agent's travelled distance s_i from a track (T, N, 2): the sum of its steps (steps with a non-finite end
    count 0)."""
    t = np.asarray(track, dtype=float)
    step = np.hypot(*np.moveaxis(np.diff(t, axis=0), -1, 0))
    return np.where(np.isfinite(step), step, 0.0).sum(axis=0)


def travel_variance_index(travelled: Sequence[float] | np.ndarray) -> float:
    """TVI (eq. 4.51): L_V = (sum s_i)^2 / (N sum s_i^2), from 1/N (one agent does all the travel) to 1 (all travel
    alike); 1 when no agent moved. Non-finite or negative distances are a ValueError."""
    s = np.asarray(travelled, dtype=float).ravel()
    if not len(s) or np.any(~np.isfinite(s)) or np.any(s < 0):
        raise ValueError(f"travel_variance_index: needs distances that are finite and >= 0, got {s.tolist()[:8]}")
    sq = float(np.sum(s * s))
    return 1.0 if sq == 0 else float(np.sum(s)) ** 2 / (len(s) * sq)


@dataclass(frozen=True)
class ObstacleSensing:
    """SO(t) (eq. 4.48), the number of agents sensing each obstacle (index = obstacle label), SOI(t) (eq. 4.49), 0
    when no obstacle is sensed, and the points dropped for a negative label or owner."""

    so: tuple[int, ...]
    soi: float
    dropped: int

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def obstacle_sensing(
    owner: Sequence[int] | np.ndarray, obstacle: Sequence[int] | np.ndarray, n_obstacles: int | None = None
) -> ObstacleSensing:
    """SO and SOI = max(SO) / sum(SO) from each sensed point's ``owner`` (the agent whose sonar saw it) and
    ``obstacle`` (its obstacle's label, e.g. a cluster; negative: none, dropped): an agent counts once per obstacle
    however many of its beams hit it. ``n_obstacles`` sets SO's length (U), default the largest label + 1."""
    ow = np.asarray(owner, dtype=int).ravel()
    ob = np.asarray(obstacle, dtype=int).ravel()
    if len(ow) != len(ob):
        raise ValueError(f"obstacle_sensing: {len(ow)} owners for {len(ob)} points")
    ok = (ow >= 0) & (ob >= 0)
    u = (int(ob[ok].max()) + 1 if ok.any() else 0) if n_obstacles is None else n_obstacles
    if u < (int(ob[ok].max()) + 1 if ok.any() else 0):
        raise ValueError(f"obstacle_sensing: n_obstacles {u} is less than the labels used")
    seen = np.unique(np.stack([ob[ok], ow[ok]], axis=1), axis=0) if ok.any() else np.zeros((0, 2), int)
    so = np.bincount(seen[:, 0], minlength=u) if u else np.zeros(0, int)
    total = int(so.sum())
    return ObstacleSensing(tuple(int(k) for k in so), float(so.max()) / total if total else 0.0, int((~ok).sum()))


def unused_area(area: float, n: int, r_s: float) -> float:
    """UA = A - N pi r_s^2 (eq. 5.12): the region's area beyond what N discs of radius r_s need."""
    return float(area) - n * math.pi * r_s * r_s


@dataclass(frozen=True)
class Summary:
    """A series' count, mean, sd (population, ``ddof`` 0, unless asked), COV = sd / mean, median, quartiles, IQR,
    extremes; NaN where the series is empty (COV: also where the mean is 0)."""

    n: int
    mean: float
    sd: float
    cov: float
    median: float
    q1: float
    q3: float
    iqr: float
    min: float
    max: float

    def as_dict(self) -> dict[str, float | None]:
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(self).items()}


def summarise(values: Sequence[float] | np.ndarray, ddof: int = 0) -> Summary:
    """The ``Summary`` of the finite ``values`` (non-finite ones are left out)."""
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if len(v) <= ddof:
        nan = math.nan
        m = float(v.mean()) if len(v) else nan
        return Summary(len(v), m, nan, nan, m, m, m, nan, m, m)
    mean, sd = float(v.mean()), float(v.std(ddof=ddof))
    q1, med, q3 = (float(x) for x in np.percentile(v, [25, 50, 75]))
    return Summary(
        len(v), mean, sd, sd / mean if mean != 0 else math.nan, med, q1, q3, q3 - q1, float(v.min()), float(v.max())
    )


def region_statistics(
    a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray, ddof: int = 0
) -> dict[str, Summary]:
    """The area pi a b and the semi-axes a and b over a run (samples of the region), each a ``Summary``."""
    av, bv = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    if av.shape != bv.shape:
        raise ValueError(f"region_statistics: {len(av)} values of a for {len(bv)} of b")
    return {"area": summarise(math.pi * av * bv, ddof), "a": summarise(av, ddof), "b": summarise(bv, ddof)}


@dataclass(frozen=True)
class LinearFit:
    """y = intercept + slope x by least squares, with R^2 and the number of points."""

    intercept: float
    slope: float
    r2: float
    n: int

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def linear_fit(x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray) -> LinearFit:
    """Least-squares line through (x, y) (e.g. mean execution time against N, Tables 6.2 and 6.3) and R^2 = 1 -
    SS_res / SS_tot (1 when y is constant and fitted exactly). Needs two distinct finite x."""
    xv, yv = np.asarray(x, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()
    if xv.shape != yv.shape or not (np.isfinite(xv).all() and np.isfinite(yv).all()) or len(np.unique(xv)) < 2:
        raise ValueError(
            f"linear_fit: needs as many x as y ({len(xv)}, {len(yv)}), all finite, two distinct x at least"
        )
    xm, ym = xv.mean(), yv.mean()
    slope = float(np.sum((xv - xm) * (yv - ym)) / np.sum((xv - xm) ** 2))
    intercept = float(ym - slope * xm)
    res = float(np.sum((yv - intercept - slope * xv) ** 2))
    tot = float(np.sum((yv - ym) ** 2))
    return LinearFit(intercept, slope, 1 - res / tot if tot > 0 else (1.0 if res == 0 else 0.0), len(xv))
