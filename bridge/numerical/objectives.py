"""The objective fields, one family, and random obstacles for the numerical (point-robot) runner.

A robot "senses" the field at its position as a normalised fitness f in [0, 1], 1 at the optimum: a cost F to
minimise becomes f = (F - max F) / (min F - max F) (thesis eq. 4.23). Every objective is a :class:`Field`, made by
name with :func:`make_field` (``FIELDS``), for the numerical runner and for the sessions (whose light sensors read
a field as lux, e.g. the mapping objective):

- ``peaks``, ``rastrigin``, ``rosenbrock``: the static benchmarks (Gaussian = MATLAB ``peaks``, thesis §7.4.1),
  mapped linearly from their canonical domain onto the arena (:class:`StaticField`);
- ``fdo_peaks``: the dynamic landscape of Algorithm 7.1 (thesis §7.4.2), whose peak regions are moved by forced
  Duffing oscillators (:class:`FdoPeaks`);
- ``light``: a session config's light spots, normalised (:class:`LightField`);
- ``mapping``: eq. 8.1 on an entropy map the robots' scans build (:class:`MappingField`, thesis chapter 8).

Everything is deterministic from the seed and vectorised: hundreds of trials call ``value`` for every robot at
every iteration.

Obstacles are axis-aligned rectangles (x0, y0, x1, y1), closed (their boundary belongs to them); the arena border
is not an obstacle here.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from bridge.numerical.entropy_map import EntropyMap, rasterise_rects

Bounds = tuple[float, float, float, float]
Cost = Callable[[np.ndarray, np.ndarray], np.ndarray]


@runtime_checkable
class Field(Protocol):
    """An objective field: f in [0, 1] at any arena point (eq. 4.23), what the numerical runner's robots and a
    session's light sensors read. A field the robots build by scanning also has ``observe(x, y, iteration)``."""

    bounds: Bounds  # (x0, y0, x1, y1), metres of the arena
    dynamic: bool

    def value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Normalised fitness f in [0, 1] at the points (x, y); 1 is the optimum."""
        ...

    def optimum(self) -> tuple[float, float]:
        """Where f = 1 is now, in arena metres."""
        ...

    def advance(self, iteration: int) -> None:
        """Set the landscape to its state after ``iteration`` iterations (a no-op for static fields)."""
        ...


def _arena_bounds(size_m: float | tuple[float, float]) -> Bounds:
    w, h = (size_m, size_m) if np.isscalar(size_m) else size_m  # type: ignore[misc]
    if not (w > 0 and h > 0):
        raise ValueError(f"arena size must be positive, got {size_m!r}")
    return (0.0, 0.0, float(w), float(h))


@dataclass(frozen=True)
class DomainMap:
    """Linear map between a benchmark's canonical domain (u, v) and the arena (x, y) (A14: a plain affine map)."""

    arena: Bounds
    domain: Bounds  # (u0, v0, u1, v1)

    @property
    def _scale(self) -> tuple[float, float]:
        (x0, y0, x1, y1), (u0, v0, u1, v1) = self.arena, self.domain
        return (u1 - u0) / (x1 - x0), (v1 - v0) / (y1 - y0)

    def to_canonical(self, x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        su, sv = self._scale
        return (self.domain[0] + (np.asarray(x) - self.arena[0]) * su,
                self.domain[1] + (np.asarray(y) - self.arena[1]) * sv)

    def to_arena(self, u: np.ndarray | float, v: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        su, sv = self._scale
        return (self.arena[0] + (np.asarray(u) - self.domain[0]) / su,
                self.arena[1] + (np.asarray(v) - self.domain[1]) / sv)


# ---------------------------------------------------------------------------------------------------------------
# Benchmark costs (canonical coordinates), all vectorised


def peaks(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """MATLAB ``peaks``: the thesis' "Gaussian" function f1 and the FDO's initial surface (§7.4, Algorithm 7.1)."""
    uu, vv = u * u, v * v
    return (3.0 * (1.0 - u) ** 2 * np.exp(-uu - (v + 1.0) ** 2)
            - 10.0 * (0.2 * u - uu * u - vv * vv * v) * np.exp(-uu - vv)
            - np.exp(-(u + 1.0) ** 2 - vv) / 3.0)


def rastrigin(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rastrigin f2 (2-D): 20 + u² + v² - 10 (cos 2πu + cos 2πv); minimum 0 at (0, 0)."""
    return 20.0 + u * u + v * v - 10.0 * (np.cos(2.0 * np.pi * u) + np.cos(2.0 * np.pi * v))


def rosenbrock(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rosenbrock f3 (2-D): 100 (v - u²)² + (1 - u)²; minimum 0 at (1, 1)."""
    a = v - u * u
    b = 1.0 - u
    return 100.0 * a * a + b * b


_LN3 = math.log(3.0)


def _peaks_fast(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``peaks`` with one exp(-u² - v²) factored out and in-place arithmetic (a third faster; same values to
    1e-14), for 1-D or larger arrays. Needs |u|, |v| well below 350 (exp(-2v) must not overflow): callers clip."""
    uu, vv = u * u, v * v
    e = uu + vv
    np.negative(e, out=e)
    np.exp(e, out=e)
    a = 1.0 - u
    a *= a
    t = v * -2.0
    t += _LN3 - 1.0
    a *= np.exp(t, out=t)  # 3 (1 - u)² exp(-2v - 1)
    b = 0.2 - uu
    b *= u
    vv *= vv
    vv *= v
    b -= vv
    b *= 10.0
    a -= b  # - 10 (u/5 - u³ - v⁵)
    t = u * -2.0
    t -= 1.0 + _LN3
    a -= np.exp(t, out=t)  # - exp(-2u - 1) / 3
    a *= e
    return a


_FAST: dict[str, Cost] = {"peaks": _peaks_fast}


def _grid_extremum(cost: Cost, domain: Bounds, sign: float, n: int = 801) -> tuple[float, float, float]:
    """Global minimum of ``sign * cost`` over the (closed) domain: a fine grid, then zooming grids around the best
    node until the window is below 1e-13. Deterministic; used for eq. 4.23's min F / max F."""
    u0, v0, u1, v1 = domain
    lo_u, hi_u, lo_v, hi_v = u0, u1, v0, v1
    while True:
        us, vs = np.linspace(lo_u, hi_u, n), np.linspace(lo_v, hi_v, n)
        uu, vv = np.meshgrid(us, vs)
        k = int(np.argmin(sign * cost(uu, vv)))
        bu, bv = float(uu.flat[k]), float(vv.flat[k])
        du, dv = 2.0 * (hi_u - lo_u) / (n - 1), 2.0 * (hi_v - lo_v) / (n - 1)
        if max(du, dv) < 1e-13:
            return bu, bv, float(cost(np.array(bu), np.array(bv)))
        lo_u, hi_u = max(u0, bu - du), min(u1, bu + du)
        lo_v, hi_v = max(v0, bv - dv), min(v1, bv + dv)
        n = 41


@dataclass(frozen=True)
class _Benchmark:
    cost: Cost
    domain: Bounds
    argmin: tuple[float, float] | None  # analytic minimiser, if known


_BENCHMARKS: dict[str, _Benchmark] = {
    # A14: peaks on [-3, 3]², Rastrigin on [-5.12, 5.12]², Rosenbrock on [-2.048, 2.048]².
    "peaks": _Benchmark(peaks, (-3.0, -3.0, 3.0, 3.0), None),
    "rastrigin": _Benchmark(rastrigin, (-5.12, -5.12, 5.12, 5.12), (0.0, 0.0)),
    "rosenbrock": _Benchmark(rosenbrock, (-2.048, -2.048, 2.048, 2.048), (1.0, 1.0)),
}


@functools.cache
def cost_range(name: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """((u, v, min F), (u, v, max F)) of a benchmark over its canonical domain (the constants of eq. 4.23)."""
    b = _BENCHMARKS[name]
    if b.argmin is not None:
        lo = (*b.argmin, float(b.cost(np.array(b.argmin[0]), np.array(b.argmin[1]))))
    else:
        lo = _grid_extremum(b.cost, b.domain, 1.0)
    return lo, _grid_extremum(b.cost, b.domain, -1.0)


class StaticField:
    """A benchmark cost mapped linearly onto the arena and normalised by eq. 4.23 (E1, E9)."""

    dynamic = False

    def __init__(self, name: str, size_m: float | tuple[float, float]) -> None:
        b = _BENCHMARKS[name]
        self.name = name
        self.bounds: Bounds = _arena_bounds(size_m)
        self.map = DomainMap(self.bounds, b.domain)
        self._fast = _FAST.get(name, b.cost)
        (umin, vmin, _), (_, _, fmax) = cost_range(name)
        su, sv = self.map._scale  # the arena -> canonical map folded into u = x*su + ou
        self._su, self._ou = su, b.domain[0] - self.bounds[0] * su
        self._sv, self._ov = sv, b.domain[1] - self.bounds[1] * sv
        ox, oy = self.map.to_arena(umin, vmin)
        self._opt = (float(ox), float(oy))
        # min F is the cost as value() computes it at optimum(), so f is exactly 1 there (it differs from the true
        # minimum by rounding only; anything below is clipped to 1).
        self._fmax = fmax
        self._fmin = float(self._fast(np.array([ox * su + self._ou]), np.array([oy * sv + self._ov]))[0])
        self._span = self._fmin - fmax

    def value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """f at arena points (eq. 4.23); a point outside the arena reads the nearest point of its edge."""
        u0, v0, u1, v1 = self.map.domain
        u = x * self._su + self._ou
        v = y * self._sv + self._ov
        if type(u) is not np.ndarray or u.ndim == 0:  # a scalar: the in-place arithmetic below needs arrays
            return self.value(np.atleast_1d(np.asarray(x, dtype=float)), np.atleast_1d(np.asarray(y, dtype=float)))[0]
        np.minimum(np.maximum(u, u0, out=u), u1, out=u)
        np.minimum(np.maximum(v, v0, out=v), v1, out=v)
        f = self._fast(u, v)
        f -= self._fmax  # eq. 4.23
        f /= self._span
        return np.minimum(np.maximum(f, 0.0, out=f), 1.0, out=f)

    def optimum(self) -> tuple[float, float]:
        return self._opt

    def advance(self, iteration: int) -> None:
        """Static: nothing moves."""


# ---------------------------------------------------------------------------------------------------------------
# Dynamic landscape (Algorithm 7.1)

DUFFING = (0.1, 1.0, 0.25, 1.0, 0.5)  # (γ, ω, ε, Γ, Ω), thesis §7.4.2


def _duffing_rk4(tau: np.ndarray, x: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """One fixed RK4 step of the standard forced Duffing oscillator x'' + γx' - ω²x + εx³ = Γ cos Ωτ (A19), for
    every oscillator at once (each with its own time ``tau``, i.e. its own forcing phase)."""
    g, w, e, amp, om = DUFFING

    def acc(t: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        return -g * q + w * w * p - e * p * p * p + amp * np.cos(om * t)

    k1x, k1v = v, acc(tau, x, v)
    k2x, k2v = v + 0.5 * h * k1v, acc(tau + 0.5 * h, x + 0.5 * h * k1x, v + 0.5 * h * k1v)
    k3x, k3v = v + 0.5 * h * k2v, acc(tau + 0.5 * h, x + 0.5 * h * k2x, v + 0.5 * h * k2v)
    k4x, k4v = v + h * k3v, acc(tau + h, x + h * k3x, v + h * k3v)
    return (x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x),
            v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v))


def disk_kernel(radius: float) -> np.ndarray:
    """Circular averaging filter like MATLAB ``fspecial('disk', r)``: each cell weighted by the fraction of it inside
    the disc (estimated on a 32 x 32 sub-grid per cell), summing to 1."""
    r = math.ceil(radius - 0.5) if radius > 0.5 else 0
    sub = (np.arange(32) + 0.5) / 32 - 0.5
    c = np.arange(-r, r + 1)
    px = (c[:, None] + sub[None, :]).ravel()  # sub-sample coordinates along one axis
    inside = (px[:, None] ** 2 + px[None, :] ** 2) <= radius * radius
    k = inside.reshape(2 * r + 1, 32, 2 * r + 1, 32).mean(axis=(1, 3))
    return k / k.sum()


class FdoPeaks:
    """Dynamic ``peaks`` landscape (Algorithm 7.1, E10): peak regions moved by forced Duffing oscillators.

    The cost is ``peaks`` sampled on ``grid`` x ``grid`` nodes spanning the arena (default 121: 5 m apart on
    600 m). Regions where |Z| > ``threshold`` · max|Z| (step 1) are labelled (step 2; 4-connected, which finds 4
    regions: the 3.59 maximum joins the 8.1 one). Region k is displaced from its home by integer node offsets
    (step 3) round(s · (x_k(τ) - x_k(τ₀), ẋ_k(τ) - ẋ_k(τ₀)) / cell): the phase-plane excursion of its own standard
    forced Duffing oscillator (A19), integrated with fixed RK4 steps of ``duffing_dt`` oscillator time units per
    iteration, from an initial state (x, ẋ) ~ U(-2, 2)² and a forcing phase ~ U(0, 2π/Ω) drawn from the seed.
    The landscape is then smoothed with a disk filter of ``disk_radius`` nodes (step 4; MATLAB's default 5).

    Scale (A19): s = ``scale_m`` metres per oscillator unit, by default width/15 (40 m on 600 m), with
    ``duffing_dt`` = 0.005 oscillator time units per iteration (500 iterations span a fifth of a forcing period,
    so each region follows one smooth curved path). Over 500 iterations a region then travels 165 m in the median
    (10-90 %: 60-295 m; mean speed 0.34 m/iteration, under half the robots' Δx_max = 0.75 m of E10, with bursts
    up to about 1.1 m/iteration) and ends 105 m from home in the median (90 %: 175 m). The excursion is bounded
    by the oscillator's attractor (about ±3.4 by ±2.5 units), so peaks do not drift out of the arena.

    Each iteration rebuilds Z from the base surface instead of moving the previous one, so smoothing does not
    accumulate. Since filtering is linear and commutes with shifts, the filtered background (Z outside the
    regions) and each filtered region patch are computed once; an iteration only pastes the patches at their
    offsets (cells pushed off the arena are lost, zero fill where a region left). f uses the min/max of the
    iteration-0 surface (eq. 4.23) and is clipped to [0, 1] (overlapping regions can deepen the minimum).
    """

    dynamic = True

    def __init__(self, size_m: float | tuple[float, float], seed: int = 0, *, grid: int = 121,
                 threshold: float = 0.2, disk_radius: float = 5.0, scale_m: float | None = None,
                 duffing_dt: float = 0.005) -> None:
        from scipy import ndimage

        from bridge.core.rng import stream

        self.name = "fdo_peaks"
        self.bounds: Bounds = _arena_bounds(size_m)
        x0, y0, x1, y1 = self.bounds
        n = int(grid)
        if n < 3:
            raise ValueError("grid needs at least 3 nodes per side")
        self._n = n
        self._cx, self._cy = (x1 - x0) / (n - 1), (y1 - y0) / (n - 1)
        self.map = DomainMap(self.bounds, (-3.0, -3.0, 3.0, 3.0))
        u, v = self.map.to_canonical(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
        base = peaks(*np.meshgrid(u, v))  # base[row j (y), col i (x)]
        labels, count = ndimage.label(np.abs(base) > threshold * np.abs(base).max())
        kern = disk_kernel(disk_radius)
        r = kern.shape[0] // 2
        self._background = ndimage.correlate(np.where(labels > 0, 0.0, base), kern, mode="nearest")
        canvas = np.zeros((n + 2 * r, n + 2 * r))
        self._patches: list[tuple[np.ndarray, int, int]] = []  # (filtered patch, home row, home col) in grid nodes
        for k, sl in enumerate(ndimage.find_objects(labels), start=1):
            canvas[:] = 0.0
            canvas[r:r + n, r:r + n] = np.where(labels == k, base, 0.0)
            rows, cols = slice(sl[0].start, sl[0].stop + 2 * r), slice(sl[1].start, sl[1].stop + 2 * r)
            patch = ndimage.correlate(canvas[rows, cols], kern, mode="constant")
            self._patches.append((patch, sl[0].start - r, sl[1].start - r))
        self.regions = count

        rng = stream(seed, "fdo_peaks")
        self._x0 = rng.uniform(-2.0, 2.0, count)
        self._v0 = rng.uniform(-2.0, 2.0, count)
        self._tau0 = rng.uniform(0.0, 2.0 * np.pi / DUFFING[4], count)
        self._h = float(duffing_dt)
        self.scale_m = float(scale_m) if scale_m is not None else (x1 - x0) / 15.0
        self._states: list[tuple[np.ndarray, np.ndarray]] = [(self._x0, self._v0)]

        self._offsets: np.ndarray | None = None
        self._build(np.zeros((count, 2), dtype=int))
        z0 = self._z
        self._zmin, self._zmax = float(z0.min()), float(z0.max())
        self._normalise()
        self.iteration = 0

    # -- dynamics ---------------------------------------------------------------------------------------------

    def displacement(self, iteration: int) -> np.ndarray:
        """(regions, 2) continuous displacement of each region from home after ``iteration`` iterations, metres."""
        while len(self._states) <= iteration:
            t = len(self._states) - 1
            x, v = self._states[-1]
            self._states.append(_duffing_rk4(self._tau0 + t * self._h, x, v, self._h))
        x, v = self._states[iteration]
        return self.scale_m * np.stack([x - self._x0, v - self._v0], axis=1)

    def advance(self, iteration: int) -> None:
        """Set the landscape to iteration ``iteration`` (any order; states are cached, so it is deterministic)."""
        if iteration < 0:
            raise ValueError("iteration must be >= 0")
        d = self.displacement(iteration)
        offsets = np.rint(d / np.array([self._cx, self._cy])).astype(int)  # (cols, rows)
        self.iteration = iteration
        if self._offsets is not None and np.array_equal(offsets, self._offsets):
            return
        self._build(offsets)
        self._normalise()

    def _build(self, offsets: np.ndarray) -> None:
        z = self._background.copy()
        n = self._n
        for (patch, r0, c0), (dc, dr) in zip(self._patches, offsets, strict=True):
            r0, c0 = r0 + int(dr), c0 + int(dc)
            h, w = patch.shape
            a0, b0, a1, b1 = max(r0, 0), max(c0, 0), min(r0 + h, n), min(c0 + w, n)
            if a0 < a1 and b0 < b1:
                z[a0:a1, b0:b1] += patch[a0 - r0:a1 - r0, b0 - c0:b1 - c0]
        self._z = z
        self._offsets = offsets

    def _normalise(self) -> None:
        f = (self._z - self._zmax) / (self._zmin - self._zmax)  # eq. 4.23
        self._f = np.clip(f, 0.0, 1.0, out=f).ravel()
        k = int(np.argmin(self._z))  # deepest node (ties in the clipped f go to the deepest cost)
        j, i = divmod(k, self._n)
        self._opt = (self.bounds[0] + i * self._cx, self.bounds[1] + j * self._cy)

    # -- sensing ----------------------------------------------------------------------------------------------

    @property
    def cost(self) -> np.ndarray:
        """The current (smoothed) cost grid, rows along y."""
        return self._z

    def value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """f by bilinear interpolation of the current grid; points outside the arena read its edge."""
        n = self._n
        fx = np.clip((x - self.bounds[0]) / self._cx, 0.0, n - 1)
        fy = np.clip((y - self.bounds[1]) / self._cy, 0.0, n - 1)
        i = np.minimum(fx.astype(np.intp), n - 2)
        j = np.minimum(fy.astype(np.intp), n - 2)
        wx, wy = fx - i, fy - j
        k = j * n + i
        f = self._f
        a, b, c, d = f[k], f[k + 1], f[k + n], f[k + n + 1]
        top = a + (b - a) * wx
        return top + ((c + (d - c) * wx) - top) * wy

    def optimum(self) -> tuple[float, float]:
        return self._opt


# ---------------------------------------------------------------------------------------------------------------
# A session's light field


class LightField:
    """A session config's light field (``LightCfg``: Gaussian spots on an ambient level) as a field, normalised to 1
    at its brightest spot's centre: a session's light arena in the numerical runner (E8, B11)."""

    dynamic = False

    def __init__(self, spots: list[tuple[float, float, float, float]], size: tuple[float, float],
                 ambient: float = 0.0) -> None:
        from bridge.core.config import LightCfg, LightSource

        self.light = LightCfg(ambient_lux=ambient, sources=[
            LightSource(x=x, y=y, peak_lux=peak, sigma_m=sigma) for x, y, peak, sigma in spots])  # (x, y, peak, sigma)
        self.bounds = (0.0, 0.0, *size)
        best = max(spots, key=lambda s: s[2])
        self._opt = (best[0], best[1])
        self._max = float(self.light.illuminance(best[0], best[1]))

    def value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.light.illuminance(np.asarray(x, float), np.asarray(y, float)) / self._max

    def optimum(self) -> tuple[float, float]:
        return self._opt

    def advance(self, iteration: int) -> None:
        """Static: nothing moves."""


# ---------------------------------------------------------------------------------------------------------------
# The mapping objective (thesis chapter 8): eq. 8.1 on an entropy map the robots build


class MappingField:
    """The mapping objective (``bridge.numerical.entropy_map``) as a field, plus ``observe``: the robots' scans.

    ``value`` is eq. 8.1 on the map as it stands; ``observe(x, y, iteration)`` enters the robots' scans and records
    eta_exp after ``iteration`` rounds (the numerical runner calls it with the start positions, 0, then after every
    round k with k + 1; a session after every scan). ``eta_curve(iterations)`` is eta_exp[0..iterations] (a round
    without moves repeats the previous value). The truth is ``obstacles`` (rectangles, rasterised) or ``occupied``
    (a grid, rows along y, as a session's arena gives it)."""

    dynamic = True

    def __init__(self, size: tuple[float, float], obstacles: np.ndarray | None = None, *, cell_m: float = 0.5,
                 r_w_m: float = 3.0, occupied: np.ndarray | None = None, **options: Any) -> None:
        w, h = float(size[0]), float(size[1])
        self.bounds: Bounds = (0.0, 0.0, w, h)
        if occupied is None:
            nx, ny = math.ceil(w / cell_m - 1e-9), math.ceil(h / cell_m - 1e-9)
            rects = np.zeros((0, 4)) if obstacles is None else np.asarray(obstacles, float)
            occupied = rasterise_rects(rects, self.bounds, cell_m, (ny, nx))
        self.map = EntropyMap(self.bounds, occupied, cell_m, r_w_m, **options)
        self.eta_at: dict[int, float] = {}

    def value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.map.value(x, y)

    def optimum(self) -> tuple[float, float]:
        return self.map.best_frontier()

    def advance(self, iteration: int) -> None:
        """The map changes by observation only (``observe``)."""

    def observe(self, x: np.ndarray, y: np.ndarray, iteration: int) -> None:
        self.map.observe(x, y)
        self.eta_at[int(iteration)] = self.map.eta()

    def eta(self) -> float:
        """Eq. 8.3 now: explored free cells over free cells."""
        return self.map.eta()

    def eta_curve(self, iterations: int) -> np.ndarray:
        out = np.zeros(iterations + 1)
        last = 0.0
        for k in range(iterations + 1):
            last = self.eta_at.get(k, last)
            out[k] = last
        return out


FIELDS = ("peaks", "rastrigin", "rosenbrock", "fdo_peaks", "light", "mapping")


def make_field(name: str, size_m: float | tuple[float, float], seed: int = 0, **options: Any) -> Field:
    """The field ``name`` over a ``size_m`` arena (square if a number), origin at (0, 0): the one factory of the
    objective family, for the numerical runner and the sessions alike.

    Static benchmarks take no options (their seed is irrelevant); ``fdo_peaks`` takes those of :class:`FdoPeaks`,
    ``light`` ``spots`` and ``ambient`` (:class:`LightField`), ``mapping`` ``obstacles`` or ``occupied`` and the
    map's options (:class:`MappingField`).
    """
    if name == "fdo_peaks":
        return FdoPeaks(size_m, seed, **options)
    if name in _BENCHMARKS:
        if options:
            raise TypeError(f"field {name!r} takes no options, got {sorted(options)}")
        return StaticField(name, size_m)
    if name in ("light", "mapping"):
        size = _arena_bounds(size_m)[2:]
        if name == "light":
            return LightField(size=size, **options)
        return MappingField(size, **options)
    raise ValueError(f"unknown field {name!r}; known: {', '.join(FIELDS)}")


# ---------------------------------------------------------------------------------------------------------------
# Obstacles (A14: 20-30 random rectangles of 5-15 m)


def random_obstacles(size_m: float | tuple[float, float], count: int | tuple[int, int] = (20, 30),
                     side_m: tuple[float, float] = (5.0, 15.0), *, rng: np.random.Generator,
                     keep_clear: Sequence[tuple[float, float, float]] = ()) -> np.ndarray:
    """(M, 4) rectangles (x0, y0, x1, y1) inside the arena, sides ~ U(side_m) independently, positions uniform,
    none closer than r to a keep-clear disc (x, y, r) (so the optimum stays reachable and deployment areas free).
    Rectangles may overlap one another. ``count`` is exact or an inclusive (lo, hi) range."""
    _, _, w, h = _arena_bounds(size_m)
    m = int(count) if np.isscalar(count) else int(rng.integers(count[0], count[1] + 1))  # type: ignore[index]
    lo, hi = side_m
    if not (0 < lo <= hi and hi <= min(w, h)):
        raise ValueError(f"side_m {side_m} does not fit a {w} x {h} m arena")
    clear = np.asarray(keep_clear, dtype=float).reshape(-1, 3)
    out = np.empty((m, 4))
    placed, tries = 0, 0
    while placed < m:
        tries += 1
        if tries > 1000 * max(m, 1):
            raise ValueError(f"could not place {m} obstacles clear of {len(clear)} keep-clear discs")
        sw, sh = rng.uniform(lo, hi, 2)
        x0, y0 = rng.uniform(0.0, w - sw), rng.uniform(0.0, h - sh)
        rect = np.array([[x0, y0, x0 + sw, y0 + sh]])
        if len(clear) and np.any(obstacle_distance(clear[:, 0], clear[:, 1], rect) < clear[:, 2]):
            continue
        out[placed] = rect[0]
        placed += 1
    return out


def obstacle_distance(px: np.ndarray, py: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """Euclidean distance from each point to the nearest rectangle (0 inside or on it; inf without rectangles).
    One pass over a rectangles x points array (χ3's input, §4.3); points along the fast axis."""
    px, py = np.broadcast_arrays(np.asarray(px, dtype=float), np.asarray(py, dtype=float))
    if len(rects) == 0:
        return np.full(px.shape, np.inf)
    r = np.asarray(rects, dtype=float)
    cx, hx = ((r[:, 0] + r[:, 2]) * 0.5)[:, None], ((r[:, 2] - r[:, 0]) * 0.5)[:, None]
    cy, hy = ((r[:, 1] + r[:, 3]) * 0.5)[:, None], ((r[:, 3] - r[:, 1]) * 0.5)[:, None]
    dx = px.ravel() - cx  # |p - c| - half side, floored at 0, per axis
    np.abs(dx, out=dx)
    dx -= hx
    np.maximum(dx, 0.0, out=dx)
    dy = py.ravel() - cy
    np.abs(dy, out=dy)
    dy -= hy
    np.maximum(dy, 0.0, out=dy)
    dx *= dx
    dy *= dy
    dx += dy
    return np.sqrt(dx.min(axis=0)).reshape(px.shape)


def inside_obstacle(px: np.ndarray, py: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """Is each point inside (or on the boundary of) any rectangle?"""
    px, py = np.broadcast_arrays(np.asarray(px, dtype=float), np.asarray(py, dtype=float))
    if len(rects) == 0:
        return np.zeros(px.shape, dtype=bool)
    r = np.asarray(rects, dtype=float)[:, :, None]
    x, y = px.ravel(), py.ravel()
    return np.any((x >= r[:, 0]) & (x <= r[:, 2]) & (y >= r[:, 1]) & (y <= r[:, 3]), axis=0).reshape(px.shape)


def segment_entry(x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """For each move (x0, y0) -> (x1, y1), the fraction t in [0, 1] of the move at which it first meets a rectangle
    (0 if it starts inside or on one), inf if it meets none. Liang-Barsky slab test, rectangles x moves.

    A move that only touches a rectangle (an edge or a corner) meets it. To stop a point robot at a wall, move it
    to a fraction a little below t (a robot left exactly on a wall reads t = 0 for every later move).
    """
    x0, y0, x1, y1 = np.broadcast_arrays(*(np.asarray(c, dtype=float) for c in (x0, y0, x1, y1)))
    shape = x0.shape
    if len(rects) == 0:
        return np.full(shape, np.inf)
    r = np.asarray(rects, dtype=float)[:, :, None]
    x0, y0 = x0.ravel(), y0.ravel()
    dx, dy = x1.ravel() - x0, y1.ravel() - y0

    def slab(p: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Entry and exit fractions of each move through the slab lo <= p + t d <= hi (rectangles x moves)."""
        still = d == 0.0
        inv = 1.0 / np.where(still, 1.0, d)
        ta, tb = (lo - p) * inv, (hi - p) * inv
        t_in, t_out = np.minimum(ta, tb), np.maximum(ta, tb)
        if still.any():  # parallel to the slab: inside it for all t, edges included, or for none
            within = (p[still] >= lo) & (p[still] <= hi)
            t_in[:, still] = np.where(within, -np.inf, np.inf)
            t_out[:, still] = np.where(within, np.inf, -np.inf)
        return t_in, t_out

    t_in, t_out = slab(x0, dx, r[:, 0], r[:, 2])
    ty_in, ty_out = slab(y0, dy, r[:, 1], r[:, 3])
    np.maximum(t_in, ty_in, out=t_in)
    np.minimum(t_out, ty_out, out=t_out)
    np.maximum(t_in, 0.0, out=t_in)
    np.minimum(t_out, 1.0, out=t_out)
    t_in[t_in > t_out] = np.inf
    return t_in.min(axis=0).reshape(shape)


def segment_hits(x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """Does each straight move (x0, y0) -> (x1, y1) meet any rectangle (crossing, touching, or inside)?"""
    return np.isfinite(segment_entry(x0, y0, x1, y1, rects))
