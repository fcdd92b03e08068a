"""A tiny Zebro behaviour for the radio's session tests: each step it broadcasts its id and a counter over the UWB
radio (``burst`` frames), then logs what it received, whom it ranges and its IMU heading; with ``garbage`` it first
writes junk and a broken frame to the module."""

from __future__ import annotations

import math
import struct
from typing import Any, ClassVar

from swarm_logic.controller import Controller


class Chatter(Controller):
    """Talks over ``robot.device("uwb_radio")`` and logs ``chatter`` records."""

    defaults: ClassVar[dict[str, Any]] = {"burst": 1, "period_s": 0.25, "radio": 1, "garbage": 0}
    ranges: ClassVar[dict[str, str]] = {"burst": "[0, 64]", "period_s": "(0, 10]", "radio": "[0, 1]",
                                        "garbage": "[0, 1]"}

    def init(self, robot: Any) -> None:
        super().init(robot)
        self.p = self.with_defaults(robot.params)
        self.period_s = self.p["period_s"]
        self.radio = robot.device("uwb_radio") if self.p["radio"] else None  # 0: its radio is on a pty
        self.imu = robot.device("imu")
        self.k = 0
        if self.radio is not None and self.p["garbage"]:  # junk, then a frame with a broken CRC
            self.radio.port.write(b"junk" + bytes((0xA5, 1, 0x01, 0x00, 0x00)))

    def step(self) -> None:
        if self.radio is None:
            self.robot.log("chatter", t=self.robot.clock.now(), heading=round(math.degrees(self.imu.heading()), 2))
            return
        sent = 0
        for _ in range(self.p["burst"]):
            if not self.radio.broadcast(struct.pack("<HI", self.robot.id, self.k)):
                break
            sent += 1
            self.k += 1
        got = [[m.src, struct.unpack_from("<HI", m.data)[1]] for m in self.radio.receive()]
        nbs = [[n.id, round(n.range_m, 3), round(math.degrees(n.bearing_rad), 2),
                None if n.heading_rad is None else round(math.degrees(n.heading_rad), 2)]
               for n in self.radio.neighbours()]
        self.robot.log("chatter", t=self.robot.clock.now(), sent=sent, got=got, nbs=nbs,
                       heading=round(math.degrees(self.imu.heading()), 2))
