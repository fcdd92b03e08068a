"""Chapter 4's global controller (Roy 2022 eqs. 4.30-4.37, 4.46-4.47, Theorem 3): the free-space gap by k-means
(K = 2) on the sensed obstacle points, the moving-obstacle test, and the circle/ellipse region that follows the gap
toward the target with its area kept (shrunk when agents fail).

The thesis' printed update (erratum 10) and axes (erratum 11) are both available; the repaired and geometric ones
are the defaults. Everything returns plain values that can be logged (``as_dict``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.cluster.vq import ClusterError, kmeans2
from scipy.spatial import cKDTree

from swarm_logic.families.roy.regions.records import Logged, check_fields
from swarm_logic.families.roy.regions.shapes import Ellipse
from swarm_logic.geometry import wrap

GAP_MODES = ("closest", "centroid")
SPLITS = ("kmeans", "sides")
DYNAMICS = ("repaired", "literal")
AXES = ("geometric", "literal")


# --- the free space (eq. 4.30, erratum 12) ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Gap(Logged):
    """The sensed free space: its width ``b_fs`` (``inf``: no gap sensed), the two cluster centroids ``c1``, ``c2``
    (r_o1, r_o2), the two points whose distance is ``b_fs`` (``p1``, ``p2``: the centroids in "centroid" mode, the
    closest pair in "closest" mode), their bearings ``theta1``, ``theta2`` from the region centre, the point count and
    why no gap was sensed (``reason``, empty when one was)."""

    b_fs: float
    c1: tuple[float, float] | None = None
    c2: tuple[float, float] | None = None
    p1: tuple[float, float] | None = None
    p2: tuple[float, float] | None = None
    theta1: float = math.nan
    theta2: float = math.nan
    n_points: int = 0
    reason: str = ""

    @property
    def sensed(self) -> bool:
        return math.isfinite(self.b_fs)

    @property
    def midpoint(self) -> np.ndarray:
        """R of eq. 4.36: the midpoint of the two cluster centres."""
        return (np.asarray(self.c1) + np.asarray(self.c2)) / 2.0


def _farthest_pair_init(p: np.ndarray) -> np.ndarray:
    """A deterministic k-means start: the point farthest from the mean, then the point farthest from it."""
    i = int(np.argmax(np.sum((p - p.mean(axis=0)) ** 2, axis=1)))
    j = int(np.argmax(np.sum((p - p[i]) ** 2, axis=1)))
    return p[[i, j]].copy()


def free_space(
    points: np.ndarray, centre: np.ndarray, mode: str = "closest", heading: float | None = None, split: str = "kmeans"
) -> Gap:
    """Eq. 4.30: split the obstacle points (K, 2) into two clusters (k-means, K = 2, from a deterministic farthest-pair
    start: same input, same answer) and measure the free space between them. ``mode`` "centroid": b_fs = |r_o1 - r_o2|
    as printed; "closest" (erratum 12, default): the closest pair of points across the two clusters (the centroids
    lie inside the obstacles' point clouds, so their distance over-estimates the gap). Below 2 finite points, or when
    every point falls in one cluster, no gap is sensed (b_fs = inf).

    Two options of ours for a planner, off by default (the thesis assumes obstacles on both sides of one path ahead):
    ``heading``: the two clusters' centroids must lie on opposite sides of the line through ``centre`` along
    ``heading`` (say, toward the target), else "one side" and no gap: k-means also cuts a single wall in two, and
    would report a gap as wide as the spacing of that wall's points. ``split`` "sides" (needs ``heading``): the two
    clusters are the points left and right of that line instead of k-means' (inside a corridor k-means cuts the walls
    into a front and a back half, whose closest pair is two neighbouring points of one wall)."""
    if mode not in GAP_MODES:
        raise ValueError(f"mode: expected one of {', '.join(GAP_MODES)}, got {mode!r}")
    if split not in SPLITS:
        raise ValueError(f"split: expected one of {', '.join(SPLITS)}, got {split!r}")
    if split == "sides" and heading is None:
        raise ValueError("split: 'sides' needs a heading")
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    p = p[np.isfinite(p).all(axis=1)]
    o = np.asarray(centre, dtype=float)
    if len(p) < 2:
        return Gap(math.inf, n_points=len(p), reason="fewer than 2 points")
    if np.ptp(p, axis=0).max() == 0.0:
        return Gap(math.inf, n_points=len(p), reason="one cluster")
    if split == "sides":
        label = (np.cos(heading) * (p[:, 1] - o[1]) - np.sin(heading) * (p[:, 0] - o[0]) < 0).astype(int)
        if label.min() == label.max():
            return Gap(math.inf, n_points=len(p), reason="one side")
        cent = np.stack([p[label == 0].mean(axis=0), p[label == 1].mean(axis=0)])
    else:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cent, label = kmeans2(p, _farthest_pair_init(p), minit="matrix", missing="raise")
        except ClusterError:
            return Gap(math.inf, n_points=len(p), reason="one cluster")
    a, b = p[label == 0], p[label == 1]
    if len(a) == 0 or len(b) == 0:
        return Gap(math.inf, n_points=len(p), reason="one cluster")
    if heading is not None:
        side = np.cos(heading) * (cent[:, 1] - o[1]) - np.sin(heading) * (cent[:, 0] - o[0])
        if side[0] * side[1] >= 0:
            return Gap(math.inf, n_points=len(p), reason="one side")
    if mode == "centroid":
        p1, p2 = cent[0], cent[1]
    else:
        dist, j = cKDTree(b).query(a)
        i = int(np.argmin(dist))
        p1, p2 = a[i], b[int(j[i])]
    t1, t2 = (math.atan2(q[1] - o[1], q[0] - o[0]) for q in (p1, p2))
    return Gap(
        float(np.hypot(*(p1 - p2))),
        tuple(map(float, cent[0])),
        tuple(map(float, cent[1])),
        tuple(map(float, p1)),
        tuple(map(float, p2)),
        t1,
        t2,
        len(p),
    )


def gap_bisector(gap: Gap, toward: float) -> float:
    """The gap's bisecting bearing (theta1 + theta2) / 2, taken as the circular mean so it never jumps at +-pi, and
    turned by pi if needed to lie within 90° of ``toward`` (an ellipse's axis is a line). When the two bearings are
    opposite (the centre between the obstacles) the mean is the normal of the segment p1-p2."""
    s = math.sin(gap.theta1) + math.sin(gap.theta2)
    c = math.cos(gap.theta1) + math.cos(gap.theta2)
    if math.hypot(s, c) > 1e-6:
        t = math.atan2(s, c)
    else:
        dx, dy = gap.p2[0] - gap.p1[0], gap.p2[1] - gap.p1[1]
        t = math.atan2(dx, -dy)
    return wrap(t + math.pi) if abs(wrap(t - toward)) > math.pi / 2 else t


# --- the moving-obstacle test (eqs. 4.36-4.37) ------------------------------------------------------------------------


@dataclass(frozen=True)
class GapDecision(Logged):
    """One window's verdict: ``status`` "accepted" (``gap`` is the reference window's gap, eq. 4.37), "blocked" (a
    mover came into the gap: AD(t2) < AD(t1); retry at the next window), "pending" (first window: no reference yet)
    or "no_gap" (the reference window sensed no gap: nothing to test); the two mean distances."""

    status: str
    gap: Gap | None
    ad_ref: float = math.nan
    ad_now: float = math.nan


def mean_distance(points: np.ndarray, ref: np.ndarray) -> float:
    """AD of eq. 4.36: the mean distance of the points (K, 2) from R; NaN for no points."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    p = p[np.isfinite(p).all(axis=1)]
    return float(np.mean(np.hypot(*(p - ref).T))) if len(p) else math.nan


