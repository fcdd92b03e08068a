"""Chapter 6's split and merge: openings found in corridor point sets, sub-region sizing (A8), allocation and
leaders (B9), merge (A9, B10), lane targets, and the missing-leader promotions."""

import json
import math

import numpy as np
import pytest

from swarm_logic.families.roy.regions.shapes import Ellipse
from swarm_logic.families.roy.regions.split_merge import (
    SplitMergeParams,
    SubSwarm,
    allocate,
    detect_openings,
    ensure_leader,
    lane_targets,
    largest_remainder,
    leaders,
    merge_all,
    merge_groups,
    merge_swarms,
    split_sizes,
    split_swarm,
)

P = SplitMergeParams(r_s=1.0)
NORTH = math.pi / 2


def corridor(gaps, wall_y=10.0, back_y=30.0, span=(-20.0, 20.0), step=0.1):
    """Points every ``step`` on a wall y = wall_y across the corridor ``span`` (side walls x = span, 0 <= y <
    wall_y), with openings ``gaps`` (x ranges) leading into lanes closed at y = back_y."""
    xs = np.round(np.arange(span[0], span[1] + step / 2, step), 6)
    inside = np.zeros_like(xs, bool)
    for lo, hi in gaps:
        inside |= (xs > lo + 1e-9) & (xs < hi - 1e-9)
    pts = [np.c_[xs[~inside], np.full((~inside).sum(), wall_y)]]
    ys = np.arange(wall_y, back_y + step / 2, step)
    for lo, hi in gaps:
        pts += [np.c_[np.full_like(ys, lo), ys], np.c_[np.full_like(ys, hi), ys]]
        xb = xs[(xs > lo) & (xs < hi)]
        pts.append(np.c_[xb, np.full_like(xb, back_y)])
    side = np.arange(0.0, wall_y, step)
    pts += [np.c_[np.full_like(side, span[0]), side], np.c_[np.full_like(side, span[1]), side]]
    return np.concatenate(pts)


THREE = [(-15.0, -9.0), (-3.0, 1.0), (6.0, 8.5)]  # widths 6, 4, 2.5, listed left to right facing north


def test_one_two_and_three_openings_are_found_left_to_right():
    one = detect_openings(corridor([(-2.0, 2.0)]), (0, 0), NORTH, P)
    assert len(one.openings) == 1 and not one.split and one.reason.startswith("one opening")
    assert one.openings[0].b_fs == pytest.approx(4.0, abs=0.1)
    two = detect_openings(corridor([(-8.0, -4.0), (3.0, 9.0)]), (0, 0), NORTH, P)
    assert two.split and [o.b_fs for o in two.openings] == pytest.approx([4.0, 6.0], abs=0.1)
    three = detect_openings(corridor(THREE), (0, 0), NORTH, P)
    assert three.split and three.reason == "3 openings"
    assert [o.b_fs for o in three.openings] == pytest.approx([6.0, 4.0, 2.5], abs=0.1)
    for o, (lo, hi) in zip(three.openings, THREE, strict=True):
        assert o.centre == pytest.approx([(lo + hi) / 2, 10.0], abs=0.1)  # eq. 6.10: the edges' midpoint
        assert o.centre == pytest.approx((np.array(o.left) + np.array(o.right)) / 2)
        assert o.theta == pytest.approx(NORTH, abs=0.02)  # the passage runs ahead
        assert o.left[0] < o.right[0]


def test_the_frame_follows_the_heading():
    """The same corridor turned by 30 degrees about (3, -2), seen along the turned heading: the same openings."""
    rot = math.radians(30)
    c, s = math.cos(rot), math.sin(rot)
    pts = corridor(THREE) @ np.array([[c, s], [-s, c]]) + np.array([3.0, -2.0])
    scan = detect_openings(pts, (3.0, -2.0), NORTH + rot, P)
    assert [o.b_fs for o in scan.openings] == pytest.approx([6.0, 4.0, 2.5], abs=0.15)


