"""The DeciZebro's contact-level body (``body = "contact"``): a box on six jointed C-legs whose DC motors the leg
modules drive; walking emerges from the legs pushing on the floor. A tripod walks forward at the Zebro's speed, legs
faster on one side turn it, a leg that stops changes its path, a dead robot's legs go limp and it stops, the same
seed walks the same way, and the option is checked."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import Config, ConfigError, load_config
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from bridge.core.world import World
from bridge.robots.decizebro.contact_legs import CONTACT_LEGS, ContactLegs
from bridge.robots.decizebro.legs import LEFT

Q = 10_000_000
WALK = 2 * math.pi  # 60 rpm: the locomotion layer's walking speed (0.31 m/s for the gait-level model)


def zebro_world(seed: int = 1, **options: object) -> World:
    c = Config.model_validate({"session": {"seed": seed}, "arena": {"width_m": 20, "length_m": 20}, "robots": [
        {"profile": "decizebro", "count": 1, "body": "contact", **options,
         "placement": {"kind": "explicit", "poses": [[5.0, 10.0, 0.0]]}}]})
    return World(c, make_plan(c).robots)


class Tripod:
    """Holds a tripod gait (0-2-4 and 1-3-5 half a turn apart) at the given left/right leg speeds, each leg on a PD of
    its phase as a leg module's loop would; ``stopped`` legs get no duty. ``turned`` is the heading's change, unwrapped
    quantum by quantum."""

    def __init__(self, w: World) -> None:
        self.w, self.legs, self.t, self.turned = w, w.model("contact_legs"), 0, 0.0
        self.phase = np.array([0.0, math.pi] * 3)

    def run(self, seconds: float, speed: tuple[float, float], stopped: tuple[int, ...] = ()) -> None:
        legs = self.legs
        for _ in range(round(seconds * 1e9 / Q)):
            for leg in range(6):
                s = speed[0] if leg in LEFT else speed[1]
                self.phase[leg] += s * Q / 1e9
                err = math.remainder(self.phase[leg] - legs.angle(0, leg), 2 * math.pi)
                duty = 0.0 if leg in stopped else s / legs.w_max[0] / 1.15 + 0.6 * err
                legs.set_duty(0, leg, duty)
            yaw = float(self.w.yaw[0])
            self.w.step_quantum(self.t, Q)
            self.turned += math.remainder(float(self.w.yaw[0]) - yaw, 2 * math.pi)
            self.t += Q


def test_a_tripod_walks_forward_at_the_zebros_speed_on_its_legs() -> None:
    w = zebro_world()
    assert isinstance(w.model("contact_legs"), ContactLegs) and w.model("legs") is None
    gait = Tripod(w)
    gait.run(1.0, (0.0, 0.0))  # the second tripod turns to its phase
    gait.run(2.0, (WALK, WALK))
    x0, heading = w.pos[0].copy(), np.zeros(2)
    for _ in range(50):
        gait.run(0.1, (WALK, WALK))
        heading += np.cos(w.yaw[0]), np.sin(w.yaw[0])
    step = w.pos[0] - x0
    assert 0.28 < float(np.hypot(*step)) / 5.0 < 0.56  # 1-2 km/h (appendix B.3)
    # forward: along its mean heading (it wanders as its legs slip)
    assert step @ heading / np.hypot(*heading) > 0.9 * float(np.hypot(*step))
    s = w.sensors(0)
    assert len(s["leg_angles"]) == 6 and all(0 <= a < 2 * math.pi for a in s["leg_angles"])
    assert all(abs(o - WALK) < 3.0 for o in s["leg_omegas"])


@pytest.mark.parametrize(("speeds", "sign"), [((3.0, 9.0), 1), ((9.0, 3.0), -1)])
def test_legs_faster_on_one_side_turn_it_towards_the_slower_side(speeds: tuple[float, float], sign: int) -> None:
    w = zebro_world()
    gait = Tripod(w)
    gait.run(1.0, (0.0, 0.0))
    gait.turned = 0.0
    gait.run(3.0, speeds)
    # the sides' rim speeds, 0.15 and 0.45 m/s, over the 0.25 m between the legs: about 1.2 rad/s
    assert sign * gait.turned > 1.5


def test_a_leg_that_stops_is_dragged_and_changes_the_path() -> None:
    paths = []
    for stopped in ((), (1,)):  # the left middle leg's motor off
        w = zebro_world()
        gait = Tripod(w)
        gait.run(1.0, (0.0, 0.0))
        gait.run(5.0, (WALK, WALK), stopped)
        paths.append((w.pos[0].copy(), float(w.yaw[0]), w.model("contact_legs").rate[0, 1]))
    (p_all, _, _), (p_five, _, w_stopped) = paths
    assert math.dist(p_all, p_five) > 0.3
    assert abs(w_stopped) < 2.0  # the stopped leg turns only as the floor drags it


def test_legs_draw_current_and_a_dead_robots_legs_go_limp_and_it_stops() -> None:
    idle, w = zebro_world(), zebro_world()
    Tripod(idle).run(3.0, (0.0, 0.0))
    gait = Tripod(w)
    gait.run(3.0, (WALK, WALK))
    assert w.soc[0] < idle.soc[0] < 1.0
    legs = w.model("contact_legs")
    w.kill(0)
    legs.set_duty(0, 0, 1.0)
    assert not legs.duty[0].any()
    gait.run(1.5, (WALK, WALK))  # it sinks onto its belly
    assert not legs._tau[0].any()  # the H-bridges are off: no torque at all
    x0 = w.pos[0].copy()
    gait.run(2.0, (WALK, WALK))
    assert math.dist(w.pos[0], x0) < 0.02


def test_the_same_seed_walks_the_same_way_and_the_legs_slip_differently_per_robot() -> None:
    runs = []
    for seed in (3, 3, 4):
        w = zebro_world(seed)
        gait = Tripod(w)
        gait.run(3.0, (WALK, WALK))
        runs.append((w.pos[0].copy(), w.yaw[0], w.model("contact_legs").traction[0].copy()))
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]
    assert not np.array_equal(runs[0][2], runs[2][2])


def test_a_part_may_ask_for_a_finer_physics_step() -> None:
    w = zebro_world()
    assert w.hz == 240.0  # the session's: the contact legs walk at it
    from bridge.robots.decizebro import radio

    finer = CONTACT_LEGS.model_copy(update={"min_physics_hz": 480.0})
    old = radio.CONTACT_LEGS
    radio.CONTACT_LEGS = finer
    try:
        assert zebro_world().hz == 480.0
    finally:
        radio.CONTACT_LEGS = old


def test_the_body_option_is_checked(tmp_path: Path) -> None:
    p = tmp_path / "zebros.toml"
    p.write_text('[[robots]]\nprofile = "decizebro"\ncount = 2\nbody = "wheels"\n')
    with pytest.raises(ConfigError, match=r"robots\[0\].body: Input should be 'gait' or 'contact'"):
        load_config(p)
    p.write_text('[[robots]]\nprofile = "decizebro"\ncount = 2\nbody = "contact"\n')
    assert load_config(p).robots[0].model_extra == {"body": "contact"}


SESSION = """
[session]
name = "zebro-contact"
duration_s = 8
seed = 4

