"""The thesis' radio survey (Couceiro 2013, section 3.2.3, Fig. 3.7): two robots wander among obstacles while
one sends the other a message every ``interval_s`` seconds; what arrives, and at which RSSI, is measured.

Both robots random-walk. The receiver (odd id) announces itself with a broadcast every ``announce_s``; the
sender (even id) learns its address from the first announcement it hears and from then on sends it one
unicast packet per interval, with the MAC's acknowledgement and retries (802.15.4) but, on Series 2, without
the ZigBee APS retries (``aps_retries = 0``), which would re-send it up to twice more, 1.6 s apart: the thesis
counts packets that arrive at each distance, not eventual deliveries. The receiver keeps what it gets; the
session's recording holds both ends, which ``swarm-sitl radio-survey`` turns into a CSV and a plot.
"""

from __future__ import annotations

import struct
from typing import ClassVar

from swarm_logic.families.demo.random_walk import RandomWalk
from swarm_logic.robot import Robot

ANNOUNCE = b"SURVEY-RX"


class RadioSurvey(RandomWalk):
    defaults: ClassVar[dict[str, float]] = {**RandomWalk.defaults, "interval_s": 2.0, "announce_s": 5.0,
                                            "aps_retries": 0}
    ranges: ClassVar[dict[str, str]] = {**RandomWalk.ranges, "interval_s": "(0, inf)", "announce_s": "(0, inf)",
                                        "aps_retries": "[0, 1]"}  # 1: the ZigBee APS retries on (Series 2)

    def init(self, robot: Robot) -> None:
        if robot.xbee is None:
            raise ValueError("radio_survey needs an XBee (robots.xbee in the session config)")
        self.sender = robot.id % 2 == 0
        self.peer64: int | None = None
        self.seq = 0
        self.received = 0
        self.next_radio = 0.0
        super().init(robot)
        self.next_radio = robot.clock.now()

    def step(self) -> None:
        super().step()
        r = self.robot
        x = r.xbee
        while (pkt := x.recv(timeout=0)) is not None:
            if self.sender and pkt.data == ANNOUNCE and self.peer64 is None:
                self.peer64 = pkt.src64
            elif not self.sender and pkt.data.startswith(b"S"):
                self.received += 1
        now = r.clock.now()
        if now < self.next_radio:
            return
        if self.sender:
            self.next_radio += self.p["interval_s"]
            if self.peer64 is not None:
                self.seq += 1
                opts = 0x01 if x.series == 2 and not self.p["aps_retries"] else 0  # 0x01: no APS retries
                x.send_nowait(self.peer64, b"S" + struct.pack("<I", self.seq), options=opts)
        else:
            self.next_radio += self.p["announce_s"]
            x.send_nowait(None, ANNOUNCE, radius=1)