def test_sparse_noisy_sensing_still_shows_three_lanes():
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pts = corridor([(-15.0, -9.0), (-3.0, 1.0), (5.0, 8.0)])
        pts = pts[rng.random(len(pts)) < 0.5]
        pts = pts + rng.normal(0.0, 0.05, pts.shape)
        scan = detect_openings(pts, (0, 0), NORTH, P)
        assert scan.split and [o.b_fs for o in scan.openings] == pytest.approx([6.0, 4.0, 3.0], abs=0.5)


def test_no_opening_in_open_space_and_bad_points_are_counted():
    empty = detect_openings(np.zeros((0, 2)), (0, 0), NORTH, P)
    assert empty.openings == () and not empty.split and empty.reason.startswith("no points")
    behind = detect_openings(np.array([[0.0, -3.0], [1.0, -4.0]]), (0, 0), NORTH, P)
    assert behind.openings == () and behind.dropped_behind == 2
    flat = detect_openings(np.c_[np.linspace(-10, 10, 201), np.full(201, 8.0)], (0, 0), NORTH, P)
    assert flat.openings == () and flat.reason == "no opening"
    pts = np.vstack([corridor(THREE), [[np.nan, 1.0], [np.inf, 2.0]]])
    scan = detect_openings(pts, (0, 0), NORTH, P)
    assert scan.dropped_nonfinite == 2 and len(scan.openings) == 3
    assert scan.as_dict()["reason"] == "3 openings"
    lost = detect_openings(corridor(THREE), (np.nan, 0.0), NORTH, P)
    assert lost.openings == () and lost.reason.startswith("frame not finite")
    with pytest.raises(ValueError, match=r"\(K, 2\)"):
        detect_openings(np.zeros((4, 3)), (0, 0), NORTH, P)


def test_lanes_seen_only_through_beams_without_echo():
    """Hits on the wall alone (the lanes' beams return nothing): the free ends of those beams show the lanes; without
    them the unknown columns take their neighbours' value (no opening) unless they are taken as open (horizon)."""
    xs = np.round(np.arange(-20.0, 20.05, 0.1), 6)
    wall = xs[(np.abs(xs + 6.0) > 2.0) & (np.abs(xs - 6.0) > 2.5)]
    hits = np.c_[wall, np.full(len(wall), 10.0)]
    gap_x = np.r_[np.arange(-7.9, -4.0, 0.3), np.arange(3.6, 8.5, 0.3)]
    free = np.c_[gap_x, np.full(len(gap_x), 14.0)]  # beams that ran clear to their 14-unit reach
    seen = detect_openings(hits, (0, 0), NORTH, P, free=free)
    assert seen.split and [o.b_fs for o in seen.openings] == pytest.approx([4.0, 5.0], abs=0.2)
    assert detect_openings(hits, (0, 0), NORTH, P).openings == ()
    assumed = detect_openings(hits, (0, 0), NORTH, SplitMergeParams(1.0, empty_bins="horizon"))
    assert [o.b_fs for o in assumed.openings] == pytest.approx([4.0, 5.0], abs=0.2)
    short = np.c_[gap_x, np.full(len(gap_x), 9.0)]  # free ends short of the wall say nothing of what lies beyond
    assert detect_openings(hits, (0, 0), NORTH, P, free=short).openings == ()


def test_an_opening_narrower_than_2_r_s_stops_the_split():
    scan = detect_openings(corridor([(-8.0, -4.0), (3.0, 5.0)]), (0, 0), NORTH, P)
    assert not scan.split and len(scan.openings) == 1 and len(scan.narrow) == 1
    assert "narrower than 2" in scan.reason
    # two wide peaks whose edges lie closer than the split gap: no split either, with the reason
    wide = detect_openings(corridor([(-8.0, -4.0), (3.0, 9.0)]), (0, 0), NORTH, SplitMergeParams(1.0, min_split_gap=5))
    assert not wide.split and "opening 0 is narrower than 5" in wide.reason


