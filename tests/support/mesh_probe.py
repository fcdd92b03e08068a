"""Robot programs for the mesh routing session test: one robot unicasts to another at the far end of a line, each
transmit status logged (delivery, retries, discovery); the far robot logs what reaches it."""

from __future__ import annotations

from typing import Any, ClassVar

from swarm_logic.controller import Controller
from swarm_logic.drivers.xbee import XBeeTimeout

SERIAL_BASE = 0x0013A200_40A00000  # a session robot's XBee serial number is this plus its id


class MeshSender(Controller):
    """Once joined, sends ``m<seq>`` to robot ``to`` and waits for its status, one after the other."""

    period_s = 1.0
    defaults: ClassVar[dict[str, Any]] = {"to": 5}

    def init(self, robot) -> None:
        super().init(robot)
        self.p = self.with_defaults(robot.params)
        self.seq = 0

    def step(self) -> None:
        xb = self.robot.xbee
        if xb.at("AI", timeout=1.0)[0] != 0:
            return
        self.seq += 1
        try:
            st = xb.send(SERIAL_BASE + int(self.p["to"]), b"m%d" % self.seq, timeout=30.0)
        except XBeeTimeout:
            self.robot.log("mesh_tx", seq=self.seq, status=-1, retries=-1, discovery=-1)
            return
        self.robot.log("mesh_tx", seq=self.seq, status=st.status, retries=st.retries, discovery=st.discovery)


class MeshSink(Controller):
    """Logs every packet that reaches it."""

    period_s = 0.5

    def step(self) -> None:
        while (pkt := self.robot.xbee.recv(timeout=0)) is not None:
            self.robot.log("mesh_rx", data=pkt.data.decode(errors="replace"), src64=pkt.src64)
