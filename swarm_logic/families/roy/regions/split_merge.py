"""Chapter 6 (digest 001 §2.4): a leader-follower swarm in an elliptical region splits into sub-swarms where its
sensing shows several openings ahead, and sub-swarms merge where their next regions overlap.

The pieces a planner calls every period, all on arrays (positions (N, 2), agent ids (N,), sensed points (K, 2)):

- ``detect_openings``: the multi-path detector of §6.3 (eqs. 6.6-6.7, erratum 23). The sensed points become a
  profile in the leader's (or the region's) heading frame, smoothed by a moving median; each pronounced peak is an
  opening, its edges l1, l2 the nearest minima on either side, its free space b_fs = |l1 - l2|.
- ``split_sizes``, ``largest_remainder``, ``allocate``, ``leaders``: sub-region sizing (eqs. 6.8-6.12), agent
  selection (eq. 6.13) and leader promotion (eq. 6.14); ``split_swarm`` runs them on a scan.
- ``merge_groups``, ``merge_swarms``, ``merge_all``: the merge of §6.4 (eqs. 6.15-6.24, erratum 24) and Theorem 1's
  area check.
- ``lane_targets``: which target each lane's sub-swarm heads for in a multi-target map (erratum 25).
- ``ensure_leader``: a sub-swarm whose leader is missing gets the surviving member nearest its region's centre.

Every result is a frozen dataclass with ``as_dict`` (JSON values). Openings are listed left to right as seen along
the heading; a region's ``a`` lies along the passage, ``b`` across it (``shapes.Ellipse``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from scipy.ndimage import median_filter
from scipy.optimize import linear_sum_assignment
from scipy.signal import find_peaks
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from swarm_logic.families.roy.regions.shapes import Ellipse

Profile = Literal["depth", "range"]


@dataclass(frozen=True)
class SplitMergeParams:
    """Chapter 6's central-controller settings. The thresholds of the detector are ours (erratum 23: the thesis
    names none); ``None`` takes the default written next to each field.

    - ``r_s``: the agents' region of repulsion (Table 6.1's cases: 3.2 and 0.5 units; hardware 11.3 cm).
    - ``profile``: "depth" (forward depth against lateral offset, binned every ``bin_width``, default r_s / 2) or
      "range" (range against bearing from the frame's origin, binned every ``bin_angle`` rad, within
      ``half_fov`` of the heading).
    - ``min_forward``: depth mode, points at or behind this forward distance are not ahead and are dropped.
    - ``median_window``: the moving median's length in samples (odd).
    - ``prominence``, ``min_width``: a peak is an opening if it stands out by >= ``prominence`` (default 2 r_s) and
      is >= ``min_width`` (default 2 r_s) wide at half its prominence; ``min_split_gap`` (default 2 r_s): a split
      needs every opening's b_fs at least this wide.
    - ``empty_bins``: a bin with neither a hit nor a free beam end is unknown: it takes the value of the "nearest"
      sampled bin (the default; the lower on a tie) or is open to the ``horizon`` (default the deepest point plus
      twice ``prominence``: for callers without free ends, where a bin no beam hit is taken as open).
    - ``span``: the profile's extent: the "hits" (the default: free ends beyond the hits' extent are left out, so the
      clear beams along a closed corridor's sides make no false lane) or "all", the hits and the free ends ahead (a
      lane beside the hits, seen only through beams that ran clear through it, as when the swarm faces the wall
      between two lanes, is then part of the profile).
    - ``edges``: "minimum" (eq. 6.6: from the peak across its top, then down while the profile falls by more than
      ``edge_tolerance`` per sample, default r_s / 4) or "foot" (the first sample beyond the half-prominence
      point). Default "minimum" for the depth profile, "foot" for the range profile (a straight wall across the
      lanes is no minimum of range against bearing: it falls toward the heading).
    - ``semi_minor``: "literal" b^i = b_fs^i (eq. 6.9, target A8) or "half" b^i = b_fs^i / 2 (the region as wide as
      the gap; the semi-axis reading of erratum 11).
    - ``allocation``: "nearest" (eq. 6.13: regions in decreasing b_fs take their nearest unassigned agents) or
      "assignment" (minimum total distance with the SG^i as capacities).
    - ``merge_centre``: "area_weighted" (erratum 24) or "mean" of the merged regions' centres.
    """

    r_s: float
    profile: Profile = "depth"
    bin_width: float | None = None
    bin_angle: float = math.radians(2.0)
    half_fov: float = math.pi / 2
    min_forward: float = 0.0
    median_window: int = 5
    prominence: float | None = None
    min_width: float | None = None
    min_split_gap: float | None = None
    empty_bins: Literal["nearest", "horizon"] = "nearest"
    span: Literal["hits", "all"] = "hits"
    horizon: float | None = None
    edges: Literal["minimum", "foot"] | None = None
    edge_tolerance: float | None = None
    semi_minor: Literal["literal", "half"] = "literal"
    allocation: Literal["nearest", "assignment"] = "nearest"
    merge_centre: Literal["area_weighted", "mean"] = "area_weighted"

    def __post_init__(self) -> None:
        def bad(name: str, why: str) -> None:
            raise ValueError(f"SplitMergeParams.{name}: {why}, got {getattr(self, name)!r}")

        if not (math.isfinite(self.r_s) and self.r_s > 0):
            bad("r_s", "must be finite and > 0")
        for name in ("bin_width", "prominence", "min_width", "min_split_gap", "horizon", "edge_tolerance"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                bad(name, "must be finite and > 0 (or None for the default)")
        if not (math.isfinite(self.bin_angle) and 0 < self.bin_angle < math.pi):
            bad("bin_angle", "must be in (0, pi) rad")
        if not (0 < self.half_fov <= math.pi):
            bad("half_fov", "must be in (0, pi] rad")
        if not math.isfinite(self.min_forward):
            bad("min_forward", "must be finite")
        if self.median_window < 1 or self.median_window % 2 == 0:
            bad("median_window", "must be an odd number >= 1")
        choices = {
            "profile": ("depth", "range"),
            "semi_minor": ("literal", "half"),
            "empty_bins": ("nearest", "horizon"),
            "span": ("hits", "all"),
            "edges": (None, "minimum", "foot"),
            "allocation": ("nearest", "assignment"),
            "merge_centre": ("area_weighted", "mean"),
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                bad(name, f"must be one of {allowed}")

    @property
    def bin(self) -> float:
        return self.bin_width if self.bin_width is not None else self.r_s / 2

    @property
    def edge_rule(self) -> str:
        return self.edges if self.edges is not None else ("minimum" if self.profile == "depth" else "foot")

    @property
    def edge_drop(self) -> float:
        return self.edge_tolerance if self.edge_tolerance is not None else self.r_s / 4

    @property
    def peak_prominence(self) -> float:
        return self.prominence if self.prominence is not None else 2 * self.r_s

    @property
    def peak_width(self) -> float:
        return self.min_width if self.min_width is not None else 2 * self.r_s

    @property
    def split_gap(self) -> float:
        return self.min_split_gap if self.min_split_gap is not None else 2 * self.r_s


def _pt(p: np.ndarray) -> tuple[float, float]:
    return float(p[0]), float(p[1])


@dataclass(frozen=True)
class Opening:
    """One lane ahead: its edges l1 (left) and l2 (right) (eq. 6.6), the peak s^i, b_fs = |l1 - l2| (eq. 6.7), the
    peak's prominence and its width at half prominence (length units), and the passage direction ``theta`` (the
    normal of l1 -> l2 pointing away from the frame's origin)."""

    left: tuple[float, float]
    right: tuple[float, float]
    peak: tuple[float, float]
    b_fs: float
    prominence: float
    width: float
    theta: float

    @property
    def centre(self) -> np.ndarray:
        """O_e^i = (l1 + l2) / 2 (eq. 6.10)."""
        return (np.array(self.left) + np.array(self.right)) / 2

    def as_dict(self) -> dict[str, Any]:
        return {
            "left": list(self.left),
            "right": list(self.right),
            "peak": list(self.peak),
            "b_fs": self.b_fs,
            "prominence": self.prominence,
            "width": self.width,
            "theta": self.theta,
        }


