"""Chapter 5's circles in Φ (digest 001 §2.3.4-2.3.5): N circles of radius r_s packed in the polygonal region, one
assigned to each agent, and the barrier that holds the next region until every agent is in its circle.

- Packing (eq. 5.9, erratum 20). The thesis keeps a lattice circle S_q iff it lies in Φ by a Minkowski difference
  whose printed condition is garbled; we keep the centres inside Φ eroded by r_s (shapely ``buffer(-r_s)``). The
  lattice is hexagonal, u1 = (2 r_s, 0), u2 = (r_s, √3 r_s), searched over a bounded grid of rotations in [0°, 60°)
  and translations in its basis cell. Its "trim-and-pack" fallback (when the lattice gives fewer than N) cannot be
  reproduced as printed; ours: the lattice centres plus seeded random points in the eroded Φ, relaxed by pairwise
  repulsion and projection back into the eroded Φ until no two centres are closer than 2 r_s; if that fails, r_s
  shrinks by 5 % per attempt.
- Assignment (eq. 5.10, erratum 21). The thesis' argmax gives each agent its *farthest* circle and may give two
  agents one circle (``"literal"``); ours is the Hungarian min-total-distance assignment (``"hungarian"``, default),
  or the min-max-distance one (``"bottleneck"``).
- Barrier (§2.3.5 [T]: "the next iteration begins when all of the agents have arrived"): every agent within 0.1 r_s
  of its circle's centre, or a timeout in the caller's clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
from scipy.optimize import linear_sum_assignment
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from swarm_logic.families.roy.regions.efa import largest_polygon
from swarm_logic.families.roy.regions.records import require

ASSIGNMENTS = ("hungarian", "bottleneck", "literal")
SELECTIONS = ("central", "all")
METHODS = ("lattice", "relaxed", "shrunk", "failed")
EROSION_QUAD_SEGS = 16  # arcs of the eroded boundary: chords within 0.0012 r_s of the true arc
EROSION_MARGIN = 2e-3  # erode by r_s (1 + margin), so those chords stay r_s clear of Φ's boundary
RELAX_INFLATION = 0.2  # the relaxation's spacing starts 20 % above 2 r_s and decays to it


@dataclass(frozen=True)
class PackingParams:
    """The packing: ``rotations`` and ``translations`` (per basis vector) of the lattice search (rotations x
    translations² lattices tried; the defaults, 12 x 6², step 5° and a sixth of the cell), ``select`` ("central":
    of more than N lattice circles keep the N nearest Φ's centroid; "all": keep every one, the assignment picks),
    ``relax`` (the fallback on), ``relax_iterations`` per try, ``relax_restarts`` tries per radius (at most
    ``relax_budget`` // N of them, at least one: a big swarm gets fewer, which bounds the time), ``shrink`` (5 %)
    and ``max_shrinks`` (then "failed")."""

    rotations: int = 12
    translations: int = 6
    select: str = "central"
    relax: bool = True
    relax_iterations: int = 400
    relax_restarts: int = 5
    relax_budget: int = 400
    shrink: float = 0.05
    max_shrinks: int = 20

    def __post_init__(self) -> None:
        for name in ("rotations", "translations", "relax_iterations", "relax_restarts", "relax_budget"):
            v = getattr(self, name)
            require(isinstance(v, int) and v >= 1, name, "must be an int >= 1", v)
        require(self.select in SELECTIONS, "select", f"expected one of {', '.join(SELECTIONS)}", self.select)
        require(0.0 < self.shrink < 1.0, "shrink", "must lie in (0, 1)", self.shrink)
        require(
            isinstance(self.max_shrinks, int) and self.max_shrinks >= 0,
            "max_shrinks",
            "must be an int >= 0",
            self.max_shrinks,
        )


@dataclass(frozen=True)
class Packing:
    """Circles in Φ: ``centres`` (M, 2), M >= N unless ``method`` is "failed"; ``radius`` used (r_s, or less when
    "shrunk"); ``method`` "lattice" (the lattice at r_s gave N), "relaxed" (the fallback at r_s), "shrunk" (either at
    a smaller radius), "failed" (no radius down to the last shrink fits N, or no region: ``centres`` holds the most
    any lattice fitted, at its radius, maybe none); ``lattice_count`` the lattice's own count at r_s (Fig. 5.7's 6
    against 8); ``rotation``/``translation`` of the lattice kept; ``shrinks`` attempts; ``region_area`` A_Φ."""

    centres: np.ndarray
    radius: float
    method: str
    lattice_count: int
    rotation: float
    translation: np.ndarray
    shrinks: int
    region_area: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "centres": self.centres.tolist(),
            "radius": self.radius,
            "method": self.method,
            "lattice_count": self.lattice_count,
            "rotation": self.rotation,
            "translation": self.translation.tolist(),
            "shrinks": self.shrinks,
            "region_area": self.region_area,
        }


def erode(region: Polygon, r: float) -> shapely.Geometry:
    """The centres' domain: Φ eroded by r (plus ``EROSION_MARGIN``), prepared for point queries; may be empty."""
    e = region.buffer(-r * (1.0 + EROSION_MARGIN), quad_segs=EROSION_QUAD_SEGS)
    shapely.prepare(e)
    return e


def hex_basis(r: float, rotation: float) -> np.ndarray:
    """The rows u1 = (2 r, 0), u2 = (r, √3 r), rotated by ``rotation`` (rad)."""
    c, s = math.cos(rotation), math.sin(rotation)
    rot = np.array([[c, s], [-s, c]])
    return np.array([[2.0 * r, 0.0], [r, math.sqrt(3.0) * r]]) @ rot


def lattice_search(domain: shapely.Geometry, r: float, params: PackingParams) -> tuple[np.ndarray, float, np.ndarray]:
    """The translational lattice packing (eq. 5.9): of the rotations x translations² hexagonal lattices, the one with
    most centres in ``domain`` (ties: the first in grid order); returns its centres, rotation and translation. All
    candidate points of all lattices are tested in one vectorised containment query."""
    if domain.is_empty:
        return np.zeros((0, 2)), 0.0, np.zeros(2)
    x0, y0, x1, y1 = domain.bounds
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])
    frac = np.arange(params.translations) / params.translations
    fa, fb = (g.ravel() for g in np.meshgrid(frac, frac, indexing="ij"))
    blocks, owners, combos = [], [], []
    for k in range(params.rotations):
        theta = (math.pi / 3.0) * k / params.rotations
        basis = hex_basis(r, theta)
        ij = corners @ np.linalg.inv(basis)  # lattice coordinates of the bounding box corners
        lo, hi = np.floor(ij.min(axis=0)) - 1, np.ceil(ij.max(axis=0)) + 1
        gi, gj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
        base = np.stack([gi.ravel(), gj.ravel()], axis=1) @ basis  # (P, 2)
        shifts = np.stack([fa, fb], axis=1) @ basis  # (T², 2)
        pts = base[None, :, :] + shifts[:, None, :]  # (T², P, 2)
        inside_box = (pts[..., 0] >= x0) & (pts[..., 0] <= x1) & (pts[..., 1] >= y0) & (pts[..., 1] <= y1)
        for t in range(len(shifts)):
            blocks.append(pts[t][inside_box[t]])
            owners.append(np.full(int(inside_box[t].sum()), len(combos)))
            combos.append((theta, shifts[t]))
    allpts = np.concatenate(blocks)
    owner = np.concatenate(owners)
    inside = shapely.contains_xy(domain, allpts[:, 0], allpts[:, 1])
    counts = np.bincount(owner[inside], minlength=len(combos))
    best = int(np.argmax(counts))
    theta, shift = combos[best]
    return allpts[inside & (owner == best)], float(theta), shift


