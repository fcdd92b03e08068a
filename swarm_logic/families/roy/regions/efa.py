"""Chapter 5's polygonal virtual region Φ (digest 001 §2.3.3): the sensed obstacle points, ordered and resampled into
a closed contour, described by Kuhl and Giardina's elliptic Fourier series (eqs. 5.6-5.8, via ``pyefd``) and
reconstructed as a valid shapely polygon; then how Φ advances toward the target, which the thesis leaves open.

Erratum 19 (digest §5.2), two gaps:

- EFA needs an *ordered* closed contour, yet the thesis uses EFA because the global controller cannot order the
  points. ``EfaParams.ordering = "polar"`` (ours, default) sorts the points by bearing about their centroid (or about a
  centre the caller gives, e.g. the swarm's) and resamples the closed polyline to k points by arc length;
  ``"given"`` (literal) takes the points in the order they come in (agent by agent, sensor by sensor).
- How Φ moves toward T is not said. ``polygon_region`` implements the digest's rule [R]: (a) fewer than 3 points: a
  circle of area N π r_s² / η one step toward T; (b) otherwise the EFA polygon intersected with a disc about the swarm
  centroid shifted one step toward T (``RegionParams.advance = "shift_clip"``). ``"efa"`` keeps the EFA polygon as
  reconstructed, neither moved nor clipped (the thesis' figures taken at face value; rule (a) still applies).
  Ours on top: rule (a) also takes an EFA polygon with less area than one circle (one wall's points), its circle
  loses a disc of r_s about every sensed point, and rule (b)'s disc grows past d_thre+ until Φ has N π r_s² / η.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyefd
import shapely
from shapely.geometry import Polygon

from swarm_logic.families.roy.regions.records import require
from swarm_logic.families.roy.regions.shapes import Ellipse

ORDERINGS = ("polar", "given")
ADVANCES = ("shift_clip", "efa")
SORT_CENTRES = ("points", "swarm")
RULES = ("circle", "efa_disc", "efa")
DUPLICATE_TOL = 1e-9  # points closer than this (units) count as one
GROW_BISECTIONS = 16  # the clip disc's radius to 2^-16 of its range


@dataclass(frozen=True)
class EfaParams:
    """The boundary fit: ``harmonics`` n and ``samples`` k (Table 5.1: 14 and 100, "because there are 14 agents"),
    ``contour_points`` on the reconstructed boundary, ``ordering`` (erratum 19: "polar" ours, "given" literal) and
    ``resample`` (arc-length resampling to k points; off, the ordered points themselves are the contour)."""

    harmonics: int = 14
    samples: int = 100
    contour_points: int = 200
    ordering: str = "polar"
    resample: bool = True

    def __post_init__(self) -> None:
        require(
            isinstance(self.harmonics, int) and self.harmonics >= 1, "harmonics", "must be an int >= 1", self.harmonics
        )
        require(isinstance(self.samples, int) and self.samples >= 3, "samples", "must be an int >= 3", self.samples)
        require(
            isinstance(self.contour_points, int) and self.contour_points >= 8,
            "contour_points",
            "must be an int >= 8",
            self.contour_points,
        )
        require(self.ordering in ORDERINGS, "ordering", f"expected one of {', '.join(ORDERINGS)}", self.ordering)


@dataclass(frozen=True)
class OrderedPoints:
    """The contour the EFA reads: ``points`` (M, 2) in order, and what was dropped on the way (non-finite rows,
    repeats of an earlier point)."""

    points: np.ndarray
    dropped_nonfinite: int
    dropped_duplicates: int


def clean_points(points: np.ndarray) -> tuple[np.ndarray, int, int]:
    """``points`` as (K, 2) float without non-finite rows and without repeats (within ``DUPLICATE_TOL``), the first
    occurrence kept in the given order; returns the points and the two drop counts. An array of odd size counts as no
    points (all dropped as non-finite)."""
    p = np.asarray(points, dtype=float)
    if p.size == 0 or p.size % 2:
        return np.zeros((0, 2)), p.size // 2, 0
    p = p.reshape(-1, 2)
    finite = np.isfinite(p).all(axis=1)
    p = p[finite]
    if len(p) == 0:
        return p, int((~finite).sum()), 0
    key = np.round(p / DUPLICATE_TOL).astype(np.int64) if np.abs(p).max() < 1e6 else p
    _, first = np.unique(key, axis=0, return_index=True)
    keep = np.sort(first)
    return p[keep], int((~finite).sum()), int(len(p) - len(keep))


def order_points(points: np.ndarray, centre: np.ndarray | None = None, ordering: str = "polar") -> OrderedPoints:
    """Erratum 19: ``"polar"`` sorts the cleaned points by bearing about ``centre`` (their centroid when None), points
    on one bearing nearest first; ``"given"`` (literal) keeps their order."""
    require(ordering in ORDERINGS, "ordering", f"expected one of {', '.join(ORDERINGS)}", ordering)
    p, nonfinite, dups = clean_points(points)
    if ordering == "polar" and len(p) > 1:
        c = p.mean(axis=0) if centre is None else np.asarray(centre, dtype=float)
        d = p - c
        bearing = np.arctan2(d[:, 1], d[:, 0])
        p = p[np.lexsort((np.hypot(d[:, 0], d[:, 1]), bearing))]
    return OrderedPoints(p, nonfinite, dups)


def resample_closed(points: np.ndarray, k: int) -> np.ndarray:
    """``k`` points equally spaced by arc length along the closed polyline through ``points`` (M, 2), starting at
    the first; (0, 2) when the polyline has no length."""
    p = np.asarray(points, dtype=float)
    if len(p) < 2:
        return np.zeros((0, 2))
    ring = np.vstack([p, p[:1]])
    seg = np.hypot(*np.diff(ring, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0.0:
        return np.zeros((0, 2))
    t = np.linspace(0.0, s[-1], k, endpoint=False)
    return np.stack([np.interp(t, s, ring[:, 0]), np.interp(t, s, ring[:, 1])], axis=1)


def largest_polygon(geom: shapely.Geometry) -> tuple[Polygon, int]:
    """The largest polygonal piece of ``geom`` (made valid first) and how many other pieces with area were dropped;
    an empty polygon when there is none."""
    if geom.is_empty:
        return Polygon(), 0
    if not geom.is_valid:
        geom = shapely.make_valid(geom)
    flat = shapely.get_parts(shapely.get_parts(geom))  # a collection's multipolygons flattened too
    parts = [g for g in flat if g.geom_type == "Polygon" and g.area > 0.0]
    if not parts:
        return Polygon(), 0
    areas = np.array([g.area for g in parts])
    return parts[int(np.argmax(areas))], len(parts) - 1


@dataclass(frozen=True)
class EfaFit:
    """One boundary fit: the coefficients (n, 4: α_n, β_n, γ_n, δ_n of eq. 5.7), the offsets (α_0, γ_0) of eq. 5.8,
    the reconstructed contour (eq. 5.6), the valid polygon, and what it took: ``repaired`` (the reconstruction crossed
    itself and was made valid, its largest piece kept, ``pieces_dropped`` others dropped), ``points_used``, the drop
    counts. ``polygon`` is empty when the points give no area (fewer than 3, collinear)."""

    coeffs: np.ndarray
    locus: np.ndarray
    contour: np.ndarray
    polygon: Polygon
    repaired: bool
    pieces_dropped: int
    points_used: int
    dropped_nonfinite: int
    dropped_duplicates: int

    @property
    def area(self) -> float:
        return float(self.polygon.area)

    def as_dict(self) -> dict[str, Any]:
        return {
            "coeffs": self.coeffs.tolist(),
            "locus": self.locus.tolist() if np.isfinite(self.locus).all() else None,
            "polygon": polygon_coords(self.polygon),
            "area": self.area,
            "repaired": self.repaired,
            "pieces_dropped": self.pieces_dropped,
            "points_used": self.points_used,
            "dropped_nonfinite": self.dropped_nonfinite,
            "dropped_duplicates": self.dropped_duplicates,
        }


def polygon_coords(polygon: Polygon) -> list[list[float]]:
    """The exterior ring of ``polygon`` as [[x, y], ...] (empty for an empty polygon), for logs."""
    return [] if polygon.is_empty else np.asarray(polygon.exterior.coords).tolist()


def efa_fit(points: np.ndarray, params: EfaParams = EfaParams(), centre: np.ndarray | None = None) -> EfaFit:
    """Eqs. 5.6-5.8 on ``points`` (K, 2): order (about ``centre`` for "polar"), resample to k points, the n-harmonic
    elliptic Fourier series (``pyefd``, not normalised, its DC offsets), the contour reconstructed at
    ``contour_points`` points and made a valid polygon (largest piece kept). Never raises on bad points."""
    ordered = order_points(points, centre, params.ordering)
    p = ordered.points
    if params.resample:
        p = resample_closed(p, params.samples)
    empty = np.zeros((0, 2))
    if len(np.unique(p, axis=0)) < 3:
        return EfaFit(
            np.zeros((params.harmonics, 4)),
            np.full(2, np.nan),
            empty,
            Polygon(),
            False,
            0,
            len(ordered.points),
            ordered.dropped_nonfinite,
            ordered.dropped_duplicates,
        )
    coeffs = pyefd.elliptic_fourier_descriptors(p, order=params.harmonics, normalize=False)
    locus = np.asarray(pyefd.calculate_dc_coefficients(p), dtype=float)
    contour = pyefd.reconstruct_contour(coeffs, locus=locus, num_points=params.contour_points + 1)[:-1]
    raw = Polygon(contour)
    repaired = not raw.is_valid
    polygon, dropped = largest_polygon(raw)
    return EfaFit(
        coeffs,
        locus,
        contour,
        polygon,
        repaired,
        dropped,
        len(ordered.points),
        ordered.dropped_nonfinite,
        ordered.dropped_duplicates,
    )


@dataclass(frozen=True)
class RegionParams:
    """How Φ is made each update (erratum 19, digest §2.3.3 [R]): ``step`` how far its centre moves toward T (units),
    ``packing_density`` η in the area Φ should have, N π r_s² / η (the open-space circle's; 0.7: the densest packings
    of 14 equal circles in a circle reach only 0.747), ``d_max`` (d_thre+, Table 5.1: 5) the radius of the disc the
    EFA polygon is clipped to, ``grow`` (ours: the disc grows past ``d_max`` until Φ has that area or is the whole
    EFA polygon; off: exactly ``d_max``), ``min_points`` below which the circle rule applies, ``advance``
    ("shift_clip" ours, "efa" the reconstruction as is), ``sort_about`` (the polar sort's centre: the points'
    centroid or the swarm's, erratum 19), ``clearance`` (ours, in r_s: the circle rule cuts a disc of that radius
    about every sensed point out of its circle, so one wall, whose points give the EFA no area, is not inside Φ; 0:
    off) and the EFA's own parameters."""

    step: float = 1.0
    packing_density: float = 0.7
    d_max: float = 5.0
    grow: bool = True
    min_points: int = 3
    advance: str = "shift_clip"
    sort_about: str = "points"
    clearance: float = 1.0
    efa: EfaParams = field(default_factory=EfaParams)

    def __post_init__(self) -> None:
        require(math.isfinite(self.step) and self.step >= 0.0, "step", "must be finite and >= 0", self.step)
        require(0.0 < self.packing_density <= 1.0, "packing_density", "must lie in (0, 1]", self.packing_density)
        require(math.isfinite(self.d_max) and self.d_max > 0.0, "d_max", "must be finite and > 0", self.d_max)
        require(
            isinstance(self.min_points, int) and self.min_points >= 3,
            "min_points",
            "must be an int >= 3",
            self.min_points,
        )
        require(self.advance in ADVANCES, "advance", f"expected one of {', '.join(ADVANCES)}", self.advance)
        require(
            self.sort_about in SORT_CENTRES, "sort_about", f"expected one of {', '.join(SORT_CENTRES)}", self.sort_about
        )
        require(
            math.isfinite(self.clearance) and self.clearance >= 0.0,
            "clearance",
            "must be finite and >= 0",
            self.clearance,
        )