@dataclass(frozen=True)
class OpeningScan:
    """What the detector saw: the openings (left to right), the prominent peaks too narrow to be one (``narrow``),
    whether the swarm should split and why, how many points it used and dropped (non-finite, not ahead), and the
    profile (sample positions, raw and smoothed values) for plots."""

    openings: tuple[Opening, ...]
    narrow: tuple[Opening, ...]
    split: bool
    reason: str
    used: int
    dropped_nonfinite: int
    dropped_behind: int
    profile_x: np.ndarray = field(repr=False, compare=False)
    profile_raw: np.ndarray = field(repr=False, compare=False)
    profile: np.ndarray = field(repr=False, compare=False)

    @property
    def b_fs(self) -> np.ndarray:
        return np.array([o.b_fs for o in self.openings])

    def as_dict(self) -> dict[str, Any]:
        return {
            "openings": [o.as_dict() for o in self.openings],
            "narrow": [o.as_dict() for o in self.narrow],
            "split": self.split,
            "reason": self.reason,
            "used": self.used,
            "dropped_nonfinite": self.dropped_nonfinite,
            "dropped_behind": self.dropped_behind,
        }


def _no_scan(reason: str, used: int, nonfinite: int, behind: int) -> OpeningScan:
    e = np.zeros(0)
    return OpeningScan((), (), False, reason, used, nonfinite, behind, e, e, e)