class MovingObstacleTest:
    """Eqs. 4.36-4.37 fed one window at a time: each window's points are tested against the previous window's gap
    (R its midpoint, AD(t1) its mean distance), then become the reference for the next (a blocked gap is retried at
    the next window). A window with no points cannot block: the reference gap is accepted."""

    def __init__(self) -> None:
        self._ref: tuple[Gap, float] | None = None

    def reset(self) -> None:
        self._ref = None

    def feed(self, points: np.ndarray, gap: Gap) -> GapDecision:
        ref, self._ref = self._ref, None
        if gap.sensed:
            self._ref = (gap, mean_distance(points, gap.midpoint))
        if ref is None:
            return GapDecision("pending" if gap.sensed else "no_gap", None)
        ref_gap, ad_ref = ref
        ad_now = mean_distance(points, ref_gap.midpoint)
        if math.isnan(ad_now) or ad_now >= ad_ref:
            return GapDecision("accepted", ref_gap, ad_ref, ad_now)
        return GapDecision("blocked", None, ad_ref, ad_now)


# --- the region (eqs. 4.31-4.35, 4.47, Theorem 3) ---------------------------------------------------------------------


def failure_area_factor(n: int, n_failed: float) -> float:
    """(N - N') / N of eq. 4.47."""
    if n <= 0 or not 0 <= n_failed <= n:
        raise ValueError(f"n_failed: must lie in [0, N = {n}], got {n_failed}")
    return (n - n_failed) / n


