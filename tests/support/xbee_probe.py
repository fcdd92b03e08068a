"""What a host does with its XBee, written once and run against two implementations of the port: a SITL
``sitl://xbee`` port inside a robot program, and a pseudo-terminal opened from outside the session."""

from __future__ import annotations

from typing import Any, ClassVar

from swarm_logic.clock import Clock
from swarm_logic.controller import Controller
from swarm_logic.drivers.xbee import XBee
from swarm_logic.families.demo.random_walk import RandomWalk


def probe(xb: XBee, clock: Clock, peers64: list[int], patience_s: float | None = None) -> dict[str, Any]:
    """Identify the module, wait until it joined, unicast to the first peer, broadcast to all, collect echoes.
    ``patience_s``: how long any one wait may last, for a program on the wall clock (a loaded machine's session may
    lag); by default the simulated-time bounds a robot's program uses in a session. Every wait ends on its event."""
    at_s = patience_s or 1.0
    t0 = clock.now()
    while xb.at("AI", timeout=at_s)[0] != 0:  # Series 2: associated (joined) is AI = 0
        if clock.now() - t0 > (patience_s or 15):
            raise TimeoutError("module did not join")
        clock.sleep(0.2)
    info = xb.identify(timeout=at_s)
    res: dict[str, Any] = {
        "sh": xb.at("SH", timeout=at_s).hex(), "sl": xb.at("SL", timeout=at_s).hex(),
        "ni": xb.at("NI", timeout=at_s).decode(), "series": info.series}
    echoes: list[dict] = []

    def collect(n: int) -> None:
        deadline = clock.now() + (patience_s or 4.0)
        want = len(echoes) + n
        while clock.now() < deadline and len(echoes) < want:
            pkt = xb.recv(timeout=max(0.0, deadline - clock.now()))
            if pkt is not None and pkt.data.startswith(b"echo:"):
                echoes.append({"src64": pkt.src64, "data": pkt.data.decode(), "rssi_dbm": pkt.rssi_dbm,
                               "broadcast": pkt.broadcast})

    res["unicast_status"] = xb.send(peers64[0], b"ping-unicast", timeout=patience_s or 8).status
    collect(1)
    res["broadcast_status"] = xb.send(None, b"ping-broadcast", timeout=patience_s or 8).status
    collect(len(peers64))
    res["echoes"] = echoes
    res["db"] = xb.at("DB", timeout=at_s)[0]  # -dBm of the last packet received
    return res


class Probe(Controller):
    """Runs the probe once from robot 0's own program (sitl://xbee), logs the result, then idles."""

    period_s = 1.0
    defaults: ClassVar[dict[str, Any]] = {}

    def init(self, robot) -> None:
        super().init(robot)
        self.done = False

    def step(self) -> None:
        if not self.done:
            self.done = True
            peers = [0x0013A200_40A00000 + i for i in (1, 2)]
            self.robot.log("probe", **probe(self.robot.xbee, self.robot.clock, peers))


class Echo(RandomWalk):
    """Answers every ``ping`` packet with a unicast ``echo:<data>`` to its sender, robot k after (k - 1) x 0.5 s
    (so answers to a broadcast do not arrive together); stands still."""

    def init(self, robot) -> None:
        super().init(robot)
        self.replies: list[tuple[float, int, bytes]] = []

    def step(self) -> None:
        xb, now = self.robot.xbee, self.robot.clock.now()
        while (pkt := xb.recv(timeout=0)) is not None:
            if pkt.data.startswith(b"ping"):
                due = now + 0.5 * (self.robot.id - 1)
                self.replies.append((due, pkt.src64, b"echo:" + pkt.data + b" from %d" % self.robot.id))
        for reply in [r for r in self.replies if r[0] <= now]:
            self.replies.remove(reply)
            xb.send_nowait(reply[1], reply[2])


class Idle(Controller):
    period_s = 1.0

    def step(self) -> None:
        pass


class RealRadio(Controller):
    """For a robot whose XBee is a real module: identify it once, then broadcast a hello each step and log what it
    heard (source, RSSI), as any radio behaviour would."""

    period_s = 0.5

    def init(self, robot) -> None:
        super().init(robot)
        info = robot.xbee.identify()
        robot.log("identity", serial64=info.serial64, series=info.series)
        self.heard = 0

    def step(self) -> None:
        xb = self.robot.xbee
        xb.send_nowait(None, b"hello from the session")
        while (pkt := xb.recv(timeout=0)) is not None:
            self.heard += 1
            self.robot.log("heard", src64=pkt.src64, rssi_dbm=pkt.rssi_dbm, data=pkt.data.decode(errors="replace"))
