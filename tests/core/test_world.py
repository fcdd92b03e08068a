"""The pybullet world: walls stop robots, obstacles from a bitmap, the light field, battery drain, sonar rates."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest
from PIL import Image

from bridge.core.config import Config, load_config
from bridge.core.plan import make_plan
from bridge.core.world import World


def world(**cfg) -> World:
    c = Config.model_validate(cfg)
    return World(c, make_plan(c).robots)


def one_robot(x: float, y: float, yaw_deg: float, **extra) -> dict:
    return {"robots": [{"count": 1, "placement": {"kind": "explicit", "poses": [[x, y, yaw_deg]]}}], **extra}


def run(w: World, seconds: float, pwm: tuple[int, int]) -> None:
    q = 10_000_000
    t = 0
    for _ in range(round(seconds * 100)):
        w.model("differential_drive").set_pwm(0, *pwm)
        w.step_quantum(t, q)
        t += q


def test_wall_stops_a_robot_and_wheels_keep_counting() -> None:
    w = world(**one_robot(1.0, 5.0, 180.0, arena={"width_m": 10, "length_m": 10}))
    run(w, 8.0, (200, 200))
    x = w.pos[0, 0]
    assert 0.063 - 0.01 < x < 0.2  # pressed against the wall at x = 0, not through it
    assert w.sensors(0)["encoders"][0] > 1.5 * 362  # counted far more than the 0.94 m it could travel


def test_robots_collide_with_each_other() -> None:
    c = Config.model_validate(
        {"robots": [{"count": 2, "placement": {"kind": "explicit", "poses": [[2.0, 2.0, 0.0], [3.0, 2.0, 180.0]]}}]}
    )
    w = World(c, make_plan(c).robots)
    drive = w.model("differential_drive")
    drive.gain[:] = 1.0  # ideal drive trains: exactly head-on along one line
    drive.wheel_r[:] = drive.parts[0].wheel_radius_m
    closest = math.inf
    for k in range(400):  # without contacts they would pass through each other
        drive.set_pwm(0, 180, 180)
        drive.set_pwm(1, 180, 180)
        w.step_quantum(k * 10_000_000, 10_000_000)
        closest = min(closest, math.dist(w.pos[0], w.pos[1]))
    assert 2 * 0.063 - 0.01 < closest < 2 * 0.063 + 0.02  # they met and did not interpenetrate


def test_bitmap_map_becomes_obstacles(tmp_path: Path) -> None:
    img = np.full((40, 40), 255, np.uint8)
    img[18:22, 0:40] = 0  # a horizontal wall across the middle of a 2 x 2 m map
    Image.fromarray(img).save(tmp_path / "m.png")
    (tmp_path / "c.toml").write_text(
        "[arena]\nwidth_m = 2\nlength_m = 2\nmap = 'm.png'\nmap_resolution_m = 0.05\n"
        "[[robots]]\n[robots.placement]\nkind = 'explicit'\nposes = [[1.0, 0.4, 90]]\n"
    )
    cfg = load_config(tmp_path / "c.toml")
    w = World(cfg, make_plan(cfg).robots)
    assert len(w.static_rects) == 5  # 4 arena walls + 1 merged rectangle
    run(w, 6.0, (200, 200))
    assert w.pos[0, 1] < 0.9 - 0.063 + 0.02  # stopped by the map wall spanning y in [0.9, 1.1]


def test_light_field_and_sensor_noise_are_seeded() -> None:
    extra = {"light": {"ambient_lux": 10, "sources": [{"x": 2, "y": 2, "peak_lux": 100, "sigma_m": 1}]}}
    a = world(**one_robot(2.0, 2.0, 0, **extra))
    b = world(**one_robot(2.0, 2.0, 0, **extra))
    assert a.cfg.light.illuminance(2, 2) == pytest.approx(110)
    assert a.cfg.light.illuminance(3, 2) == pytest.approx(10 + 100 * math.exp(-0.5))
    readings = [a.sensors(0)["lux"] for _ in range(200)]
    assert readings[:5] == [b.sensors(0)["lux"] for _ in range(5)]  # seeded: same stream in the same order
    assert np.std(readings) == pytest.approx(110 * 0.01, rel=0.25)  # 1 % noise is there
    assert np.mean(readings) == pytest.approx(110, rel=0.005)


def test_battery_drains_faster_with_motors_on() -> None:
    idle = world(**one_robot(2, 2, 0))
    busy = world(**one_robot(2, 2, 0))
    run(idle, 5, (0, 0))
    run(busy, 5, (255, -255))
    assert busy.soc[0] < idle.soc[0] < 1.0
    assert busy.battery_v[0] < idle.battery_v[0]


def test_each_robot_kind_samples_its_sonars_at_its_own_rate(monkeypatch: pytest.MonkeyPatch) -> None:
    """An eSwarBot (20 Hz), a TraxBot (10 Hz) and a SonPI (100 Hz) in one arena: each robot's sonars are sampled at
    its own part's rate, and the robots due at one quantum's end share one ray batch."""

    def at(x: float, y: float, profile: str) -> dict:
        return {"profile": profile, "count": 1, "placement": {"kind": "explicit", "poses": [[x, y, 0.0]]}}

    # walls within every sonar's reach in any direction: every reading is an echo, noisy where the part has noise
    w = world(
        arena={"width_m": 3, "length_m": 3},
        robots=[at(1.0, 1.0, "eswarbot"), at(2.0, 1.0, "traxbot"), at(1.5, 2.0, "sonpi")],
    )
    real = pb.rayTestBatch
    now = [0]
    batches: list[tuple[int, int]] = []

    def counted(*args, **kw):  # the real ray test, counted
        batches.append((now[0], len(args[0])))
        return real(*args, **kw)

    monkeypatch.setattr(pb, "rayTestBatch", counted)
    sonar = w.model("sonar")
    rates = {0: 20, 1: 10, 2: 100}
    rays = {0: 5, 1: 3 * 5, 2: 5 * 5}  # sonars x rays per cone
    q = 10_000_000
    seen: dict[int, list[int]] = {r: [] for r in rates}  # the quantum ends where a robot's readings changed
    last = {r: sonar.ranges[sonar.local[r]].copy() for r in rates}
    try:
        for k in range(100):
            now[0] = (k + 1) * q
            w.step_quantum(k * q, q)
            for r in rates:
                cur = sonar.ranges[sonar.local[r]]
                if not np.array_equal(cur, last[r]):
                    seen[r].append(now[0])
                last[r] = cur.copy()
    finally:
        w.close()
    # a robot samples at the first quantum end at or after each of its periods (0, 1/rate, 2/rate, ...)
    due = {
        r: [(k + 1) * q for k in range(100) if k == 0 or (k + 1) * q * rate % 1_000_000_000 == 0]
        for r, rate in rates.items()
    }
    assert [len(d) for d in due.values()] == [21, 11, 100]
    assert seen[0] == due[0] and seen[1] == due[1]  # their noise is drawn afresh at each sample, and only then
    assert seen[2] == due[2][:1]  # the SonPI's cones have no noise: standing still, its ranges never change
    expected = [(t, sum(n for r, n in rays.items() if t in due[r])) for t in due[2]]
    assert batches == expected  # one ray batch per quantum end with a robot due, holding exactly those robots' rays


def test_a_board_s_sonar_schedule_casts_only_the_cones_it_fires(monkeypatch: pytest.MonkeyPatch) -> None:
    """A SonPI whose board fires one sensor per 60 ms slot (``Sonars.schedule``): each quantum end casts only the
    cones due (5 rays each), each at the first quantum end at or after its firing time; a malformed schedule is an
    error."""
    one = {"profile": "sonpi", "count": 1, "placement": {"kind": "explicit", "poses": [[1.5, 1.5, 0]]}}
    w = world(arena={"width_m": 3, "length_m": 3}, robots=[one])
    real = pb.rayTestBatch
    now = [0]
    batches: list[tuple[int, int]] = []

    def counted(*args, **kw):
        batches.append((now[0], len(args[0])))
        return real(*args, **kw)

    monkeypatch.setattr(pb, "rayTestBatch", counted)
    sonar = w.model("sonar")
    ms = 1_000_000
    nxt = [25 * ms + j * 60 * ms for j in range(5)]  # part order; one per slot, the first between quanta
    sonar.schedule(0, nxt, [300 * ms] * 5)
    with pytest.raises(ValueError, match="5 times"):
        sonar.schedule(0, nxt[:4], [300 * ms] * 4)
    q = 10 * ms
    try:
        for k in range(70):
            now[0] = (k + 1) * q
            w.step_quantum(k * q, q)
    finally:
        w.close()
    times = [n + i * 300 * ms for n in nxt for i in range(3)]
    expected = sorted((-(-t // q) * q, 5) for t in times if t <= 700 * ms)
    assert batches == expected and batches[0] == (30 * ms, 5)


def test_a_moving_obstacle_follows_its_path_and_the_sonars_see_it() -> None:
    """A cylinder shuttling on a repeated path (a toy car): where its waypoints say at each time, looping; a SonPI's
    front sonar sees it come and go; a path that does not close its loop, or goes back in time, is refused."""
    car = {"type": "cylinder", "x": 1.0, "y": 1.5, "radius": 0.1, "height": 0.08,
           "motion": {"waypoints": [[2.0, 2.6, 1.5], [4.0, 1.0, 1.5]], "repeat": True}}
    one = {"profile": "sonpi", "count": 1, "placement": {"kind": "explicit", "poses": [[2.5, 0.5, 90]]}}
    w = world(arena={"width_m": 3, "length_m": 3}, obstacles=[car], robots=[one])
    body, _, period, _ = w.movers[0]
    assert period == 4.0 and not w.cylinders  # not a static obstacle
    q = 10_000_000
    seen = []
    try:
        for k in range(800):
            w.step_quantum(k * q, q)
            if (k + 1) % 25 == 0:
                (x, y, _), _ = pb.getBasePositionAndOrientation(body, physicsClientId=w.cid)
                t = (k + 1) / 100 % 4.0
                assert (x, y) == pytest.approx((1.0 + 0.8 * min(t, 4.0 - t), 1.5), abs=0.01)
                seen.append(float(w.model("sonar").ranges[0][0]))  # the front sonar, looking along x = 2.5
    finally:
        w.close()
    assert min(seen) < 1.0 and max(seen) > 2.0  # the car crosses the sonar's line (x = 2.5) and leaves it
    for bad, why in (({"waypoints": [[2.0, 2.0, 1.5]], "repeat": True}, "last waypoint"),
                     ({"waypoints": [[2.0, 2.0, 1.5], [1.0, 1.0, 1.5]]}, "increasing")):
        with pytest.raises(ValueError, match=why):
            Config.model_validate({"obstacles": [{**car, "motion": bad}], "robots": [one]})


def _walls_by_every_ray(w: World, src: int) -> np.ndarray:
    """The walls between ``src`` and every robot, casting every ray (what ``World.walls`` must equal)."""
    z = [p.height_m * 0.9 for p in w.profiles]
    frm = [[float(w.pos[src, 0]), float(w.pos[src, 1]), z[src]]] * w.n
    to = [[float(w.pos[d, 0]), float(w.pos[d, 1]), z[d]] for d in range(w.n)]
    counts = np.zeros(w.n, dtype=int)
    for level in range(w.MAX_WALLS):
        hits = pb.rayTestBatch(frm, to, numThreads=1, reportHitNumber=level, collisionFilterMask=w.STATIC_RAY_MASK,
                               fractionEpsilon=1e-4, physicsClientId=w.cid)
        counts += np.array([h[0] >= 0 for h in hits])
    return counts


def test_wall_counts_from_the_walls_scene_are_those_of_the_full_scene() -> None:
    """The radio's wall counts, cast in the scene of static bodies only, are those of casting every ray in the full
    scene among the robots: crates at angles, pillars, a partition lower than any antenna, an obstacle on a path,
    robots of two heights, over time."""
    obstacles = [{"type": "box", "x": 3.0, "y": 3.0, "size": [1.2, 0.8, 0.6], "yaw_deg": 30},
                 {"type": "box", "x": 6.5, "y": 6.0, "size": [3.0, 0.15, 0.05]},
                 {"type": "cylinder", "x": 2.0, "y": 7.0, "radius": 0.3},
                 {"type": "box", "x": 5.0, "y": 1.0, "size": [0.6, 0.6, 0.5],
                  "motion": {"waypoints": [[3.0, 5.0, 8.0]], "repeat": False}}]
    robots = [{"count": 14, "placement": {"kind": "random", "region": [0.5, 0.5, 9.5, 9.5], "min_separation_m": 0.5}},
              {"profile": "sonpi", "count": 6,
               "placement": {"kind": "random", "region": [0.5, 0.5, 9.5, 9.5], "min_separation_m": 0.5}}]
    w = world(arena={"width_m": 10, "length_m": 10}, obstacles=obstacles, robots=robots, session={"seed": 3})
    q = 10_000_000
    try:
        assert pb.getNumBodies(physicsClientId=w.walls_cid) == 1 + 4 + 4  # floor, arena walls, obstacles: no robot
        crossed = 0
        for k in range(300):
            w.step_quantum(k * q, q)
            if k % 50 == 49:
                for src in range(w.n):
                    every = _walls_by_every_ray(w, src).tolist()
                    pair = [(src + 7) % w.n, (src + 3) % w.n]  # one exchange's pair first, then a whole broadcast
                    assert w.walls(src, np.array(pair)).tolist() == [every[d] for d in pair]
                    got = w.walls(src, np.arange(w.n))
                    assert got.tolist() == every
                    crossed += int((got > 0).sum())
        assert crossed > 0
    finally:
        w.close()


def test_a_ray_grazing_a_corner_counts_the_same_in_both_scenes() -> None:
    """A ray that passes a crate's corner within Bullet's contact threshold hits it in the full scene (whose bounding
    boxes a physics step grows by that threshold); the walls scene must count it too (a case met at 50 robots)."""
    crate = {"type": "box", "x": 1.5, "y": 13.0, "size": [0.8, 0.8, 0.6]}
    robots = [{"count": 2, "placement": {"kind": "explicit", "poses": [[1.2, 14.3, 0], [4.6, 10.0, 0]]}}]
    w = world(arena={"width_m": 10, "length_m": 20}, obstacles=[crate], robots=robots)
    try:
        w.step_quantum(0, 10_000_000)
        w.pos = np.array([[1.2029111281102864, 14.269854860451373], [4.646179552547476, 9.974670034576127]])
        w._walls_rows.clear()
        assert _walls_by_every_ray(w, 0).tolist() == [0, 1]
        assert w.walls(0, np.array([1])).tolist() == [1]
    finally:
        w.close()