def test_the_range_profile_finds_the_gaps_of_a_ring():
    """Range against bearing from a region's centre: a ring wall of radius 8 with gaps of 4 units ahead-left,
    ahead and ahead-right (beams through them reach 20)."""
    phi = np.radians(np.arange(0.0, 360.0, 0.25))
    gap = np.zeros_like(phi, bool)
    for centre in (45.0, 90.0, 135.0):
        gap |= np.abs(np.degrees(phi) - centre) < math.degrees(2.0 / 8.0)  # half-width 2 at radius 8
    r = np.where(gap, 20.0, 8.0)
    pts = np.c_[r * np.cos(phi), r * np.sin(phi)]
    scan = detect_openings(pts, (0, 0), NORTH, SplitMergeParams(1.0, profile="range", bin_angle=math.radians(1)))
    assert scan.split and len(scan.openings) == 3
    assert [o.b_fs for o in scan.openings] == pytest.approx([4.0] * 3, abs=0.4)
    assert [math.degrees(math.atan2(*o.centre[::-1])) for o in scan.openings] == pytest.approx([135, 90, 45], abs=2)


def test_split_sizes_a8():
    sz = split_sizes([6.0, 4.0, 2.0], 50, 1.3)
    assert sz.count.tolist() == [25, 17, 8] and sz.count.sum() == 50
    assert sz.area.sum() == pytest.approx(50 * math.pi * 1.3**2)
    assert math.pi * sz.a * sz.b == pytest.approx(sz.area)
    assert sz.b.tolist() == [6.0, 4.0, 2.0]
    assert split_sizes([6.0, 4.0, 2.0], 50, 1.3, "half").b.tolist() == [3.0, 2.0, 1.0]
    assert largest_remainder([1, 1, 1], 10).tolist() == [4, 3, 3]
    assert largest_remainder([1, 2], 3).tolist() == [1, 2]
    with pytest.raises(ValueError, match="b_fs"):
        split_sizes([3.0, 0.0], 10, 1.0)


def cluster(n, seed=3, centre=(0.0, 4.0), spread=3.0):
    return np.random.default_rng(seed).uniform(-spread, spread, (n, 2)) + np.array(centre)


def test_split_b9_the_widest_opening_gets_the_most_agents_and_leaders_are_nearest():
    scan = detect_openings(corridor(THREE), (0, 0), NORTH, P)
    pos = cluster(50)
    parent = SubSwarm(0, tuple(range(50)), 7, Ellipse(0.0, 4.0, 5.0, 10.0, NORTH))
    d = split_swarm(scan, parent, pos, P, first_id=1)
    assert d.split and d.promotions == () and [s.id for s in d.swarms] == [1, 2, 3]
    sizes = [len(s.members) for s in d.swarms]
    assert sizes == split_sizes(scan.b_fs, 50, 1.0).count.tolist() and sum(sizes) == 50
    assert int(np.argmax(sizes)) == int(np.argmax(scan.b_fs)) == 0
    assert sorted(m for s in d.swarms for m in s.members) == list(range(50))
    assert sum(s.region.area for s in d.swarms) == pytest.approx(50 * math.pi)
    for s, o in zip(d.swarms, scan.openings, strict=True):
        assert s.region.b == pytest.approx(o.b_fs) and s.region.centre == pytest.approx(o.centre)
        dist = np.hypot(*(pos[list(s.members)] - s.region.centre).T)
        assert s.leader == s.members[int(np.argmin(dist))]  # eq. 6.14
    json.dumps([scan.as_dict(), d.as_dict()])  # plain values, for the planner's log
    # eq. 6.13: the widest region took the agents nearest its centre
    first = d.swarms[0]
    dist0 = np.hypot(*(pos - first.region.centre).T)
    assert set(first.members) == set(np.argsort(dist0, kind="stable")[: len(first.members)].tolist())


def test_allocation_by_assignment_respects_the_counts_and_costs_no_more():
    pos = cluster(40, seed=5)
    centres = np.array([[-8.0, 10.0], [0.0, 10.0], [7.0, 10.0]])
    counts = [20, 12, 8]
    greedy = allocate(pos, centres, counts, priority=[6.0, 4.0, 2.0])
    best = allocate(pos, centres, counts, method="assignment")
    for lab in (greedy, best):
        assert np.bincount(lab, minlength=3).tolist() == counts

    def cost(lab):
        return float(np.hypot(*(pos - centres[lab]).T).sum())

    assert cost(best) <= cost(greedy) + 1e-9
    assert leaders(pos, best, centres).tolist() == [
        int(np.flatnonzero(best == j)[np.argmin(np.hypot(*(pos[best == j] - centres[j]).T))]) for j in range(3)
    ]
    with pytest.raises(ValueError, match="sum to the 40 agents"):
        allocate(pos, centres, [20, 12, 7])