@dataclass(frozen=True)
class PolygonRegion:
    """Φ for one update: the valid ``polygon`` (never empty), the ``rule`` that made it ("circle": rule (a), too few
    points, or an EFA polygon with less area than one circle; "efa_disc": rule (b); "efa": the reconstruction as
    is), ``reason`` in words, the ``centre`` it was built about (the swarm centroid one step toward T),
    ``disc_radius`` of the clip (NaN when none), ``repaired``/``pieces_dropped`` for any piece dropped (the EFA's
    self-crossings, the clip's, the circle's beyond the points), the sensed points dropped (non-finite, repeated),
    and the ``fit`` when EFA ran."""

    polygon: Polygon
    rule: str
    reason: str
    centre: np.ndarray
    disc_radius: float
    repaired: bool
    pieces_dropped: int
    dropped_nonfinite: int
    dropped_duplicates: int
    fit: EfaFit | None

    @property
    def area(self) -> float:
        """A_Φ (eq. 5.12's first term)."""
        return float(self.polygon.area)

    def as_dict(self) -> dict[str, Any]:
        return {
            "polygon": polygon_coords(self.polygon),
            "area": self.area,
            "rule": self.rule,
            "reason": self.reason,
            "centre": self.centre.tolist(),
            "disc_radius": None if math.isnan(self.disc_radius) else self.disc_radius,
            "repaired": self.repaired,
            "pieces_dropped": self.pieces_dropped,
            "dropped_nonfinite": self.dropped_nonfinite,
            "dropped_duplicates": self.dropped_duplicates,
            "fit": None if self.fit is None else self.fit.as_dict(),
        }


