"""The DeciZebro's body in the world: a box on six C-legs; walking emerges from the legs' phases (tripod: straight
at the rim speed of the legs in stance; one side slower: it turns; legs turned backwards: it walks backwards), the
legs draw from the battery, a dead robot's legs stop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.core.world import World
from bridge.robots.decizebro.legs import LEFT

Q = 10_000_000


def zebro_world(yaw_deg: float = 0.0) -> World:
    c = Config.model_validate({"arena": {"width_m": 20, "length_m": 20}, "robots": [
        {"profile": "decizebro", "count": 1,
         "placement": {"kind": "explicit", "poses": [[5.0, 10.0, yaw_deg]]}}]})
    return World(c, make_plan(c).robots)


def walk(w: World, seconds: float, speed_rad_s: tuple[float, float], t0: int = 0) -> int:
    """Hold a tripod gait at the given left/right leg speeds (a PD on each leg's phase, as a leg module would)."""
    legs = w.model("legs")
    phase = np.zeros(6)
    t = t0
    for _ in range(round(seconds * 1e9 / Q)):
        for leg in range(6):
            s = speed_rad_s[0] if leg in LEFT else speed_rad_s[1]
            offset = 0.0 if leg in (0, 2, 4) else math.pi  # tripods 0-2-4 and 1-3-5, half a turn apart
            target = s * t / 1e9 + offset
            err = math.remainder(target - legs.angle(0, leg), 2 * math.pi)
            legs.set_duty(0, leg, s / legs.w_max[0] / 1.15 + 0.6 * err)
            phase[leg] = target
        w.step_quantum(t, Q)
        t += Q
    return t


def test_a_tripod_gait_walks_straight_at_the_legs_rim_speed() -> None:
    w = zebro_world()
    omega = 60 * 2 * math.pi / 60  # 60 rpm
    t = walk(w, 2.0, (omega, omega))
    x0 = w.pos[0].copy()
    walk(w, 5.0, (omega, omega), t)
    v = math.dist(w.pos[0], x0) / 5.0
    assert v == pytest.approx(0.05 * omega, rel=0.15)  # 0.31 m/s: within the Zebro's 0.28-0.56 m/s
    # nearly straight: the legs' traction differs a little (they slip), so the heading drifts slowly
    assert abs(w.pos[0, 1] - 10.0) < 0.6 and abs(math.remainder(float(w.yaw[0]), 2 * math.pi)) < 0.6


def test_slower_legs_on_one_side_turn_it_and_backward_legs_walk_it_backwards() -> None:
    w = zebro_world()
    walk(w, 1.5, (4.0, 8.0))  # the right side faster: it turns left, about (0.4 - 0.2) / 0.21 rad/s
    assert 0.6 < float(w.yaw[0]) < 1.8
    w2 = zebro_world()
    walk(w2, 4.0, (-6.0, -6.0))
    assert w2.pos[0, 0] < 5.0 - 0.5  # the hardware can; the locomotion layer on the robot never asks for it


def test_legs_draw_current_and_a_dead_robots_legs_stop() -> None:
    idle, walking = zebro_world(), zebro_world()
    t = 0
    for _ in range(300):
        idle.step_quantum(t, Q)
        t += Q
    walk(walking, 3.0, (6.0, 6.0))
    assert walking.soc[0] < idle.soc[0] < 1.0
    legs = walking.model("legs")
    walking.kill(0)
    legs.set_duty(0, 0, 1.0)
    assert not legs.duty[0].any()
    s = walking.sensors(0)
    assert len(s["leg_angles"]) == 6 and all(0 <= a < 2 * math.pi for a in s["leg_angles"])
    assert s["sonar_m"] <= 0.30
