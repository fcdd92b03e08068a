"""The foot-bot in the world: who hears whom on the range-and-bearing link (range, walls and bodies in the line of
sight, the bearing's sign, the noise and loss options, the seed), and what the base board's sensors read (ARGoS's
proximity curve, the floor's grey, the light's direction)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bridge.core.config import Config, ConfigError
from bridge.core.plan import make_plan
from bridge.core.world import World
from bridge.robots.footbot.sensors import argos_proximity
from swarm_logic.robots.footbot.interfaces import ring_angles
from tests.core.test_session import run as session_run

RADIUS = 0.085


def footbots(poses: list[list[float]], seed: int = 1, obstacles: list[dict] | None = None,
             **extra: Any) -> World:
    """A 10 x 10 m arena with foot-bots at ``poses`` ([x, y, yaw_deg]); ``extra``: the group's options and the
    config's other sections (``arena``, ``light``)."""
    sections = {k: extra.pop(k) for k in ("arena", "light") if k in extra}
    c = Config.model_validate({
        "session": {"seed": seed}, "arena": {"width_m": 10, "length_m": 10, **sections.pop("arena", {})},
        **sections, "obstacles": obstacles or [],
        "robots": [{"profile": "footbot", "count": len(poses), **extra,
                    "placement": {"kind": "explicit", "poses": poses}}]})
    return World(c, make_plan(c).robots)


def heard_by(w: World, src: int) -> dict[int, tuple[float, float]]:
    heard, _, _ = w.model("range_and_bearing").receivers(src)
    return {d: (r, b) for d, r, b in heard}


# -- range and line of sight -------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("options", "range_m"), [({}, 3.0), ({"rab_range_m": 1.0}, 1.0)])
def test_the_board_hears_within_its_range_and_not_beyond(options: dict, range_m: float) -> None:
    w = footbots([[2.0, 5.0, 0.0], [2.0 + range_m - 0.05, 5.0, 0.0], [2.0, 5.0 + range_m + 0.05, 0.0]], **options)
    assert set(heard_by(w, 0)) == {1}
    assert heard_by(w, 0)[1][0] == pytest.approx(range_m - 0.05)  # no noise by default: the true range
    assert set(heard_by(w, 2)) == set()


def test_a_wall_between_two_foot_bots_occludes_them() -> None:
    wall = {"type": "box", "x": 5.0, "y": 5.0, "size": [0.05, 0.6, 0.5]}
    w = footbots([[4.0, 5.0, 0.0], [6.0, 5.0, 0.0], [4.0, 6.0, 0.0], [6.0, 6.0, 0.0]], obstacles=[wall])
    heard, occluded, lost = w.model("range_and_bearing").receivers(0)
    assert {d for d, _, _ in heard} == {2, 3} and occluded == [1] and lost == []  # the pair at y = 6 passes above it
    assert 0 not in heard_by(w, 1)  # both ways


def test_a_low_box_under_the_boards_height_does_not_occlude() -> None:
    low = {"type": "box", "x": 5.0, "y": 5.0, "size": [0.05, 0.6, 0.05]}  # ARGoS: things below 0.1 m let the IR by
    w = footbots([[4.0, 5.0, 0.0], [6.0, 5.0, 0.0]], obstacles=[low])
    assert set(heard_by(w, 0)) == {1}


def test_a_third_foot_bot_on_the_line_of_sight_occludes() -> None:
    w = footbots([[3.0, 5.0, 0.0], [4.0, 5.0, 0.0], [5.0, 5.0, 0.0]])
    heard, occluded, _ = w.model("range_and_bearing").receivers(0)
    assert [d for d, _, _ in heard] == [1] and occluded == [2]
    assert set(heard_by(w, 1)) == {0, 2}
    w2 = footbots([[3.0, 5.0, 0.0], [4.0, 5.0 + 2 * RADIUS + 0.01, 0.0], [5.0, 5.0, 0.0]])  # moved off the line
    assert set(heard_by(w2, 0)) == {1, 2}


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, -135.0, 180.0])
def test_the_bearing_is_positive_to_the_left_in_the_receivers_frame(yaw_deg: float) -> None:
    """The receiver at (5, 5) heading ``yaw_deg``; senders straight ahead, to its left, behind, to its right."""
    yaw = math.radians(yaw_deg)
    rel = {1: 0.0, 2: math.pi / 2, 3: math.pi, 4: -math.pi / 2, 5: math.radians(30)}
    poses = [[5.0, 5.0, yaw_deg]] + [[5.0 + 1.5 * math.cos(yaw + a), 5.0 + 1.5 * math.sin(yaw + a), 0.0]
                                     for a in rel.values()]
    w = footbots(poses)
    for src, a in rel.items():
        r, b = heard_by(w, src)[0]
        assert r == pytest.approx(1.5, abs=1e-6)
        assert math.remainder(b - a, math.tau) == pytest.approx(0.0, abs=1e-6)
        assert -math.pi <= b <= math.pi