def test_merge_groups_follow_overlaps_transitively():
    a, b, c = Ellipse(0, 0, 2, 1), Ellipse(3.5, 0, 2, 1), Ellipse(7, 0, 2, 1)
    far = Ellipse(0, 20, 2, 1)
    assert merge_groups([a, b, c, far]) == ((0, 1, 2),)
    assert merge_groups([a, far]) == ()


def test_merge_a9_b10_hardware_swarm():
    """Two sub-swarms of 3 with r_s = 11.3 cm, sized by the split of two equal lanes: the merged region has the
    larger b, the sum of the areas, 6 pi r_s^2 = 2407 cm^2 (Theorem 1 met), one leader."""
    r_s = 11.3
    prm = SplitMergeParams(r_s)
    sz = split_sizes([20.4, 20.4], 6, r_s)
    props = [Ellipse(0.0, 0.0, sz.a[0], sz.b[0], 0.3), Ellipse(30.0, 10.0, sz.a[1], 18.0, 0.3)]
    pos = np.array([[0, 0], [5, 5], [-5, 0], [30, 10], [25, 12], [35, 8]], float)
    subs = [SubSwarm(1, (0, 1, 2), 0, props[0]), SubSwarm(2, (3, 4, 5), 3, props[1])]
    out, merges = merge_all(subs, props, pos, prm, target=(200.0, 10.0))
    assert len(out) == 1 and len(merges) == 1
    m = merges[0]
    assert m.area == pytest.approx(props[0].area + props[1].area) and m.swarm.region.area == pytest.approx(m.area)
    assert m.swarm.region.b == pytest.approx(max(p.b for p in props))
    assert m.required_area == pytest.approx(2407.0, abs=1.0) and round(6 * math.pi * r_s**2) == 2407
    assert m.theorem1 == (m.area >= m.required_area)
    w = np.array([p.area for p in props])
    centre = (w[:, None] * np.array([p.centre for p in props])).sum(0) / w.sum()
    assert m.swarm.region.centre == pytest.approx(centre)
    assert m.swarm.region.theta == pytest.approx(math.atan2(10.0 - centre[1], 200.0 - centre[0]))
    assert m.swarm.leader == int(np.argmin(np.hypot(*(pos - centre).T))) and m.swarm.members == tuple(range(6))
    json.dumps([m.as_dict() for m in merges] + [s.as_dict() for s in out])
    equal = merge_swarms(subs, [props[0], props[0].moved(5.0, 0.0)], pos, prm)
    assert equal.area == pytest.approx(2 * 3 * math.pi * r_s**2) and equal.theorem1
    small = merge_swarms(subs, [Ellipse(0, 0, 10, 10), Ellipse(5, 0, 10, 10)], pos, prm)
    assert not small.theorem1 and small.as_dict()["theorem1"] is False


def test_regions_that_do_not_overlap_take_their_proposals():
    subs = [SubSwarm(1, (0,), 0, Ellipse(0, 0, 1, 1)), SubSwarm(2, (1,), 1, Ellipse(9, 0, 1, 1))]
    props = [Ellipse(0, 1, 1, 1), Ellipse(9, 1, 1, 1)]
    out, merges = merge_all(subs, props, np.array([[0.0, 0.0], [9.0, 0.0]]), P)
    assert merges == () and [s.region for s in out] == props


