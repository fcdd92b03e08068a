"""The Zebro's accelerometer in the world (the BNO055's, on its IMU part): gravity's reaction up at rest, the body's
acceleration forward as it starts walking, in the chip's axes; seeded errors in the realistic mode, none in the
faithful one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.core.world import World
from tests.robots.test_decizebro_legs import Q, walk


def zebro_world(sensing: str, yaw_deg: float = 30.0, seed: int = 1) -> World:
    c = Config.model_validate({"session": {"seed": seed}, "arena": {"width_m": 20, "length_m": 20}, "robots": [
        {"profile": "decizebro", "count": 1, "sensing": sensing,
         "placement": {"kind": "explicit", "poses": [[5.0, 10.0, yaw_deg]]}}]})
    return World(c, make_plan(c).robots)


def accel(w: World) -> np.ndarray:
    return np.array(w.model("imu").sense(0)["accel_mps2"])


def test_at_rest_it_reads_gravity_up_and_starting_to_walk_forward() -> None:
    w = zebro_world("faithful")
    t = 0
    for _ in range(30):  # settle
        w.step_quantum(t, Q)
        t += Q
    assert accel(w) == pytest.approx([0.0, 0.0, 9.81], abs=0.05)
    assert w.model("imu").sense(0)["gravity_mps2"] == pytest.approx([0.0, 0.0, 9.81], abs=0.05)
    omega = 2 * math.pi  # 60 rpm
    peak = 0.0
    for _ in range(20):  # the first 0.2 s of a tripod: the body speeds up forward (x), whatever its yaw
        t = walk(w, 0.01, (omega, omega), t)
        peak = max(peak, float(accel(w)[0]))
    assert peak > 0.3
    t = walk(w, 3.0, (omega, omega), t)  # at speed: forward acceleration back near zero on average
    xs = []
    for _ in range(50):
        t = walk(w, 0.01, (omega, omega), t)
        xs.append(accel(w)[0])
    assert abs(float(np.mean(xs))) < 0.3


def test_the_realistic_accelerometer_has_a_seeded_offset_and_noise() -> None:
    reads = []
    for _ in range(2):
        w = zebro_world("realistic", seed=4)
        t = 0
        out = []
        for _ in range(40):
            w.step_quantum(t, Q)
            t += Q
            out.append(accel(w))
        reads.append(np.array(out[10:]))
    assert np.array_equal(reads[0], reads[1])  # same seed, same readings
    a = reads[0]
    assert a.std(axis=0) == pytest.approx([0.012] * 3, rel=0.6)  # white noise
    assert float(np.abs(a.mean(axis=0) - [0.0, 0.0, 9.81]).max()) < 0.25  # a small offset
    assert not np.allclose(a.mean(axis=0), [0.0, 0.0, 9.81], atol=0.005)