# -- noise, loss, seed ------------------------------------------------------------------------------------------------


def draws(seed: int, n: int = 3000, **options: Any) -> tuple[np.ndarray, np.ndarray, int]:
    """Robot 1's measurements of ``n`` emissions of robot 0, 2 m straight ahead: range errors (relative), bearing
    errors (deg), and how many it lost."""
    w = footbots([[5.0, 5.0, 0.0], [3.0, 5.0, 0.0]], seed=seed, **options)
    links = w.model("range_and_bearing")
    rng, brg, lost = [], [], 0
    for _ in range(n):
        heard, _, gone = links.receivers(0)
        lost += len(gone)
        for _, r, b in heard:
            rng.append(r / 2.0 - 1.0)
            brg.append(math.degrees(b))
    return np.array(rng), np.array(brg), lost


def test_without_options_the_link_is_exact() -> None:
    rng, brg, lost = draws(1, n=50)
    assert np.all(np.abs(rng) < 1e-12) and np.all(np.abs(brg) < 1e-9) and lost == 0


def test_range_and_bearing_errors_have_the_std_asked() -> None:
    rng, brg, lost = draws(2, rab_range_noise_rel=0.05, rab_bearing_noise_deg=4.0)
    assert lost == 0 and len(rng) == 3000
    assert rng.std() == pytest.approx(0.05, rel=0.08) and abs(rng.mean()) < 0.005
    assert brg.std() == pytest.approx(4.0, rel=0.08) and abs(brg.mean()) < 0.4


def test_the_loss_option_drops_about_that_share_of_receptions() -> None:
    rng, _, lost = draws(3, rab_loss=0.3)
    assert lost / 3000 == pytest.approx(0.3, abs=0.03) and len(rng) + lost == 3000


def test_the_same_seed_draws_the_same_errors() -> None:
    opts = {"rab_range_noise_rel": 0.05, "rab_bearing_noise_deg": 4.0, "rab_loss": 0.2}
    a, b = draws(7, n=200, **opts), draws(7, n=200, **opts)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2]
    c = draws(8, n=200, **opts)
    assert not np.array_equal(a[0][:100], c[0][:100])


@pytest.mark.parametrize("options", [{"rab_loss": 1.5}, {"rab_range_m": 0.0}, {"rab_bearing_noise_deg": -1},
                                     {"rab_rang_m": 2.0}])
def test_bad_options_are_refused(options: dict) -> None:
    with pytest.raises((ConfigError, ValueError)):
        footbots([[5.0, 5.0, 0.0]], **options)


# -- the base board's sensors -----------------------------------------------------------------------------------------


def sample(w: World) -> dict[str, list[float]]:
    w.step_quantum(0, 10_000_000)
    return w.model("footbot_sensors").take_new(0)


def surface_to_wall(gap: float, angle: float) -> float:
    """How far a sensor at ``angle`` on the body's rim sees a wall ahead of the body by ``gap``, along its ray."""
    return (RADIUS + gap - RADIUS * math.cos(angle)) / math.cos(angle) if math.cos(angle) > 0 else math.inf


@pytest.mark.parametrize("gap", [0.005, 0.02, 0.05, 0.08])
def test_facing_a_wall_the_proximity_ring_reads_argos_curve(gap: float) -> None:
    """The east wall's inner face is at x = 10; the robot faces it ``gap`` from its body."""
    w = footbots([[10.0 - RADIUS - gap, 5.0, 0.0]])
    prox = sample(w)["proximity"]
    angles = ring_angles(24)
    for k, a in enumerate(angles):
        d = surface_to_wall(gap, math.remainder(a, math.tau))
        want = float(argos_proximity(np.array([d]), np.array([d < 0.1]))[0])
        assert prox[k] == pytest.approx(want, rel=0.02, abs=1e-6), (k, d)
    assert prox[0] == max(prox) and prox[0] == pytest.approx(min(1.0, 0.0100527 / (gap + 0.000163144)), rel=0.02)
    assert prox[12] == 0.0  # the back sees nothing


def test_with_nothing_within_10_cm_the_proximity_ring_reads_0() -> None:
    w = footbots([[10.0 - RADIUS - 0.105, 5.0, 0.0], [5.0, 5.0, 0.0]])
    assert sample(w)["proximity"] == [0.0] * 24