def step_toward(origin: np.ndarray, target: np.ndarray, step: float) -> np.ndarray:
    """``origin`` moved ``step`` toward ``target``, not past it."""
    d = np.asarray(target, dtype=float) - origin
    dist = float(np.hypot(*d))
    return origin.copy() if dist <= 0.0 else origin + d * (min(step, dist) / dist)


def clip_to_disc(
    polygon: Polygon, centre: np.ndarray, radius: float, need: float, grow: bool
) -> tuple[Polygon, int, float]:
    """``polygon`` ∩ the disc of ``radius`` about ``centre``, its largest piece; with ``grow``, the disc's radius
    bisected up (at most to the polygon's farthest vertex) until that piece's area reaches ``need``. Returns the
    piece, the pieces dropped and the radius."""

    def clip(r: float) -> tuple[Polygon, int]:
        return largest_polygon(polygon.intersection(Ellipse.circle(float(centre[0]), float(centre[1]), r).polygon()))

    piece, dropped = clip(radius)
    if not grow or piece.area >= need:
        return piece, dropped, radius
    far = float(np.hypot(*(np.asarray(polygon.exterior.coords) - centre).T).max()) / math.cos(math.pi / 72)
    if far <= radius:
        return piece, dropped, radius
    best = clip(far)
    if best[0].area < need:
        return best[0], best[1], far
    lo, hi = radius, far
    for _ in range(GROW_BISECTIONS):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if clip(mid)[0].area < need else (lo, mid)
    piece, dropped = clip(hi)
    return piece, dropped, hi