def test_a_missing_leader_is_replaced_by_the_survivor_nearest_the_centre():
    pos = cluster(12, seed=9)
    region = Ellipse(0.0, 4.0, 3.0, 3.0)
    ids = np.arange(12)
    alive = ids != 4
    sw = SubSwarm(5, tuple(range(12)), 4, region)
    kept, promo = ensure_leader(sw, pos[alive], ids[alive])
    near = int(ids[alive][np.argmin(np.hypot(*(pos[alive] - region.centre).T))])
    assert promo is not None and promo.dead == 4 and promo.promoted == near == kept.leader
    assert 4 not in kept.members and len(kept.members) == 11
    nan_pos = pos.copy()
    nan_pos[4] = np.nan  # a dead robot reported without a position
    assert ensure_leader(sw, nan_pos)[1].promoted == near
    assert ensure_leader(sw, pos)[1] is None
    gone, promo = ensure_leader(sw, np.zeros((0, 2)), np.zeros(0, int))
    assert gone.leader == -1 and promo.promoted == -1 and gone.members == ()
    # during a split: the parent's leader is replaced first, and it is logged
    scan = detect_openings(corridor(THREE), (0, 0), NORTH, P)
    d = split_swarm(scan, sw, pos[alive], P, ids=ids[alive], first_id=10)
    assert d.split and d.promotions[0].dead == 4 and d.missing == (4,)
    assert sum(len(s.members) for s in d.swarms) == 11 and all(4 not in s.members for s in d.swarms)
    # during a merge: a sub-swarm's leader missing, the merged leader named in the promotion
    a = SubSwarm(1, (0, 1, 2, 3, 4, 5), 4, Ellipse(-1.0, 4.0, 2.0, 2.0))
    b = SubSwarm(2, (6, 7, 8, 9, 10, 11), 6, Ellipse(1.0, 4.0, 2.0, 2.0))
    m = merge_swarms([a, b], [a.region, b.region], pos[alive], P, ids=ids[alive])
    assert [p.dead for p in m.promotions] == [4] and m.promotions[0].promoted == m.swarm.leader != 4
    json.dumps(m.as_dict())
    assert len(m.swarm.members) == 11 and m.required_area == pytest.approx(11 * math.pi)


def test_too_few_survivors_for_the_openings_do_not_split():
    scan = detect_openings(corridor(THREE), (0, 0), NORTH, P)
    one = split_swarm(scan, SubSwarm(0, (0,), 0, Ellipse.circle(0, 4, 1)), np.array([[0.0, 4.0]]), P)
    assert not one.split and one.swarms[0].members == (0,)
    two = split_swarm(scan, SubSwarm(0, (0, 1), 0, Ellipse.circle(0, 4, 1)), np.array([[0, 4.0], [1, 4.0]]), P)
    assert two.split and len(two.swarms) == 2  # the narrowest lane would get nobody: dropped, the sizes redone
    assert sum(s.region.area for s in two.swarms) == pytest.approx(2 * math.pi)


def test_lane_targets_by_direction_or_by_the_scenario():
    centres = np.array([[-6.0, 10.0], [0.0, 10.0], [6.0, 10.0]])
    targets = np.array([[80.0, 90.0], [-80.0, 90.0], [0.0, 95.0]])
    assert lane_targets((0, 0), centres, targets) == (1, 2, 0)
    assert lane_targets((0, 0), centres, targets, mapping=[0, 0, 1]) == (0, 0, 1)
    with pytest.raises(ValueError, match="mapping"):
        lane_targets((0, 0), centres, targets, mapping=[0, 5, 1])
    scan = detect_openings(corridor(THREE), (0, 0), NORTH, P)
    d = split_swarm(scan, SubSwarm(0, tuple(range(20)), 0, Ellipse.circle(0, 4, 3)), cluster(20), P, targets=targets)
    assert [s.target for s in d.swarms] == [1, 2, 0]


def test_bad_parameters_name_the_field():
    with pytest.raises(ValueError, match="r_s"):
        SplitMergeParams(0.0)
    with pytest.raises(ValueError, match="median_window"):
        SplitMergeParams(1.0, median_window=4)
    with pytest.raises(ValueError, match="profile"):
        SplitMergeParams(1.0, profile="polar")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="bin_width"):
        SplitMergeParams(1.0, bin_width=-1.0)