[arena]
width_m = 8
length_m = 8

[[robots]]
count = 1
profile = "decizebro"
body = "contact"
behaviour = "tests.support.zebro_walkers:Walker"
placement = { kind = "explicit", poses = [[1.5, 2.0, 0.0]] }

[[robots]]
count = 1
profile = "decizebro"
behaviour = "tests.support.zebro_walkers:Walker"
placement = { kind = "explicit", poses = [[1.5, 5.0, 0.0]] }
"""


@pytest.mark.session
def test_in_a_session_the_locomotion_layer_walks_a_contact_zebro_beside_a_gait_level_one(tmp_path: Path) -> None:
    from tests.robots.test_zebro_bus_session import legs, run

    cfg = tmp_path / "zebro.toml"
    cfg.write_text(SESSION)
    s = run(cfg, tmp_path / "a")
    assert run(cfg, tmp_path / "b")["digest"] == s["digest"]  # the same seed: the same session, byte for byte
    contact, gait = s["per_robot"]
    assert not s["failures"]
    for rob in (contact, gait):
        assert all(c["estops"] == 0 and c["errors"] == 0 for c in legs(rob).values())
    # the locomotion layer's tripod at 60 rpm walks it forward at 1-2 km/h once its legs have found their gait (its
    # heading wanders as they slip: nothing steers it)
    poses = [(t, p["x"][0], p["y"][0], p["yaw"][0]) for topic, t, p in
             ((topic, t, json.loads(d)) for topic, t, d in iter_messages(tmp_path / "a" / "session.mcap")
              if topic == "/world/poses") if t % 500_000_000 == 0 and t >= 2_000_000_000]
    path = sum(math.dist(a[1:3], b[1:3]) for a, b in itertools.pairwise(poses))
    ahead = sum((b[1] - a[1]) * math.cos(a[3]) + (b[2] - a[2]) * math.sin(a[3]) for a, b in itertools.pairwise(poses))
    assert 0.28 < path / ((poses[-1][0] - poses[0][0]) / 1e9) < 0.56 and ahead > 0.9 * path
    assert gait["final_pose"][0] > 1.5 + 1.7