def shrunk_major_axis(r_c: float, u_b: float, n: int, n_failed: float) -> float:
    """Eq. 4.47: u_a = (r_c^2 / u_b) (N - N') / N, the major semi-axis after N' agents failed."""
    return r_c * r_c / u_b * failure_area_factor(n, n_failed)


def cohesion_radius(a: float, b: float, n: int) -> float:
    """Theorem 3: R_s = sqrt(a b / N), from N pi R_s^2 = pi a b (maximum cohesion)."""
    if n <= 0:
        raise ValueError(f"n: must be >= 1, got {n}")
    return math.sqrt(a * b / n)


@dataclass(frozen=True)
class RegionParams:
    """The region controller's parameters (Table 4.1 and the digest's §5.3 defaults).

    ``dynamics`` (erratum 10): "repaired" sets a, b to their targets (through a first-order lag of time constant
    ``axes_lag`` s when > 0), alpha_e = atan2(T - O), turns theta toward the gap bisector (obstacles sensed) or T
    at rate ``k_theta`` and moves at min(k_vcir |O - T|, v_max); "literal" integrates eqs. 4.31-4.35 as printed
    (targets as rates, unbounded speed). ``axes`` (erratum 11): "geometric" b = b_fs / 2 - ``clearance``, switching
    to the ellipse when b_fs < 2 r; "literal" b = b_fs, switching when b_fs < r (r the equal-area radius). ``barrier``:
    the centre advances only when every (non-failed) agent is inside the region. ``r_robot``: the body radius for
    the "cannot hold the swarm" test (area < N pi r_robot^2)."""

    r_c: float = 2.5
    k_vcir: float = 10.0
    v_max: float = 0.3
    k_theta: float = 2.0
    dynamics: str = "repaired"
    axes: str = "geometric"
    clearance: float = 0.5
    axes_lag: float = 0.0
    barrier: bool = True
    r_robot: float = 0.5

    def __post_init__(self) -> None:
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics: expected one of {', '.join(DYNAMICS)}, got {self.dynamics!r}")
        if self.axes not in AXES:
            raise ValueError(f"axes: expected one of {', '.join(AXES)}, got {self.axes!r}")
        check_fields(self, ("r_c", "k_vcir", "v_max", "k_theta"))
        check_fields(self, ("clearance", "axes_lag", "r_robot"), positive=False)


def axis_targets(b_fs: float, params: RegionParams, area_factor: float = 1.0) -> tuple[float, float]:
    """Eqs. 4.34-4.35 and 4.47: the target semi-axes (a, b) for a free space b_fs (``inf``: none sensed). The area
    is pi r^2 with r = r_c sqrt(area_factor); a circle of radius r unless the gap is narrower than the mode's
    threshold (r literal, 2 r geometric), then b from the gap and a = r^2 / b (equal area, target A4). The b of the
    geometric mode can be <= 0 (a gap narrower than twice the clearance): the caller decides (``RegionStep``)."""
    r = params.r_c * math.sqrt(area_factor)
    if params.axes == "literal":
        if not b_fs < r:
            return r, r
        b = b_fs
    else:
        if not b_fs < 2 * r:
            return r, r
        b = b_fs / 2.0 - params.clearance
    return (r * r / b if b > 0 else math.inf), b