def sonar_scan(gaps, seed, periods=4, r_s=0.5):
    """What a chapter 6 leader gathers over ``periods``: 100 agents in a 10 x 10 block 1 unit apart (front row 3
    units from a wall across a 20-unit corridor with openings ``gaps``), each with 8 beams 45 degrees apart at a
    heading within 0.4 rad of the corridor's, Table 6.1's window [2, 5]; the hits and the echo-less beams' ends."""
    rng = np.random.default_rng(seed)
    cuts = [-10.0, *[g for gap in gaps for g in gap], 10.0]
    segs = [((a, 3.5), (b, 3.5)) for a, b in zip(cuts[::2], cuts[1::2], strict=True)]
    segs += [((lo, 3.5), (lo, 23.5)) for gap in gaps for lo in gap] + [((-10, -50), (-10, 3.5)), ((10, -50), (10, 3.5))]
    p, e = np.array(segs)[:, 0], np.diff(np.array(segs), axis=1)[:, 0]
    block = np.stack(np.meshgrid(np.arange(10) - 4.5, 0.5 - np.arange(10)), -1).reshape(-1, 2)
    hits, free = [], []
    for k in range(periods):
        pos = block + rng.normal(0, 0.1, block.shape) + [0, -0.2 * k]
        ang = (NORTH + rng.uniform(-0.4, 0.4, 100)[:, None] + np.arange(8) * math.pi / 4).ravel()
        o, d = np.repeat(pos, 8, axis=0), np.c_[np.cos(ang), np.sin(ang)]
        den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
        w = p[None] - o[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]) / den
            u = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / den
        t = np.where((den != 0) & (u >= 0) & (u <= 1) & (t > 0), t, np.inf).min(axis=1)
        hit = (t >= 2.0) & (t <= 5.0)
        hits.append(o[hit] + t[hit, None] * d[hit])
        free.append(o[t > 5.0] + 5.0 * d[t > 5.0])
    params = SplitMergeParams(r_s, bin_width=r_s)
    return detect_openings(np.concatenate(hits), block.mean(0), NORTH, params, free=np.concatenate(free))


def test_sonar_density_gathered_over_four_periods():
    """The density a planner gets from 8-beam sonars (see the docs' measurements): no false lane in a closed
    corridor, and the lanes found in most seeds, their b_fs within half a unit."""
    assert all(sonar_scan([], seed).openings == () for seed in range(10))
    one = [sonar_scan([(-2.0, 2.0)], seed) for seed in range(10)]
    found = [s.b_fs for s in one if len(s.openings) == 1]
    assert len(found) >= 8 and np.allclose(found, 4.0, atol=0.5)
    two = [sonar_scan([(-6.0, -3.0), (1.0, 5.0)], seed) for seed in range(10)]
    split = [s.b_fs for s in two if s.split and len(s.openings) == 2]
    assert len(split) >= 5 and np.allclose(split, [3.0, 4.0], atol=0.5)


def test_span_all_finds_lanes_seen_only_through_clear_beams():
    """A swarm facing the wall between two lanes 3 wide: hits only on that wall (x = 5, |y| <= 1.2), the lanes seen
    through beams clear to 10, the outer walls through echoes beyond the window (6.5). With ``span="hits"`` the
    profile covers the wall alone; with ``"all"`` both lanes are found, b_fs within 0.1 of 3."""
    hits = np.stack([np.full(40, 5.0), np.linspace(-1.2, 1.2, 40)], axis=1)

    def ray(deg: np.ndarray, r: float) -> np.ndarray:
        a = np.radians(deg)
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)

    lanes = np.concatenate([np.linspace(15, 39, 30), -np.linspace(15, 39, 30)])
    outer = np.concatenate([np.linspace(41, 70, 30), -np.linspace(41, 70, 30)])
    free = np.concatenate([ray(lanes, 10.0), ray(outer, 6.5)])
    kw = {"r_s": 0.5, "profile": "range", "bin_width": 0.5, "prominence": 1.0, "min_width": 1.0, "edge_tolerance": 0.5}
    narrow = detect_openings(hits, np.zeros(2), 0.0, SplitMergeParams(**kw), free=free)
    assert narrow.openings == () and not narrow.split
    wide = detect_openings(hits, np.zeros(2), 0.0, SplitMergeParams(**kw, span="all"), free=free)
    assert wide.split and np.allclose(wide.b_fs, 3.0, atol=0.1)
    with pytest.raises(ValueError, match="span"):
        SplitMergeParams(r_s=1.0, span="everything")
