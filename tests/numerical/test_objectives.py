"""Objective fields (eq. 4.23, A14, Algorithm 7.1 / A19, target U14) and rectangle obstacles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize

from bridge.numerical.objectives import (
    FIELDS,
    DomainMap,
    Field,
    cost_range,
    inside_obstacle,
    make_field,
    obstacle_distance,
    peaks,
    random_obstacles,
    segment_entry,
    segment_hits,
)

STATIC = ("peaks", "rastrigin", "rosenbrock")


# --- U14: peaks normalised by eq. 4.23 ---------------------------------------------------------------------------


def test_peaks_extrema_match_the_digest() -> None:
    (umin, vmin, fmin), (umax, vmax, fmax) = cost_range("peaks")
    assert (umin, vmin) == pytest.approx((0.228, -1.626), abs=1e-3)
    assert (umax, vmax) == pytest.approx((-0.009, 1.581), abs=1e-3)
    assert fmin == pytest.approx(-6.551, abs=1e-3)
    assert fmax == pytest.approx(8.106, abs=1e-3)


def _local_max(field: Field, start_uv: tuple[float, float]) -> tuple[np.ndarray, float]:
    """Local maximum of f near a canonical point, in canonical coordinates."""
    m: DomainMap = field.map  # type: ignore[attr-defined]

    def neg_f(p: np.ndarray) -> float:
        x, y = m.to_arena(p[0], p[1])
        return -float(field.value(np.array([x]), np.array([y]))[0])

    res = optimize.minimize(neg_f, np.asarray(start_uv), method="Nelder-Mead",
                            options={"xatol": 1e-7, "fatol": 1e-12, "maxiter": 4000})
    return res.x, -res.fun


@pytest.mark.parametrize(("start", "where", "f"), [
    ((0.3, -1.55), (0.228, -1.626), 1.0),  # the optimum
    ((-1.3, 0.25), (-1.347, 0.205), 0.761),  # sub-optimum 1
    ((0.25, 0.36), (0.296, 0.320), 0.557),  # sub-optimum 2
])
def test_u14_peaks_optimum_and_sub_optima(start: tuple[float, float], where: tuple[float, float], f: float) -> None:
    field = make_field("peaks", 300.0)
    uv, value = _local_max(field, start)
    assert tuple(uv) == pytest.approx(where, abs=1e-3)
    assert value == pytest.approx(f, abs=1e-3)


def test_peaks_optimum_in_arena_coordinates() -> None:
    field = make_field("peaks", 300.0)
    u, v = field.map.to_canonical(*field.optimum())  # type: ignore[attr-defined]
    assert (float(u), float(v)) == pytest.approx((0.228, -1.626), abs=1e-3)
    # [-3, 3] onto [0, 300]: 50 m per unit
    assert field.optimum() == pytest.approx((150 + 50 * 0.2283, 150 - 50 * 1.6255), abs=0.01)


# --- normalisation and mapping -----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", STATIC)
@pytest.mark.parametrize("size", [300.0, (250.0, 170.0)])
def test_static_field_normalised_with_its_maximum_at_the_optimum(name: str, size: float | tuple[float, float]) -> None:
    field = make_field(name, size)
    assert isinstance(field, Field) and not field.dynamic
    x0, y0, x1, y1 = field.bounds
    assert (x0, y0) == (0.0, 0.0) and (x1, y1) == ((size, size) if np.isscalar(size) else size)
    gx, gy = np.meshgrid(np.linspace(x0, x1, 701), np.linspace(y0, y1, 701))
    f = field.value(gx, gy)
    assert f.shape == gx.shape
    assert f.min() >= 0.0 and f.max() <= 1.0
    assert f.min() < 1e-3  # max F of the domain is reached (up to the grid)
    ox, oy = field.optimum()
    assert field.value(ox, oy) == 1.0
    assert field.value(np.array([ox]), np.array([oy]))[0] == 1.0
    # nothing on the grid beats the optimum, and the grid's best is next to it
    k = np.argmax(f)
    assert math.hypot(gx.flat[k] - ox, gy.flat[k] - oy) < 2 * (x1 - x0) / 700
    field.advance(10)  # static: no-op
    assert field.optimum() == (ox, oy)


def test_rastrigin_and_rosenbrock_optima() -> None:
    ras = make_field("rastrigin", 300.0)
    assert ras.optimum() == pytest.approx((150.0, 150.0), abs=1e-9)
    ros = make_field("rosenbrock", 300.0)
    # [-2.048, 2.048] onto [0, 300]: (1, 1) -> 300 * 3.048 / 4.096
    assert ros.optimum() == pytest.approx((223.2421875, 223.2421875), abs=1e-9)
    (_, _, fmin), (umax, vmax, fmax) = cost_range("rosenbrock")
    assert fmin == 0.0 and (umax, vmax) == (-2.048, -2.048)
    assert fmax == pytest.approx(100 * (-2.048 - 2.048**2) ** 2 + 3.048**2, rel=1e-12)
    (_, _, rmin), (_, _, rmax) = cost_range("rastrigin")
    assert rmin == 0.0 and rmax == pytest.approx(80.7066, abs=1e-3)  # two maxima of u² - 10 cos 2πu at ±4.523


def test_value_is_the_normalised_cost() -> None:
    field = make_field("peaks", 600.0)
    (_, _, fmin), (_, _, fmax) = cost_range("peaks")
    x, y = np.array([0.0, 123.0, 600.0]), np.array([0.0, 456.0, 300.0])
    u, v = field.map.to_canonical(x, y)  # type: ignore[attr-defined]
    assert field.value(x, y) == pytest.approx((peaks(u, v) - fmax) / (fmin - fmax), abs=1e-12)
    # outside the arena: the nearest edge point
    assert field.value(np.array([-50.0, 700.0]), np.array([456.0, 300.0])) == pytest.approx(
        field.value(np.array([0.0, 600.0]), np.array([456.0, 300.0])), abs=1e-15)


def test_domain_map_round_trip_and_corners() -> None:
    m = DomainMap((0.0, 0.0, 300.0, 200.0), (-5.12, -2.048, 5.12, 2.048))
    assert tuple(map(float, m.to_canonical(0.0, 0.0))) == (-5.12, -2.048)
    assert tuple(map(float, m.to_canonical(300.0, 200.0))) == pytest.approx((5.12, 2.048), abs=1e-12)
    assert tuple(map(float, m.to_arena(0.0, 0.0))) == pytest.approx((150.0, 100.0), abs=1e-12)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(0, 300, 1000), rng.uniform(0, 200, 1000)
    xb, yb = m.to_arena(*m.to_canonical(x, y))
    assert np.allclose(xb, x, atol=1e-9) and np.allclose(yb, y, atol=1e-9)
    u, v = m.to_canonical(x, y)
    assert np.allclose(np.diff(u) / np.diff(x), 10.24 / 300) and np.allclose(np.diff(v) / np.diff(y), 4.096 / 200)


def test_make_field_rejects_unknown_names_and_options() -> None:
    with pytest.raises(ValueError) as err:
        make_field("sphere", 300.0)
    for name in FIELDS:
        assert name in str(err.value)
    with pytest.raises(TypeError):
        make_field("peaks", 300.0, grid=10)
    with pytest.raises(TypeError):
        make_field("fdo_peaks", 300.0, colour=1)


# --- fdo_peaks ---------------------------------------------------------------------------------------------------


def _grid_values(field: Field, n: int = 121) -> np.ndarray:
    x0, y0, x1, y1 = field.bounds
    gx, gy = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    return field.value(gx, gy)


def test_fdo_starts_as_peaks() -> None:
    field = make_field("fdo_peaks", 600.0, seed=3)
    assert field.dynamic and field.regions == 4  # type: ignore[attr-defined]
    u, v = field.map.to_canonical(*field.optimum())  # type: ignore[attr-defined]
    assert math.hypot(u - 0.228, v + 1.626) < 0.06  # within one 5 m node (0.05 units)
    assert field.value(*field.optimum()) == 1.0
    # the disk-smoothed surface is close to peaks normalised the same way
    f = _grid_values(field)
    ref = make_field("peaks", 600.0)
    assert np.abs(f - _grid_values(ref)).max() < 0.06


def test_fdo_is_deterministic_from_the_seed() -> None:
    a, b, c = (make_field("fdo_peaks", 600.0, seed=s) for s in (7, 7, 8))
    for fld in (a, b, c):
        fld.advance(250)
    assert np.array_equal(_grid_values(a), _grid_values(b))
    assert a.optimum() == b.optimum()
    assert not np.array_equal(_grid_values(a), _grid_values(c))
    # advancing in any order gives the same landscape
    d = make_field("fdo_peaks", 600.0, seed=7)
    d.advance(400)
    d.advance(250)
    assert np.array_equal(_grid_values(d), _grid_values(a))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_fdo_optimum_moves_inside_the_arena(seed: int) -> None:
    field = make_field("fdo_peaks", 600.0, seed=seed)
    start = field.optimum()
    x0, y0, x1, y1 = field.bounds
    for it in range(1, 501):
        field.advance(it)
        ox, oy = field.optimum()
        assert x0 <= ox <= x1 and y0 <= oy <= y1
        if it % 100 == 0:
            f = _grid_values(field)
            assert f.min() >= 0.0 and f.max() <= 1.0
            assert field.value(ox, oy) == pytest.approx(f.max(), abs=1e-12)
    moved = math.dist(start, field.optimum())
    assert 0.0 < moved <= 400.0


def test_fdo_scale_moves_peaks_100_to_200_m_in_500_iterations() -> None:
    """A19: the chosen scale moves a peak region about 100-200 m over a trial, slower than the robots."""
    nets, paths = [], []
    for seed in range(20):
        field = make_field("fdo_peaks", 600.0, seed=seed)
        d = np.array([field.displacement(t) for t in range(501)])  # type: ignore[attr-defined]
        nets += list(np.hypot(*d[-1].T))
        paths += list(np.hypot(*np.diff(d, axis=0).transpose(2, 0, 1)).sum(axis=0))
    assert 80.0 <= float(np.median(nets)) <= 200.0
    assert 100.0 <= float(np.median(paths)) <= 250.0
    assert float(np.mean(paths)) / 500 < 0.75  # mean speed below Δx_max of E10


# --- obstacles ---------------------------------------------------------------------------------------------------

RECTS = np.array([[10.0, 10.0, 20.0, 20.0], [30.0, 0.0, 40.0, 5.0]])


def test_inside_and_distance_hand_cases() -> None:
    px = np.array([15.0, 10.0, 20.0, 9.99, 25.0, 25.0, 23.0, 35.0, 45.0])
    py = np.array([15.0, 15.0, 20.0, 15.0, 25.0, 15.0, 24.0, 8.0, 10.0])
    assert inside_obstacle(px, py, RECTS).tolist() == [True, True, True, False, False, False, False, False, False]
    expected = [0.0, 0.0, 0.0, 0.01, math.hypot(5, 5), 5.0, 5.0, 3.0, math.hypot(5, 5)]
    assert obstacle_distance(px, py, RECTS) == pytest.approx(expected, abs=1e-12)
    assert obstacle_distance(px, py, np.empty((0, 4))).tolist() == [math.inf] * len(px)
    assert not inside_obstacle(px, py, np.empty((0, 4))).any()


def test_distance_matches_brute_force() -> None:
    rng = np.random.default_rng(5)
    rects = random_obstacles(100.0, 30, rng=rng)
    px, py = rng.uniform(0, 100, 200), rng.uniform(0, 100, 200)
    d = obstacle_distance(px, py, rects)
    for x, y, got in zip(px, py, d, strict=True):
        want = min(math.hypot(max(r[0] - x, 0, x - r[2]), max(r[1] - y, 0, y - r[3])) for r in rects)
        assert got == pytest.approx(want, abs=1e-12)
    assert np.array_equal(d == 0, inside_obstacle(px, py, rects))


SEGMENT_CASES = [
    ((0, 15, 30, 15), True, 1 / 3),  # crossing
    ((15, 30, 15, 0), True, 1 / 3),  # crossing downwards
    ((0, 20, 30, 20), True, 1 / 3),  # sliding along the top edge
    ((15, 25, 25, 15), True, 0.5),  # touching the corner (20, 20)
    ((0, 15, 10, 15), True, 1.0),  # ending on the wall
    ((0, 15, 9.9, 15), False, math.inf),  # stopping short
    ((0, 25, 30, 25), False, math.inf),  # parallel, above
    ((25, 0, 25, 30), False, math.inf),  # parallel, between the two
    ((12, 12, 18, 18), True, 0.0),  # fully inside
    ((15, 15, 50, 50), True, 0.0),  # leaving from inside
    ((5, 5, 5, 5), False, math.inf),  # not moving, outside
    ((15, 12, 15, 12), True, 0.0),  # not moving, inside
    ((25, 8, 45, 8), False, math.inf),  # passing above the second rectangle
    ((45, 0, 25, 10), True, 0.25),  # into the second rectangle's right side
]


@pytest.mark.parametrize(("move", "hit", "t"), SEGMENT_CASES)
def test_segment_hand_cases(move: tuple[float, float, float, float], hit: bool, t: float) -> None:
    x0, y0, x1, y1 = (np.array([c], dtype=float) for c in move)
    assert segment_hits(x0, y0, x1, y1, RECTS).tolist() == [hit]
    assert segment_entry(x0, y0, x1, y1, RECTS)[0] == pytest.approx(t, abs=1e-12)
    # the reverse move hits the same rectangles
    assert segment_hits(x1, y1, x0, y0, RECTS).tolist() == [hit]


def test_segment_hand_cases_in_one_batch() -> None:
    """Moving and still moves mixed in one call, in a 2-D batch, give the same answers one by one."""
    moves = np.array([m for m, _, _ in SEGMENT_CASES], dtype=float).reshape(2, -1, 4)
    t = segment_entry(moves[..., 0], moves[..., 1], moves[..., 2], moves[..., 3], RECTS)
    assert t.shape == moves.shape[:2]
    assert t.ravel() == pytest.approx([want for _, _, want in SEGMENT_CASES], abs=1e-12)
    assert segment_hits(moves[..., 0], moves[..., 1], moves[..., 2], moves[..., 3], RECTS).ravel().tolist() == [
        hit for _, hit, _ in SEGMENT_CASES]
    assert segment_hits(5.0, 5.0, moves[..., 2], moves[..., 3], np.empty((0, 4))).shape == moves.shape[:2]


def test_segments_vectorised_against_sampling() -> None:
    rng = np.random.default_rng(11)
    rects = random_obstacles(60.0, 12, side_m=(2.0, 8.0), rng=rng)
    x0, y0 = rng.uniform(0, 60, 500), rng.uniform(0, 60, 500)
    x1, y1 = x0 + rng.normal(0, 8, 500), y0 + rng.normal(0, 8, 500)
    hits = segment_hits(x0, y0, x1, y1, rects)
    t = segment_entry(x0, y0, x1, y1, rects)
    assert hits.shape == (500,) and 0 < hits.sum() < 500
    s = np.linspace(0, 1, 2001)[:, None]
    sampled = inside_obstacle(x0 + s * (x1 - x0), y0 + s * (y1 - y0), rects)  # (samples, moves)
    assert np.all(hits[sampled.any(axis=0)])  # every sampled contact is found
    first = np.where(sampled.any(axis=0), s[np.argmax(sampled, axis=0), 0], np.inf)
    found = sampled.any(axis=0)
    assert np.all(t[found] <= first[found] + 1e-12)
    assert np.all(first[found] - t[found] <= 1 / 2000 + 1e-12)
    xt, yt = x0[hits] + t[hits] * (x1 - x0)[hits], y0[hits] + t[hits] * (y1 - y0)[hits]
    assert obstacle_distance(xt, yt, rects).max() < 1e-9  # the entry point is on a rectangle


def test_random_obstacles_respect_the_arena_sizes_and_keep_clear() -> None:
    clear = [(150.0, 150.0, 40.0), (20.0, 20.0, 25.0), (290.0, 10.0, 5.0)]
    for seed in range(20):
        rects = random_obstacles(300.0, rng=np.random.default_rng(seed), keep_clear=clear)
        assert rects.shape[1] == 4 and 20 <= len(rects) <= 30
        w, h = rects[:, 2] - rects[:, 0], rects[:, 3] - rects[:, 1]
        assert np.all((w >= 5) & (w <= 15) & (h >= 5) & (h <= 15))
        assert rects[:, :2].min() >= 0 and rects[:, 2:].max() <= 300
        for x, y, r in clear:
            assert obstacle_distance(np.array([x]), np.array([y]), rects)[0] >= r
    a = random_obstacles((300.0, 100.0), 25, rng=np.random.default_rng(4))
    b = random_obstacles((300.0, 100.0), 25, rng=np.random.default_rng(4))
    assert len(a) == 25 and np.array_equal(a, b) and a[:, 3].max() <= 100
    with pytest.raises(ValueError):
        random_obstacles(100.0, 5, rng=np.random.default_rng(0), keep_clear=[(50.0, 50.0, 200.0)])


def test_make_field_builds_the_whole_family_by_name() -> None:
    from bridge.numerical.objectives import LightField, MappingField

    light = make_field("light", (2.55, 2.45), spots=[(1.0, 1.0, 1.0, 0.5)])
    assert isinstance(light, LightField) and isinstance(light, Field) and not light.dynamic
    assert light.optimum() == (1.0, 1.0) and float(light.value(np.array(1.0), np.array(1.0))) == 1.0
    obstacles = np.array([[10.0, 5.0, 12.0, 15.0]])
    mapping = make_field("mapping", (30.0, 20.0), obstacles=obstacles, cell_m=0.5, r_w_m=2.0)
    direct = MappingField((30.0, 20.0), obstacles, cell_m=0.5, r_w_m=2.0)
    assert isinstance(mapping, MappingField) and isinstance(mapping, Field) and mapping.dynamic
    assert np.array_equal(mapping.map.truth, direct.map.truth)
    same = make_field("mapping", (30.0, 20.0), occupied=direct.map.truth, cell_m=0.5, r_w_m=2.0)
    for f in (mapping, same):
        f.observe(np.array([5.0]), np.array([5.0]), 0)  # type: ignore[attr-defined]
    assert mapping.eta() == same.eta() > 0  # type: ignore[attr-defined]
