"""A robot's I2C bus on a pseudo-terminal, through an emulated Devantech USB-ISS adapter: a program outside the
session opens the terminal as it would open the adapter's ``/dev/ttyACM0`` and drives the robot's I2C devices with
the adapter's commands (``swarm_logic.drivers.usb_iss`` gives it an ``smbus2.SMBus`` over them).

The adapter is a firmware entity of role ``i2c_adapter`` (``bridge.media.i2c.ADAPTER``) beside the robot's modules: a
master on the robot's I2C medium, as the robot program is. Each quantum it reads what arrived on its terminal, puts
the next transaction of the command it is working on on the bus (timed there at the mode's SCL rate, recorded on
``/rNNN/i2c``, counted with the bus's), and writes the answers back once the transactions have ended. The
adapter's protocol is ``firmware_sim.modules.usb_iss``; its counters are the entity's (``summary.json``:
``per_robot[].firmware.i2c_adapter``).
"""

from __future__ import annotations

from typing import Any

from bridge.hosts.firmware import PtyLink
from firmware_sim.modules.usb_iss import UsbIss


class UsbIssEntity:
    """The adapter on robot ``robot``'s bus, its USB side linked at ``link`` (``what``: the option that asked, for
    errors)."""

    def __init__(self, robot: int, link: str, what: str = "i2c_pty") -> None:
        self.module = UsbIss(serial=f"{robot % 100_000_000:08d}")
        self.link = PtyLink(link, what)
        self.seq = 0
        self.waiting: int | None = None  # the number of the transaction on the bus

    @property
    def counters(self) -> dict[str, int]:
        return {**self.module.counters, "pty_dropped_bytes": self.link.dropped}

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        for item in inputs["in"]:
            if item[0] != "i2c" or len(item) != 2:
                continue
            try:
                seq, errno, reads, _end = item[1]
            except (TypeError, ValueError):
                continue
            if seq == self.waiting:
                self.waiting = None
                self.module.on_result(int(errno), [bytes(b) for b in reads])
        self.module.feed(t_ns, self.link.read())
        out: list[list] = []
        if self.waiting is None and (txn := self.module.poll(t_ns)) is not None:
            self.seq += 1
            self.waiting = self.seq
            out.append(["i2c", self.seq, txn, self.module.scl_hz])
        if data := self.module.take_output():
            self.link.write(data)
        return {"out": out, "wake": t_ns + 1, "wom": True}  # the terminal is polled every quantum

    def close(self) -> None:
        self.link.close()