def polygon_region(
    points: np.ndarray,
    positions: np.ndarray,
    target: np.ndarray,
    r_s: float,
    params: RegionParams = RegionParams(),
    centre: np.ndarray | None = None,
) -> PolygonRegion:
    """Φ for the next iteration from the sensed obstacle ``points`` (K, 2), the agents' ``positions`` (N, 2), the
    ``target`` (2,) and r_s. ``centre`` (default: the finite positions' centroid) is where the region is now; the
    circle rule and the clip disc sit one ``step`` from it toward T; the polar sort runs about the points' own
    centroid or ``centre`` (``sort_about``). Bad input never raises: non-finite points are dropped and counted, no
    finite position means the origin and N = 1, a non-finite target means no step."""
    require(math.isfinite(r_s) and r_s > 0.0, "r_s", "must be finite and > 0", r_s)
    pos = np.asarray(positions, dtype=float).reshape(-1, 2)
    pos = pos[np.isfinite(pos).all(axis=1)]
    n = max(len(pos), 1)
    here = np.asarray(centre, dtype=float) if centre is not None else (pos.mean(axis=0) if len(pos) else np.zeros(2))
    if here.shape != (2,) or not np.isfinite(here).all():
        here = np.zeros(2)
    t = np.asarray(target, dtype=float)
    ahead = step_toward(here, t, params.step) if t.shape == (2,) and np.isfinite(t).all() else here.copy()
    need = n * math.pi * r_s * r_s / params.packing_density
    clean, nonfinite, dups = clean_points(points)

    def circle(reason: str, fit: EfaFit | None) -> PolygonRegion:
        disc = Ellipse.circle(float(ahead[0]), float(ahead[1]), math.sqrt(need / math.pi)).polygon()
        dropped = 0
        if params.clearance > 0.0 and len(clean):
            cut = shapely.multipoints(clean).buffer(params.clearance * r_s, quad_segs=8)
            piece, dropped = largest_polygon(disc.difference(cut))
            if piece.is_empty:
                return PolygonRegion(
                    disc,
                    "circle",
                    reason + "; no room left beside the points, not cut",
                    ahead,
                    math.nan,
                    False,
                    0,
                    nonfinite,
                    dups,
                    fit,
                )
            disc = piece
        return PolygonRegion(disc, "circle", reason, ahead, math.nan, dropped > 0, dropped, nonfinite, dups, fit)

    if len(clean) < params.min_points:
        return circle(f"{len(clean)} points sensed (fewer than {params.min_points})", None)
    fit = efa_fit(clean, params.efa, here if params.sort_about == "swarm" else None)
    if fit.polygon.is_empty:
        return circle("the EFA contour encloses no area (collinear points)", fit)
    if fit.area < math.pi * r_s * r_s:
        return circle(f"the EFA polygon ({fit.area:.3g}) is smaller than one circle", fit)
    if params.advance == "efa":
        return PolygonRegion(
            fit.polygon,
            "efa",
            "EFA polygon as reconstructed",
            ahead,
            math.nan,
            fit.repaired,
            fit.pieces_dropped,
            nonfinite,
            dups,
            fit,
        )
    clipped, dropped, radius = clip_to_disc(fit.polygon, ahead, params.d_max, need, params.grow)
    if clipped.is_empty:
        return circle("the EFA polygon lies outside the disc ahead", fit)
    return PolygonRegion(
        clipped,
        "efa_disc",
        "EFA polygon clipped to the disc ahead",
        ahead,
        radius,
        fit.repaired or dropped > 0,
        fit.pieces_dropped + dropped,
        nonfinite,
        dups,
        fit,
    )