@dataclass(frozen=True)
class RegionState(Logged):
    """The region and its controller's state: the ellipse, its speed ``v`` and the target bearing ``alpha`` (both
    integrated in the literal dynamics), and the last region that could hold the swarm."""

    region: Ellipse
    v: float = 0.0
    alpha: float = 0.0


@dataclass(frozen=True)
class RegionStep(Logged):
    """One update's outcome: the new state, whether the centre advanced, the target axes and why anything was held
    (``held``: "barrier", "gap blocked", "infeasible: ..." or "")."""

    state: RegionState
    advanced: bool
    a_target: float
    b_target: float
    held: str = ""
    notes: dict[str, float] = field(default_factory=dict)


def can_hold(a: float, b: float, n: int, r_robot: float) -> str:
    """Why a region of semi-axes (a, b) cannot hold ``n`` agents of radius ``r_robot`` ("" if it can): a semi-axis
    not finite and > 0, or an area below N pi r_robot^2."""
    if not (math.isfinite(a) and math.isfinite(b) and a > 0 and b > 0):
        return f"infeasible: semi-axes a = {a:.4g}, b = {b:.4g}"
    if a * b < n * r_robot * r_robot:
        return f"infeasible: area {math.pi * a * b:.4g} < N pi r_robot^2 = {n * math.pi * r_robot * r_robot:.4g}"
    return ""


def step_region(
    state: RegionState,
    gap: Gap,
    target: np.ndarray,
    dt: float,
    params: RegionParams,
    positions: np.ndarray | None = None,
    active: np.ndarray | None = None,
    n_failed: int = 0,
    blocked: bool = False,
) -> RegionStep:
    """One global-controller update of the region by ``dt`` s toward ``target`` (2,), given the committed ``gap``.

    ``positions`` (N, 2) with ``active`` (N,) (default all) feed the barrier and the agent count N of the failure
    shrink (eq. 4.47 with ``n_failed``) and of the capacity test; ``blocked`` (the moving-obstacle test said so)
    holds the region where it is. A region that cannot hold the swarm is not adopted: the last one is kept and
    ``held`` says why."""
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be finite and > 0, got {dt}")
    if n_failed and positions is None:
        raise ValueError("n_failed: needs the positions (and active mask) of the swarm it is counted against")
    e = state.region
    tgt = np.asarray(target, dtype=float)
    if tgt.shape != (2,) or not np.isfinite(tgt).all():
        raise ValueError(f"target: expected 2 finite numbers, got {target!r}")
    x = None if positions is None else np.asarray(positions, dtype=float).reshape(-1, 2)
    act = None if x is None else (np.ones(len(x), bool) if active is None else np.asarray(active, bool))
    n_active = 0 if act is None else int(act.sum())
    n_total = n_active + n_failed
    factor = failure_area_factor(n_total, n_failed) if n_total > 0 else 1.0
    a_t, b_t = axis_targets(gap.b_fs, params, factor)
    if blocked:
        return RegionStep(state, False, a_t, b_t, "gap blocked")
    to_t = tgt - e.centre
    dist_t = float(np.hypot(*to_t))
    inside = True
    if x is not None and params.barrier and n_active:
        inside = bool(np.all(e.contains(x[act])))
    if params.dynamics == "literal":
        alpha_rate = math.atan2(to_t[1], to_t[0])
        u_theta = state.alpha - ((gap.theta1 + gap.theta2) / 2 if gap.sensed else e.theta)
        u_v = params.k_vcir * dist_t
        u_a, u_b = a_t, b_t  # eqs. 4.34-4.35 (4.47 through the area factor): targets integrated as rates (erratum 10)
        step = state.v * dt if inside else 0.0
        new = (
            Ellipse(
                e.x + step * math.cos(e.theta),
                e.y + step * math.sin(e.theta),
                e.a + u_a * dt,
                e.b + u_b * dt,
                e.theta + u_theta * dt,
            )
            if math.isfinite(u_a) and u_b > 0
            else None
        )
        new_state = None if new is None else RegionState(new, state.v + u_v * dt, state.alpha + alpha_rate * dt)
    else:
        alpha = math.atan2(to_t[1], to_t[0]) if dist_t > 0 else state.alpha
        cmd = gap_bisector(gap, alpha) if gap.sensed else alpha
        gain = min(params.k_theta * dt, 1.0)
        theta = wrap(e.theta + gain * wrap(cmd - e.theta))
        if params.axes_lag > 0 and math.isfinite(a_t):
            g = 1.0 - math.exp(-dt / params.axes_lag)
            a, b = e.a + g * (a_t - e.a), e.b + g * (b_t - e.b)
        else:
            a, b = a_t, b_t
        v = min(params.k_vcir * dist_t, params.v_max)
        step = min(v * dt, dist_t) if inside else 0.0
        ok = math.isfinite(a) and a > 0 and b > 0
        new = Ellipse(e.x + step * math.cos(theta), e.y + step * math.sin(theta), a, b, theta) if ok else None
        new_state = None if new is None else RegionState(new, v, alpha)
    why = can_hold(new.a, new.b, n_active, params.r_robot) if new is not None else can_hold(a_t, b_t, 0, 0.0)
    if new is None or why:
        return RegionStep(state, False, a_t, b_t, why or "infeasible")
    return RegionStep(new_state, step > 0, a_t, b_t, "" if inside else "barrier", {"area_factor": factor})