def _minimum(s: np.ndarray, p: int, step: int, tol: float) -> int | None:
    """The nearest minimum of ``s`` from peak ``p`` going ``step`` (-1 left, +1 right), eq. 6.6 (f' ~ 0 and f'' > 0
    where the fall ends): across the peak's top (within ``tol`` of it), then down while the profile falls by more
    than ``tol`` per sample (or over two samples, across a one-sample ledge). None if the top leads up to higher
    ground: ``p`` is a bump on a higher peak's flank, no peak of its own."""
    end = 0 if step < 0 else len(s) - 1
    i = p
    while i != end and abs(s[i + step] - s[p]) <= tol:
        i += step
    if i != end and s[i + step] > s[p] + tol:
        return None
    while i != end:
        if s[i + step] < s[i] - tol:
            i += step
        elif i + step != end and s[i + 2 * step] < s[i] - tol and s[i + step] <= s[i] + tol:
            i += 2 * step
        else:
            break
    return i


def _crossing(s: np.ndarray, p: int, step: int, level: float) -> float:
    """Where ``s`` first falls to ``level`` from peak ``p`` going ``step``, interpolated between samples."""
    i = p
    while s[i] > level and 0 <= i + step < len(s):
        i += step
    if s[i] > level or s[i - step] == s[i]:
        return float(i)
    return float(i - step) + step * (s[i - step] - level) / (s[i - step] - s[i])


