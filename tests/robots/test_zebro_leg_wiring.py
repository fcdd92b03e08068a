"""What the DeciZebro plugin gets from the leg bus: six leg-module entities, their wiring to the legs' world model,
and the HAL table that puts the robot program on the simulated I2C bus."""

from __future__ import annotations

import math
from types import SimpleNamespace

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.core.world import World
from bridge.robots.decizebro import firmware
from bridge.robots.decizebro.wiring import LEG_WIRING
from firmware_sim.robots.decizebro.leg_module import LegModule

Q = 10_000_000


def test_six_leg_modules_at_their_addresses_with_serials_of_their_own() -> None:
    rp = SimpleNamespace(id=3, profile="decizebro", options=None)
    assert firmware.roles(rp) == ("leg0", "leg1", "leg2", "leg3", "leg4", "leg5")
    mods = firmware.modules(rp, None)
    assert [m.address for m in mods.values()] == [0x10, 0x11, 0x12, 0x13, 0x14, 0x15]
    assert all(isinstance(m, LegModule) and m.period_ns == Q for m in mods.values())  # the profile's 100 Hz
    assert len({m.vregs[0x04] for m in mods.values()}) == 6
    assert firmware.hal(rp, None) == {"legs": {"bus": "sitl://i2c", "scl_hz": 100_000}}


def test_the_wiring_reads_the_leg_and_drives_its_motor() -> None:
    c = Config.model_validate({"arena": {"width_m": 10, "length_m": 10}, "robots": [
        {"profile": "decizebro", "count": 1, "placement": {"kind": "explicit", "poses": [[5.0, 5.0, 0.0]]}}]})
    w = World(c, make_plan(c).robots)
    try:
        wiring = LEG_WIRING("leg4")
        assert LEG_WIRING("uwb") is None and LEG_WIRING("leg6") is None and LEG_WIRING("leg4") is wiring
        assert wiring.valid({"duty": 0.5}) and wiring.valid({"duty": -1})
        for bad in ({"duty": 1.5}, {"duty": math.nan}, {"duty": True}, {"duty": 0.1, "x": 1}, {}, None):
            assert not wiring.valid(bad)
        wiring.actuate(w, 0, {"duty": 0.6})
        t = 0
        for _ in range(50):
            w.step_quantum(t, Q)
            t += Q
        sent, recorded = wiring.sense(w, 0, {}, False)
        assert sent is recorded and set(sent) == {"angle", "omega", "battery_v"}
        assert sent["omega"] > 0.5 * 0.6 * 17.8 and 0 < sent["angle"] < 2 * math.pi and sent["battery_v"] > 12
        assert LEG_WIRING("leg0").sense(w, 0, {}, False)[0]["omega"] == 0.0  # only leg 4 was driven
    finally:
        w.close()