def test_the_ground_sensors_read_the_floor_patch_under_them() -> None:
    patch = {"floor": [{"x_min": 0.0, "y_min": 0.0, "x_max": 3.0, "y_max": 10.0, "grey": 0.5}]}
    w = footbots([[1.5, 5.0, 0.0], [3.0, 2.0, 0.0], [3.0, 8.0, 180.0], [6.0, 5.0, 0.0]], arena=patch)
    w.step_quantum(0, 10_000_000)
    s = w.model("footbot_sensors")
    assert [s.take_new(r)["ground"] for r in range(4)] == [
        [0.5] * 4,
        [1.0, 0.5, 0.5, 1.0],  # its front sensors (x = +6.3 cm) beyond the patch's edge
        [0.5, 1.0, 1.0, 0.5],  # facing back onto the patch
        [1.0] * 4]


def test_the_base_ground_sensors_read_black_or_white() -> None:
    """The 8 black-or-white sensors on their 8 cm ring: 0 on a dark patch (grey < 0.5), 1 on the white floor."""
    patch = {"floor": [{"x_min": 0.0, "y_min": 0.0, "x_max": 3.0, "y_max": 10.0, "grey": 0.2}]}
    w = footbots([[3.0, 5.0, 0.0], [3.0, 2.0, 90.0], [6.0, 5.0, 0.0]], arena=patch)
    w.step_quantum(0, 10_000_000)
    s = w.model("footbot_sensors")
    # straddling the edge facing east: the sensors ahead (0, +-45 deg) on white, those behind on the patch; sensors
    # 2 and 6 (+-90 deg) sit on the edge (x = 3.0: white, the patch ends before it)
    assert s.take_new(0)["base_ground"] == [1, 1, 1, 0, 0, 0, 1, 1]
    assert s.take_new(1)["base_ground"] == [1, 0, 0, 0, 1, 1, 1, 1]  # facing north: its left side on the patch
    assert s.take_new(2)["base_ground"] == [1] * 8


@pytest.mark.parametrize("yaw_deg", [0.0, 60.0, 200.0])
@pytest.mark.parametrize(("lx", "ly"), [(7.0, 5.0), (3.0, 7.0), (4.0, 2.0)])
def test_the_light_ring_points_to_the_light(yaw_deg: float, lx: float, ly: float) -> None:
    light = {"ambient_lux": 0.0, "sources": [{"x": lx, "y": ly, "peak_lux": 1000.0, "sigma_m": 5.0}]}
    w = footbots([[5.0, 5.0, yaw_deg]], light=light)
    values = sample(w)["light"]
    angles = ring_angles(24)
    bearing = math.atan2(ly - 5.0, lx - 5.0) - math.radians(yaw_deg)
    k = int(np.argmax(values))
    assert abs(math.remainder(angles[k] - bearing, math.tau)) <= math.radians(7.5) + 1e-9
    back = int(np.argmin([abs(math.remainder(a - bearing - math.pi, math.tau)) for a in angles]))
    assert values[back] == 0.0 and 0 < values[k] <= 1.0


# -- a session ------------------------------------------------------------------------------------------------------

SESSION = """[session]
duration_s = 3.0
seed = 3
[arena]
width_m = 3.0
length_m = 3.0
[[arena.floor]]
x_min = 0.0
y_min = 0.0
x_max = 1.0
y_max = 3.0
grey = 0.5
[light]
ambient_lux = 0.0
[[light.sources]]
x = 0.5
y = 1.5
peak_lux = 1000.0
sigma_m = 5.0
[[robots]]
profile = "footbot"
behaviour = "pfsm_searcher"
placement = { kind = "explicit", poses = [[0.5, 1.5, 0.0]] }
[[robots]]
profile = "footbot"
behaviour = "pfsm_target"
placement = { kind = "explicit", poses = [[1.5, 1.5, 180.0]] }
"""


@pytest.mark.session
def test_a_searcher_and_a_target_talk_over_their_boards_in_a_session(tmp_path: Path) -> None:
    cfg = tmp_path / "footbots.toml"
    cfg.write_text(SESSION)
    code, s = session_run(cfg, tmp_path / "run")
    assert code == 0
    rab = s["radio"]["rab"]
    assert rab["robots"] == 2 and rab["emitted"] > 0 and rab["received"] > 0
    per = s["per_robot"]
    assert all(p["rab"]["received"] > 0 for p in per)
    json.dumps(s)  # the summary is plain JSON