def detect_openings(
    points: np.ndarray,
    origin: Sequence[float] | np.ndarray,
    heading: float,
    params: SplitMergeParams,
    free: np.ndarray | None = None,
) -> OpeningScan:
    """Multi-path detection (§6.3, eqs. 6.6-6.7, erratum 23) on sensed points (K, 2) in the frame at ``origin``
    (the leader's position or the region's centre) facing ``heading`` (rad).

    Depth profile: each point's lateral offset u (to the right of the heading) and forward depth f; the points
    ahead (f > ``min_forward``) are binned along u and each bin keeps its nearest point ahead (the clearance there).
    ``free`` (F, 2), optional, are the ends of the beams that had no echo (sensor position + its range along the
    beam): a bin with no hit keeps the farthest of its free ends (clear at least that far). A bin with neither takes
    its nearest sampled neighbour's value (unknown; or the ``horizon``, ``empty_bins``). Range profile: the same
    with bearing (clockwise from the heading, within ``half_fov``) and range. The profile is smoothed by a moving
    median of ``median_window`` samples; each peak (``find_peaks``) has its edges at the nearest minima either side
    (eq. 6.6, ``edges``), its prominence over the higher of the two, its width at half that prominence (for the
    range profile, an angle at the points' median range); the peaks of prominence >= 2 r_s and width >= 2 r_s are
    the openings (peaks of one plateau are one opening). l1, l2 are the sensed points of the edge bins nearest the
    peak (the bin's centre if it holds none). Split iff there are >= 2 openings and every b_fs >= 2 r_s. No point
    ahead: no opening.

    The points are obstacle hits (``sensing.sense`` gives them): from hits alone a lane shows only by what its beams
    hit beyond it; pass ``free`` (or ``empty_bins="horizon"``) for lanes whose beams return nothing."""
    pts = np.asarray(points, dtype=float)
    if pts.size and (pts.ndim != 2 or pts.shape[1] != 2):
        raise ValueError(f"detect_openings: points must be (K, 2), got shape {pts.shape}")
    pts = pts.reshape(-1, 2)
    o = np.asarray(origin, dtype=float)
    finite = np.isfinite(pts).all(axis=1)
    nonfinite = int((~finite).sum())
    if o.shape != (2,) or not (np.isfinite(o).all() and math.isfinite(heading)):
        return _no_scan(
            f"frame not finite (origin {o.tolist()}, heading {heading}): no opening", 0, nonfinite, int(finite.sum())
        )
    pts = pts[finite]
    h = np.array([math.cos(heading), math.sin(heading)])
    right = np.array([h[1], -h[0]])
    step = params.bin if params.profile == "depth" else params.bin_angle

    def frame(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Profile coordinate (lateral offset or clockwise bearing), value (depth or range), whether ahead."""
        d = q - o
        if params.profile == "depth":
            u, v = d @ right, d @ h
            return u, v, v > params.min_forward
        bearing = np.arctan2(d[:, 1], d[:, 0]) - heading
        u = -np.arctan2(np.sin(bearing), np.cos(bearing))  # clockwise: left to right
        v = np.hypot(d[:, 0], d[:, 1])
        return u, v, (np.abs(u) <= params.half_fov) & (v > 0)

    x, y, ahead = frame(pts)
    behind = int((~ahead).sum())
    x, y, pts = x[ahead], y[ahead], pts[ahead]
    if not len(x):
        return _no_scan("no points ahead: no opening", 0, nonfinite, behind)
    fu = fv = np.zeros(0)
    if free is not None and len(free):
        fu, fv, fa = frame(np.asarray(free, dtype=float).reshape(-1, 2))
        ok = fa & np.isfinite(fu) & np.isfinite(fv)
        fu, fv = fu[ok], fv[ok]
    # the profile spans the hits ("hits") or the hits and the free ends ahead ("all")
    lo = float(x.min()) if params.span == "hits" else float(min(x.min(), fu.min(initial=np.inf)))
    idx = np.floor((x - lo) / step).astype(int)
    fb = np.floor((fu - lo) / step).astype(int)
    nb = int(idx.max() if params.span == "hits" else max(idx.max(), fb.max(initial=0))) + 1
    raw = np.full(nb, np.inf)
    np.minimum.at(raw, idx, y)
    if len(fu):
        inside = (fb >= 0) & (fb < nb)
        reach = np.full(nb, -np.inf)
        np.maximum.at(reach, fb[inside], fv[inside])
        seen_free = ~np.isfinite(raw) & np.isfinite(reach)
        raw[seen_free] = reach[seen_free]  # no hit, but a beam ran this far clear
    empty = ~np.isfinite(raw)
    if params.empty_bins == "horizon":
        raw[empty] = params.horizon if params.horizon is not None else float(y.max()) + 2 * params.peak_prominence
    elif empty.any():
        have = np.flatnonzero(~empty)
        hole = np.flatnonzero(empty)
        right_k = np.searchsorted(have, hole)  # the sampled bins either side of each hole
        lo_b, hi_b = have[np.maximum(right_k - 1, 0)], have[np.minimum(right_k, len(have) - 1)]
        d_lo, d_hi = np.abs(hole - lo_b), np.abs(hi_b - hole)
        raw[hole] = np.where(d_lo < d_hi, raw[lo_b], np.where(d_hi < d_lo, raw[hi_b], np.minimum(raw[lo_b], raw[hi_b])))
    smooth = median_filter(raw, size=params.median_window, mode="nearest")
    xs = lo + (np.arange(nb) + 0.5) * step
    width_scale = step if params.profile == "depth" else step * float(np.median(y))  # samples -> length
    peaks, _ = find_peaks(smooth)  # every local maximum (a plateau by its middle)

    def world(u: float, v: float) -> np.ndarray:
        if params.profile == "depth":
            return o + u * right + v * h
        a = heading - u
        return o + v * np.array([math.cos(a), math.sin(a)])

    def edge_point(b: int, toward: int) -> np.ndarray:
        near = (idx == b) & (y <= smooth[b] + params.bin)
        if not near.any():
            return world(float(xs[b]), float(smooth[b]))
        k = np.flatnonzero(near)
        return pts[k[np.lexsort((y[k], -x[k] * toward))[0]]]  # nearest the peak, then the nearest ahead

    found: list[Opening] = []
    narrow: list[Opening] = []
    seen: set[tuple[int, int]] = set()
    for p in peaks.tolist():
        lo_i, hi_i = _minimum(smooth, p, -1, params.edge_drop), _minimum(smooth, p, +1, params.edge_drop)
        if lo_i is None or hi_i is None:
            continue
        prominence = float(smooth[p] - max(smooth[lo_i], smooth[hi_i]))
        if prominence < params.peak_prominence or (lo_i, hi_i) in seen:  # one plateau's peaks are one opening
            continue
        seen.add((lo_i, hi_i))
        level = float(smooth[p]) - prominence / 2
        left_x, right_x = _crossing(smooth, p, -1, level), _crossing(smooth, p, +1, level)
        if params.edge_rule == "foot":
            lo_i, hi_i = math.floor(left_x), math.ceil(right_x)
        l1, l2 = edge_point(lo_i, +1), edge_point(hi_i, -1)
        mouth = l2 - l1
        normal = np.array([mouth[1], -mouth[0]]) if np.any(mouth) else h.copy()  # l1 left, l2 right: ahead
        if normal @ ((l1 + l2) / 2 - o) < 0:
            normal = -normal
        op = Opening(
            _pt(l1),
            _pt(l2),
            _pt(world(float(xs[p]), float(smooth[p]))),
            float(np.hypot(*mouth)),
            prominence,
            float((right_x - left_x) * width_scale),
            math.atan2(normal[1], normal[0]),
        )
        (found if op.width >= params.peak_width else narrow).append(op)
    q = len(found)
    tight = [i for i, op in enumerate(found) if op.b_fs < params.split_gap]
    if q >= 2 and not tight:
        reason, split = f"{q} openings", True
    elif q >= 2:
        reason, split = (
            (
                f"{q} openings but opening {tight[0]} is narrower than {params.split_gap:g} "
                f"(b_fs = {found[tight[0]].b_fs:.3g}): no split"
            ),
            False,
        )
    else:
        reason, split = ("one opening" if q == 1 else "no opening"), False
        if narrow:
            reason += f" ({len(narrow)} more narrower than {params.peak_width:g}): no split"
    return OpeningScan(tuple(found), tuple(narrow), split, reason, len(x), nonfinite, behind, xs, raw, smooth)


def largest_remainder(weights: Sequence[float] | np.ndarray, n: int) -> np.ndarray:
    """``n`` split in proportion to ``weights`` in whole numbers summing to n (Hamilton's method: the floors, then
    one more each to the largest remainders, ties to the larger weight, then the lower index)."""
    w = np.asarray(weights, dtype=float)
    if n < 0 or not len(w) or np.any(~np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(
            f"largest_remainder: needs n >= 0 and finite weights >= 0 with a positive sum, got n = {n}, "
            f"weights = {w.tolist()}"
        )
    quota = w / w.sum() * n
    out = np.floor(quota).astype(int)
    rest = n - int(out.sum())
    order = np.lexsort((np.arange(len(w)), -w, -(quota - out)))
    out[order[:rest]] += 1
    return out


@dataclass(frozen=True)
class SplitSizes:
    """Eqs. 6.8-6.12 for free spaces b_fs: the areas A_e^i, semi-axes a^i (along the lane) and b^i, agent counts."""

    area: np.ndarray
    a: np.ndarray
    b: np.ndarray
    count: np.ndarray


def split_sizes(
    b_fs: Sequence[float] | np.ndarray, n: int, r_s: float, semi_minor: Literal["literal", "half"] = "literal"
) -> SplitSizes:
    """A_e = N pi r_s^2, A_e^i = b_fs^i / sum b_fs A_e (eq. 6.8), b^i = b_fs^i (or b_fs^i / 2, ``semi_minor``),
    a^i = A_e^i / (pi b^i) (eq. 6.9), SG^i = b_fs^i / sum b_fs N by largest remainder (eqs. 6.11-6.12)."""
    b = np.asarray(b_fs, dtype=float)
    if not len(b) or np.any(~np.isfinite(b)) or np.any(b <= 0):
        raise ValueError(f"split_sizes: b_fs must be finite and > 0, got {b.tolist()}")
    area = b / b.sum() * (n * math.pi * r_s * r_s)
    semi = b if semi_minor == "literal" else b / 2
    return SplitSizes(area, area / (math.pi * semi), semi, largest_remainder(b, n))


def allocate(
    positions: np.ndarray,
    centres: np.ndarray,
    counts: Sequence[int] | np.ndarray,
    priority: Sequence[float] | np.ndarray | None = None,
    method: Literal["nearest", "assignment"] = "nearest",
) -> np.ndarray:
    """Which region each agent joins (N,), region j taking ``counts[j]`` agents (sum = N). "nearest" (eq. 6.13):
    the regions in decreasing ``priority`` (b_fs; ties to the lower index) each take their nearest unassigned agents
    (ties to the lower row). "assignment": the minimum total distance to the centres with the counts as capacities
    (an assignment on the regions' columns repeated ``counts`` times)."""
    pos = np.asarray(positions, dtype=float).reshape(-1, 2)
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    cnt = np.asarray(counts, dtype=int)
    if len(cnt) != len(c) or int(cnt.sum()) != len(pos) or np.any(cnt < 0):
        raise ValueError(
            f"allocate: counts {cnt.tolist()} must be >= 0, one per centre ({len(c)}) and sum to the {len(pos)} agents"
        )
    dist = np.hypot(pos[:, None, 0] - c[None, :, 0], pos[:, None, 1] - c[None, :, 1])
    label = np.full(len(pos), -1)
    if method == "assignment":
        cols = np.repeat(np.arange(len(c)), cnt)
        rows, col = linear_sum_assignment(dist[:, cols])
        label[rows] = cols[col]
        return label
    pr = np.zeros(len(c)) if priority is None else np.asarray(priority, dtype=float)
    for j in np.lexsort((np.arange(len(c)), -pr)).tolist():
        free = np.flatnonzero(label < 0)
        label[free[np.argsort(dist[free, j], kind="stable")[: cnt[j]]]] = j
    return label


def leaders(positions: np.ndarray, label: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Eq. 6.14: per region the row of its member nearest its centre (ties to the lower row; -1 if it has none)."""
    pos = np.asarray(positions, dtype=float).reshape(-1, 2)
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    out = np.full(len(c), -1)
    for j in range(len(c)):
        rows = np.flatnonzero(label == j)
        if len(rows):
            out[j] = rows[np.argmin(np.hypot(*(pos[rows] - c[j]).T))]
    return out


@dataclass(frozen=True)
class SubSwarm:
    """A (sub-)swarm: its id, member agent ids, leader id (-1: none survives), region and target (an index into
    the scenario's targets, or None)."""

    id: int
    members: tuple[int, ...]
    leader: int
    region: Ellipse
    target: int | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "members": list(self.members),
            "leader": self.leader,
            "region": self.region.as_dict(),
            "target": self.target,
        }


@dataclass(frozen=True)
class Promotion:
    """A leader replaced because it was missing (dead, or no longer reported): ``promoted`` is -1 when no member
    survives."""

    swarm: int
    dead: int
    promoted: int
    reason: str

    def as_dict(self) -> dict[str, Any]:
        return {"swarm": self.swarm, "dead": self.dead, "promoted": self.promoted, "reason": self.reason}


def _rows(ids: np.ndarray | Sequence[int] | None, positions: np.ndarray) -> tuple[np.ndarray, dict[int, int]]:
    pos = np.asarray(positions, dtype=float).reshape(-1, 2)
    idv = np.arange(len(pos)) if ids is None else np.asarray(ids, dtype=int)
    if len(idv) != len(pos):
        raise ValueError(f"ids: {len(idv)} ids for {len(pos)} positions")
    ok = np.isfinite(pos).all(axis=1)
    return pos, dict(zip(idv[ok].tolist(), np.nonzero(ok)[0].tolist(), strict=True))


def ensure_leader(
    swarm: SubSwarm, positions: np.ndarray, ids: np.ndarray | Sequence[int] | None = None
) -> tuple[SubSwarm, Promotion | None]:
    """The swarm without its missing members (ids absent from ``ids`` or with non-finite positions) and with a
    live leader: if its leader is missing, the surviving member nearest its region's centre (eq. 6.14's rule) is
    promoted and the promotion returned for the caller to log."""
    pos, row = _rows(ids, positions)
    alive = tuple(filter(row.__contains__, swarm.members))
    if swarm.leader in row and swarm.leader in alive:
        return (swarm if alive == swarm.members else replace(swarm, members=alive)), None
    if not alive:
        return replace(swarm, members=(), leader=-1), Promotion(swarm.id, swarm.leader, -1, "no member survives")
    r = np.array([row[m] for m in alive])
    new = alive[int(np.argmin(np.hypot(*(pos[r] - swarm.region.centre).T)))]
    why = f"leader {swarm.leader} missing: member {new}, nearest the region's centre, promoted"
    return replace(swarm, members=alive, leader=new), Promotion(swarm.id, swarm.leader, new, why)


def lane_targets(
    origin: Sequence[float] | np.ndarray, centres: np.ndarray, targets: np.ndarray, mapping: Sequence[int] | None = None
) -> tuple[int, ...]:
    """Each lane's target index (erratum 25): the scenario's ``mapping`` (lane k, counted left to right, -> target
    index) when it gives one, else the target whose bearing from ``origin`` is nearest the lane's (origin -> its
    centre)."""
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    t = np.asarray(targets, dtype=float).reshape(-1, 2)
    if not len(t):
        raise ValueError("lane_targets: targets is empty")
    if mapping is not None:
        m = list(mapping)
        if len(m) < len(c) or any(not 0 <= k < len(t) for k in m[: len(c)]):
            raise ValueError(
                f"lane_targets: mapping {m} must name a target index in 0..{len(t) - 1} for each of the {len(c)} lanes"
            )
        return tuple(int(k) for k in m[: len(c)])
    o = np.asarray(origin, dtype=float)
    lane = np.arctan2(c[:, 1] - o[1], c[:, 0] - o[0])
    tb = np.arctan2(t[:, 1] - o[1], t[:, 0] - o[0])
    diff = np.abs(np.angle(np.exp(1j * (lane[:, None] - tb[None, :]))))
    return tuple(int(k) for k in np.argmin(diff, axis=1))


@dataclass(frozen=True)
class SplitDecision:
    """A split's outcome: whether the swarm split and why, the resulting swarms (the parent alone when it does not
    split), the leaders promoted because one was missing, and the members left out as missing."""

    split: bool
    reason: str
    swarms: tuple[SubSwarm, ...]
    promotions: tuple[Promotion, ...] = ()
    missing: tuple[int, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {
            "split": self.split,
            "reason": self.reason,
            "swarms": [s.as_dict() for s in self.swarms],
            "promotions": [p.as_dict() for p in self.promotions],
            "missing": list(self.missing),
        }


def split_swarm(
    scan: OpeningScan,
    swarm: SubSwarm,
    positions: np.ndarray,
    params: SplitMergeParams,
    ids: np.ndarray | Sequence[int] | None = None,
    first_id: int | None = None,
    targets: np.ndarray | None = None,
    lane_map: Sequence[int] | None = None,
) -> SplitDecision:
    """The central controller's split (§6.3) of ``swarm`` on a scan: one sub-region per opening (eqs. 6.8-6.10,
    ``split_sizes``, the major axis along the opening's passage), its SG^i surviving members (``allocate``), its
    leader (eq. 6.14) and, with ``targets``, its target (``lane_targets``). Missing members take no part (a missing
    parent leader is replaced first, ``ensure_leader``). An opening that would get no agent is dropped and the
    sizes recomputed; fewer than two openings left, or no split in the scan: no split. Sub-swarm ids count up from
    ``first_id`` (default the parent's id + 1: the caller passes a fresh one)."""
    parent, promo = ensure_leader(swarm, positions, ids)
    promotions = (promo,) if promo else ()
    missing = tuple(m for m in swarm.members if m not in parent.members)

    def stay(reason: str) -> SplitDecision:
        return SplitDecision(False, reason, (parent,), promotions, missing)

    if not scan.split:
        return stay(scan.reason)
    pos, row = _rows(ids, positions)
    members = np.array(parent.members, dtype=int)
    if len(members) < 2:
        return stay(f"{len(members)} surviving agent(s) cannot split: no split")
    openings = list(scan.openings)
    while True:
        sizes = split_sizes([op.b_fs for op in openings], len(members), params.r_s, params.semi_minor)
        if np.all(sizes.count > 0) or len(openings) < 2:
            break
        openings = [op for op, k in zip(openings, sizes.count, strict=True) if k > 0]
    if len(openings) < 2 or np.any(sizes.count == 0):
        return stay(f"{len(members)} surviving agents cannot fill {len(scan.openings)} openings: no split")
    centres = np.array([op.centre for op in openings])
    rows = np.array([row[m] for m in members.tolist()])
    label = allocate(pos[rows], centres, sizes.count, [op.b_fs for op in openings], params.allocation)
    lead = leaders(pos[rows], label, centres)
    tg: tuple[int | None, ...] = (None,) * len(openings)
    if targets is not None:
        tg = lane_targets(parent.region.centre, centres, targets, lane_map)
    base = parent.id + 1 if first_id is None else first_id
    subs = tuple(
        SubSwarm(
            base + j,
            tuple(int(m) for m in members[label == j]),
            int(members[lead[j]]),
            Ellipse(float(centres[j, 0]), float(centres[j, 1]), float(sizes.a[j]), float(sizes.b[j]), op.theta),
            tg[j],
        )
        for j, op in enumerate(openings)
    )
    return SplitDecision(True, f"split into {len(subs)} at {len(openings)} openings", subs, promotions, missing)


def merge_groups(regions: Sequence[Ellipse]) -> tuple[tuple[int, ...], ...]:
    """The sets (of indices into ``regions``, two or more each) whose regions overlap, directly or through each
    other: connected components of the pairwise ``Ellipse.intersects`` (§6.4's trigger)."""
    n = len(regions)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if regions[i].intersects(regions[j])]
    if not pairs:
        return ()
    i, j = np.array(pairs).T
    graph = coo_matrix((np.ones(len(pairs)), (i, j)), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    groups = [tuple(np.flatnonzero(comp == c).tolist()) for c in np.unique(comp)]
    return tuple(sorted(g for g in groups if len(g) >= 2))


@dataclass(frozen=True)
class MergeDecision:
    """A merge's outcome: the merged swarm, the ids it merged, its area A = sum A_e^i (eq. 6.23) against Theorem 1's
    pi r_s^2 sum Q^i (eq. 6.24) over the surviving members, and the leaders promoted because one was missing."""

    swarm: SubSwarm
    merged: tuple[int, ...]
    area: float
    required_area: float
    promotions: tuple[Promotion, ...] = ()

    @property
    def theorem1(self) -> bool:
        return self.area >= self.required_area * (1 - 1e-12)

    def as_dict(self) -> dict[str, Any]:
        return {
            "swarm": self.swarm.as_dict(),
            "merged": list(self.merged),
            "area": self.area,
            "required_area": self.required_area,
            "theorem1": self.theorem1,
            "promotions": [p.as_dict() for p in self.promotions],
        }


def merge_swarms(
    swarms: Sequence[SubSwarm],
    proposals: Sequence[Ellipse],
    positions: np.ndarray,
    params: SplitMergeParams,
    ids: np.ndarray | Sequence[int] | None = None,
    target: Sequence[float] | np.ndarray | None = None,
    direction: float | None = None,
    new_id: int | None = None,
) -> MergeDecision:
    """Merge ``swarms`` whose next regions are ``proposals`` (§6.4): b = max b^i (eq. 6.20), a = sum A_e^i / (pi b)
    (eq. 6.21) with A_e^i each proposal's area; the centre the area-weighted (or plain, ``merge_centre``) mean of
    the proposals' centres and the a axis toward ``target``, else along ``direction`` (rad), else the proposals'
    area-weighted mean axis (erratum 24); the leader the surviving member nearest the merged centre. The merged
    swarm takes ``new_id`` (default the lowest merged id) and the target of its largest part."""
    if len(swarms) != len(proposals) or not swarms:
        raise ValueError(f"merge_swarms: {len(swarms)} swarms for {len(proposals)} proposals")
    pos, row = _rows(ids, positions)
    area = np.array([p.area for p in proposals])
    b = max(p.b for p in proposals)
    total = float(area.sum())
    w = area / total if params.merge_centre == "area_weighted" else np.full(len(area), 1 / len(area))
    centre = w @ np.array([p.centre for p in proposals])
    if target is not None and np.isfinite(target).all() and np.any(np.asarray(target, dtype=float) != centre):
        d = np.asarray(target, dtype=float) - centre
        theta = math.atan2(d[1], d[0])
    elif direction is not None:
        theta = float(direction)
    else:
        th = np.array([p.theta for p in proposals])
        theta = 0.5 * math.atan2(float(area @ np.sin(2 * th)), float(area @ np.cos(2 * th)))
    members = tuple(m for s in swarms for m in s.members if m in row)
    promotions: list[Promotion] = []
    leader = -1
    if members:
        r = np.array([row[m] for m in members])
        leader = members[int(np.argmin(np.hypot(*(pos[r] - centre).T)))]
    for s in swarms:
        if s.leader not in row:
            promotions.append(
                Promotion(
                    s.id,
                    s.leader,
                    leader,
                    f"leader {s.leader} missing at the merge: member {leader}, nearest the merged centre, leads",
                )
            )
    sizes = [sum(m in row for m in s.members) for s in swarms]
    largest = min(range(len(swarms)), key=lambda k: (-sizes[k], swarms[k].id))
    merged = SubSwarm(
        min(s.id for s in swarms) if new_id is None else new_id,
        members,
        leader,
        Ellipse(float(centre[0]), float(centre[1]), total / (math.pi * b), b, theta),
        swarms[largest].target,
    )
    return MergeDecision(
        merged, tuple(s.id for s in swarms), total, math.pi * params.r_s**2 * len(members), tuple(promotions)
    )


def merge_all(
    swarms: Sequence[SubSwarm],
    proposals: Sequence[Ellipse],
    positions: np.ndarray,
    params: SplitMergeParams,
    ids: np.ndarray | Sequence[int] | None = None,
    target: Sequence[float] | np.ndarray | None = None,
) -> tuple[tuple[SubSwarm, ...], tuple[MergeDecision, ...]]:
    """One merge check of the central controller: the swarms whose proposed next regions overlap (``merge_groups``)
    merge (``merge_swarms``, toward ``target`` or, without one, along their mean axis); the others take their
    proposals as their regions. Returns the swarms after the check (merged ones in place of their first part) and
    the merges."""
    if len(swarms) != len(proposals):
        raise ValueError(f"merge_all: {len(swarms)} swarms for {len(proposals)} proposals")
    groups = merge_groups(proposals)
    decisions = {
        g[0]: merge_swarms([swarms[k] for k in g], [proposals[k] for k in g], positions, params, ids, target)
        for g in groups
    }
    merged = {k for g in groups for k in g[1:]}
    out = tuple(
        decisions[k].swarm if k in decisions else replace(s, region=proposals[k])
        for k, s in enumerate(swarms)
        if k not in merged
    )
    return out, tuple(decisions[g[0]] for g in groups)