def project_inside(domain: shapely.Geometry, points: np.ndarray) -> np.ndarray:
    """``points`` with those outside ``domain`` moved to the nearest point of its boundary."""
    out = ~shapely.contains_xy(domain, points[:, 0], points[:, 1])
    if out.any():
        ring = domain.boundary
        q = shapely.points(points[out])
        points = points.copy()
        points[out] = shapely.get_coordinates(shapely.line_interpolate_point(ring, shapely.line_locate_point(ring, q)))
    return points


def sample_inside(domain: shapely.Geometry, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` seeded uniform points in ``domain`` by rejection from its bounding box (a bounded number of rounds; any
    still missing are the domain's representative point)."""
    x0, y0, x1, y1 = domain.bounds
    frac = max(domain.area / max((x1 - x0) * (y1 - y0), 1e-300), 1e-3)
    got: list[np.ndarray] = []
    have = 0
    for _ in range(20):
        if have >= n:
            break
        m = math.ceil((n - have) / frac * 1.3) + 8
        cand = np.stack([rng.uniform(x0, x1, m), rng.uniform(y0, y1, m)], axis=1)
        cand = cand[shapely.contains_xy(domain, cand[:, 0], cand[:, 1])][: n - have]
        got.append(cand)
        have += len(cand)
    pts = np.concatenate(got) if got else np.zeros((0, 2))
    if len(pts) < n:
        rep = np.asarray(domain.representative_point().coords[0])
        pts = np.vstack([pts, np.repeat(rep[None, :], n - len(pts), axis=0)])
    return pts


def min_spacing(centres: np.ndarray) -> float:
    """The smallest distance between two centres (inf for fewer than 2)."""
    if len(centres) < 2:
        return math.inf
    d, _ = cKDTree(centres).query(centres, k=2)
    return float(d[:, 1].min())


def relax(
    domain: shapely.Geometry, start: np.ndarray, r: float, iterations: int, rng: np.random.Generator
) -> tuple[np.ndarray, int]:
    """The fallback (erratum 20): ``start`` (N, 2) pushed apart pairwise (each pair closer than the spacing moves
    apart by half its overlap each, coincident pairs along a seeded random direction) and projected back into
    ``domain``, until no pair is closer than 2 r or ``iterations`` run out; returns the centres and how many pairs
    are still closer than 2 r (0: done). The spacing aimed at starts ``RELAX_INFLATION`` above 2 r and decays to it,
    which shakes the centres out of jammed arrangements."""
    p = project_inside(domain, start)
    for it in range(iterations):
        want = 2.0 * r * (1.0 + 1e-9 + RELAX_INFLATION * (1.0 - it / iterations) ** 2)
        pairs = cKDTree(p).query_pairs(want, output_type="ndarray")
        d = p[pairs[:, 0]] - p[pairs[:, 1]]
        dist = np.hypot(d[:, 0], d[:, 1])
        if not (dist < 2.0 * r).any():
            return p, 0
        zero = dist < 1e-12
        if zero.any():
            a = rng.uniform(0.0, 2.0 * math.pi, int(zero.sum()))
            d[zero] = np.stack([np.cos(a), np.sin(a)], axis=1)
            dist[zero] = 1.0
        push = d * ((want - np.where(zero, 0.0, dist)) / (2.0 * dist))[:, None]
        move = np.zeros_like(p)
        np.add.at(move, pairs[:, 0], push)
        np.add.at(move, pairs[:, 1], -push)
        p = project_inside(domain, p + move)
    return p, len(cKDTree(p).query_pairs(2.0 * r * (1.0 - 1e-12), output_type="ndarray"))


def pick_central(centres: np.ndarray, domain: shapely.Geometry, n: int) -> np.ndarray:
    """The ``n`` centres nearest the domain's centroid (stable order)."""
    if len(centres) <= n:
        return centres
    c = np.asarray(domain.centroid.coords[0])
    order = np.argsort(np.hypot(*(centres - c).T), kind="stable")[:n]
    return centres[np.sort(order)]


def pack_circles(
    region: Polygon,
    n: int,
    r_s: float,
    params: PackingParams = PackingParams(),
    rng: np.random.Generator | int = 0,
) -> Packing:
    """At least ``n`` circles of radius ``r_s`` (or the largest shrunk radius that fits) in ``region`` Φ: the lattice
    search, then (when it gives fewer than n) the seeded relaxation, then 5 % shrinks. ``rng`` a Generator or a seed
    (same seed, same centres). A region that is not one valid polygon is made one (its largest valid piece). Never
    raises on a bad region: "failed" with what fitted."""
    require(math.isfinite(r_s) and r_s > 0.0, "r_s", "must be finite and > 0", r_s)
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    if isinstance(region, shapely.Geometry) and not region.is_empty and not isinstance(region, Polygon):
        region = largest_polygon(region)[0]  # a MultiPolygon or a collection: its largest polygon
    elif isinstance(region, Polygon) and not region.is_empty and not region.is_valid:
        region = largest_polygon(region)[0]  # e.g. a self-crossing ring: made valid, largest piece
    valid = isinstance(region, Polygon) and not region.is_empty and region.area > 0.0
    area = float(region.area) if valid else 0.0
    empty = np.zeros((0, 2))
    if n <= 0 or not valid:
        return Packing(empty, r_s, "lattice" if n <= 0 and valid else "failed", 0, 0.0, np.zeros(2), 0, area)
    lattice_count = -1
    last = (empty, r_s, 0.0, np.zeros(2))
    for k in range(params.max_shrinks + 1):
        r = r_s * (1.0 - params.shrink) ** k
        if n * math.pi * r * r > area and k < params.max_shrinks:  # n circles' area exceeds Φ's: skip this radius
            if lattice_count < 0:
                lattice_count = len(lattice_search(erode(region, r), r, params)[0])
            continue
        domain = erode(region, r)
        centres, theta, shift = lattice_search(domain, r, params)
        if lattice_count < 0:
            lattice_count = len(centres)
        if len(centres) > len(last[0]):
            last = (centres, r, theta, shift)
        if len(centres) >= n:
            chosen = pick_central(centres, domain, n) if params.select == "central" else centres
            return Packing(chosen, r, "lattice" if k == 0 else "shrunk", lattice_count, theta, shift, k, area)
        if params.relax and not domain.is_empty:
            for _ in range(min(params.relax_restarts, max(1, params.relax_budget // n))):
                start = np.vstack([centres, sample_inside(domain, n - len(centres), gen)])
                relaxed, overlapping = relax(domain, start, r, params.relax_iterations, gen)
                if overlapping == 0:
                    return Packing(relaxed, r, "relaxed" if k == 0 else "shrunk", lattice_count, theta, shift, k, area)
    centres, r, theta, shift = last
    return Packing(centres, r, "failed", max(lattice_count, 0), theta, shift, params.max_shrinks, area)


@dataclass(frozen=True)
class Assignment:
    """Which circle each agent goes to: ``index`` (N,) into the centres (-1: none left for it), ``targets`` (N, 2)
    the assigned centres (NaN rows for -1), ``distances`` (N,), ``method``, ``one_to_one`` (no circle twice)."""

    index: np.ndarray
    targets: np.ndarray
    distances: np.ndarray
    method: str
    one_to_one: bool

    def as_dict(self) -> dict[str, Any]:
        return {
            "index": self.index.tolist(),
            "distances": [None if not math.isfinite(d) else float(d) for d in self.distances],
            "method": self.method,
            "one_to_one": self.one_to_one,
        }


def bottleneck_assignment(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows matched to distinct columns minimising the largest cost (bisection on the sorted costs with a maximum
    bipartite matching), ties broken by the least total cost; rows <= columns."""
    values = np.unique(cost)
    lo, hi = 0, len(values) - 1
    while lo < hi:
        mid = (lo + hi) // 2
        graph = csr_matrix(cost <= values[mid])
        if (maximum_bipartite_matching(graph, perm_type="column") >= 0).all():
            hi = mid
        else:
            lo = mid + 1
    capped = np.where(cost <= values[lo], cost, cost.max() * len(cost) + 1.0)
    return linear_sum_assignment(capped)


def assign_circles(positions: np.ndarray, centres: np.ndarray, method: str = "hungarian") -> Assignment:
    """Eq. 5.10 and erratum 21: ``"hungarian"`` (default) the one-to-one assignment of least total distance
    (``scipy.optimize.linear_sum_assignment``); ``"bottleneck"`` the one-to-one assignment of least largest distance;
    ``"literal"`` the thesis' argmax, each agent its *farthest* circle, which may send two agents to one circle (kept
    as printed: ``one_to_one`` says whether it happened). With fewer circles than agents, the one-to-one methods
    leave the rest at -1. Agents with non-finite positions get -1."""
    require(method in ASSIGNMENTS, "method", f"expected one of {', '.join(ASSIGNMENTS)}", method)
    x = np.asarray(positions, dtype=float).reshape(-1, 2)
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    n = len(x)
    index = np.full(n, -1, dtype=int)
    ok = np.flatnonzero(np.isfinite(x).all(axis=1))
    if len(ok) and len(c):
        d = np.hypot(x[ok, None, 0] - c[None, :, 0], x[ok, None, 1] - c[None, :, 1])
        if method == "literal":
            index[ok] = np.argmax(d, axis=1)
        else:
            transpose = len(ok) > len(c)  # more agents than circles: match the circles to agents
            cost = d.T if transpose else d
            rows, cols = bottleneck_assignment(cost) if method == "bottleneck" else linear_sum_assignment(cost)
            agents, circles = (cols, rows) if transpose else (rows, cols)
            index[ok[agents]] = circles
    targets = np.full((n, 2), np.nan)
    has = index >= 0
    targets[has] = c[index[has]]
    distances = np.hypot(*(x - targets).T)
    used = index[has]
    return Assignment(index, targets, distances, method, len(np.unique(used)) == len(used))


@dataclass(frozen=True)
class BarrierParams:
    """The iteration barrier (§2.3.5 [R]): arrived within ``tolerance`` x r_s of the circle's centre (0.1), released
    anyway after ``timeout`` (in the caller's clock units, e.g. simulated seconds)."""

    tolerance: float = 0.1
    timeout: float = 30.0

    def __post_init__(self) -> None:
        require(
            math.isfinite(self.tolerance) and self.tolerance > 0.0,
            "tolerance",
            "must be finite and > 0",
            self.tolerance,
        )
        require(self.timeout > 0.0, "timeout", "must be > 0", self.timeout)


@dataclass(frozen=True)
class BarrierStatus:
    """``released`` (next region may be made), ``all_arrived``, ``timed_out``, ``arrived`` count, ``waiting`` the
    indices of agents not yet in their circles, ``unassigned`` agents with no circle (not waited for)."""

    released: bool
    all_arrived: bool
    timed_out: bool
    arrived: int
    waiting: np.ndarray
    unassigned: int

    def as_dict(self) -> dict[str, Any]:
        return {
            "released": self.released,
            "all_arrived": self.all_arrived,
            "timed_out": self.timed_out,
            "arrived": self.arrived,
            "waiting": self.waiting.tolist(),
            "unassigned": self.unassigned,
        }


def barrier(
    positions: np.ndarray,
    targets: np.ndarray,
    r_s: float,
    since: float,
    now: float,
    params: BarrierParams = BarrierParams(),
) -> BarrierStatus:
    """Whether the next iteration may begin: every agent with a circle (``targets`` (N, 2) row finite) within
    ``tolerance`` r_s of it, or ``now - since >= timeout`` (the caller's clock). An agent whose position is not
    finite never arrives."""
    x = np.asarray(positions, dtype=float).reshape(-1, 2)
    t = np.asarray(targets, dtype=float).reshape(-1, 2)
    assigned = np.isfinite(t).all(axis=1)
    with np.errstate(invalid="ignore"):
        near = np.hypot(*(x - t).T) <= params.tolerance * r_s
    arrived = assigned & near
    waiting = np.flatnonzero(assigned & ~near)
    all_arrived = len(waiting) == 0
    timed_out = (now - since) >= params.timeout
    return BarrierStatus(
        all_arrived or timed_out,
        all_arrived,
        timed_out and not all_arrived,
        int(arrived.sum()),
        waiting,
        int((~assigned).sum()),
    )


@dataclass(frozen=True)
class CirclePlan:
    """One region update's circles: the ``packing`` and the ``assignment`` of its circles to the agents."""

    packing: Packing
    assignment: Assignment

    def as_dict(self) -> dict[str, Any]:
        return {"packing": self.packing.as_dict(), "assignment": self.assignment.as_dict()}


def plan_circles(
    region: Polygon,
    positions: np.ndarray,
    r_s: float,
    params: PackingParams = PackingParams(),
    assignment: str = "hungarian",
    rng: np.random.Generator | int = 0,
) -> CirclePlan:
    """Pack N = len(positions) circles in ``region`` and assign them (eqs. 5.9-5.10)."""
    x = np.asarray(positions, dtype=float).reshape(-1, 2)
    packing = pack_circles(region, len(x), r_s, params, rng)
    return CirclePlan(packing, assign_circles(x, packing.centres, assignment))