# --- agent failure (eq. 4.46, erratum 17) -----------------------------------------------------------------------------


@dataclass(frozen=True)
class FailureParams:
    """Erratum 17's detector: an agent slower than ``speed_frac`` v_max for ``hold`` s while the region's centre
    moves faster than ``centre_frac`` v_max and the agent is outside the region has failed."""

    v_max: float = 0.3
    speed_frac: float = 0.05
    centre_frac: float = 0.2
    hold: float = 2.0

    def __post_init__(self) -> None:
        check_fields(self, ("v_max", "speed_frac", "centre_frac", "hold"))


class FailureDetector:
    """Eq. 4.46's monitor fed one planner tick at a time: e^i = x_i - O_e changes only through O_e for a stopped
    agent. Failures latch (a failed agent leaves the formation and the count for good)."""

    def __init__(self, n: int, params: FailureParams = FailureParams()) -> None:
        self.params = params
        self.failed = np.zeros(n, bool)
        self._since = np.zeros(n)
        self._last: tuple[float, np.ndarray, np.ndarray] | None = None

    def update(self, t: float, positions: np.ndarray, region: Ellipse) -> np.ndarray:
        """Feed the positions (N, 2) and region at simulated time ``t``; returns the failed mask (N,)."""
        x = np.asarray(positions, dtype=float)
        last, self._last = self._last, (t, x.copy(), region.centre)
        if last is None or t <= last[0]:
            return self.failed.copy()
        dt = t - last[0]
        p = self.params
        speed = np.hypot(*(x - last[1]).T) / dt
        centre_speed = float(np.hypot(*(region.centre - last[2]))) / dt
        stuck = (speed < p.speed_frac * p.v_max) & ~region.contains(x) & (centre_speed > p.centre_frac * p.v_max)
        self._since = np.where(stuck, self._since + dt, 0.0)
        self.failed |= self._since >= p.hold - 1e-9
        return self.failed.copy()


def region_with_failures(region: Ellipse, r_c: float, n: int, n_failed: int) -> Ellipse:
    """The region's semi-axes after N' failures (eq. 4.47): the minor axis kept, the major one scaled so that the
    area is pi r_c^2 (N - N') / N; a circle stays a circle (radius r_c sqrt((N - N') / N))."""
    f = failure_area_factor(n, n_failed)
    if region.is_circle:
        r = r_c * math.sqrt(f)
        return replace(region, a=r, b=r)
    return replace(region, a=shrunk_major_axis(r_c, region.b, n, n_failed))
