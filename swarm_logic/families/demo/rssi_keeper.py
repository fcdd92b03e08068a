"""Random walk that keeps the radio network together by RSSI (the thesis' connectivity rule, section 3.2.3).

Every robot broadcasts a hello through its XBee every ``hello_s`` and keeps a neighbour table: the RSSI of
each neighbour's hellos (smoothed), forgotten after three missed hellos (the thesis' link-break rule).
While at least ``k`` neighbours are heard at ``q_min_dbm`` (-75 dBm, about 3 m) or better, it random-walks;
when fewer are, it turns back (180 degrees, the way it came, where the links were good) and drives until
``k`` neighbours are above ``q_min_dbm + hysteresis_db`` again or ``return_s`` has passed. Obstacle
avoidance always comes first. The LEDs show the neighbour count: 0 red, 1 orange, 2 yellow, 3 green,
4 or more blue.

With a UWB module the robot also tracks every neighbour's range with a Kalman filter and logs raw and
filtered ranges (``uwb_ranges``), which a session scores against the ground truth.
"""

from __future__ import annotations

import math
import struct
from typing import ClassVar

from swarm_logic.controller import DBM_RANGE
from swarm_logic.families.demo.random_walk import RandomWalk
from swarm_logic.robot import Robot

HELLO = b"H"
COUNT_COLOURS = ((255, 0, 0), (255, 96, 0), (255, 200, 0), (0, 255, 0), (0, 64, 255))


class RssiKeeper(RandomWalk):
    needs_radio = True
    defaults: ClassVar[dict[str, float]] = {
        **RandomWalk.defaults,
        "hello_s": 1.0,
        "q_min_dbm": -75.0,
        "hysteresis_db": 3.0,
        "k": 1,
        "return_s": 8.0,
        "rssi_smoothing": 0.5,
        "log_every_s": 1.0,
        "uwb_poll_s": 0.5,
        "uwb_update_s": 1.0,  # the UWB modules' ranging period (1 Hz, the Zebro figure)
        "uwb_nlos_bias_m": 0.6,  # mean excess of a range the module flags as NLOS (calibrate it per site)
        "uwb_accel_sigma": 0.1,  # m/s^2: how hard the range between two robots may change its rate
    }
    ranges: ClassVar[dict[str, str]] = {
        **RandomWalk.ranges,
        "hello_s": "(0, inf)",
        "q_min_dbm": DBM_RANGE,
        "hysteresis_db": "[0, inf)",
        "k": "[0, inf)",
        "return_s": "(0, inf)",
        "rssi_smoothing": "(0, 1]",
        "log_every_s": "(0, inf)",
        "uwb_poll_s": "(0, inf)",
        "uwb_update_s": "(0, inf)",
        "uwb_nlos_bias_m": "[0, inf)",
        "uwb_accel_sigma": "(0, inf)",
    }
    static_params = frozenset({"uwb_nlos_bias_m", "uwb_accel_sigma"})  # the range tracker is built by init

    def init(self, robot: Robot) -> None:
        if robot.xbee is None:
            raise ValueError("rssi_keeper needs an XBee (robots.xbee in the session config)")
        self.table: dict[int, tuple[float, float]] = {}  # src64 -> (smoothed RSSI dBm, last heard s)
        self.hello_seq = 0
        self.returning_until: float | None = None
        self.turn_until = 0.0
        self.tracker = None
        self.raw: dict[int, tuple[float, float]] = {}  # peer -> (latest raw UWB range m, its time s)
        super().init(robot)
        now = robot.clock.now()
        self.next_hello = now + float(robot.rng.uniform(0, self.p["hello_s"]))  # no synchronised hellos
        self.next_log = now
        self.next_uwb = now
        if robot.uwb is not None:
            from swarm_logic.drivers.ranging import RangeTracker

            self.tracker = RangeTracker(nlos_bias_m=self.p["uwb_nlos_bias_m"], accel_sigma=self.p["uwb_accel_sigma"])

    def telemetry(self) -> dict[str, float | int]:
        """The random walk's, the neighbour count, the links at ``q_min_dbm`` or better, whether it turns back."""
        return {**super().telemetry(), "neighbours": len(self.table), "good_links": self._good(),
                "returning": int(self.returning_until is not None)}

    # -- radio -------------------------------------------------------------------------------------------
    def _radio(self, now: float) -> None:
        r = self.robot
        a = self.p["rssi_smoothing"]
        while (pkt := r.xbee.recv(timeout=0)) is not None:
            if not pkt.data.startswith(HELLO):
                continue
            rssi = pkt.rssi_dbm  # None when the module's last-packet RSSI could belong to another packet
            old = self.table.get(pkt.src64)
            if rssi is None:
                if old is not None:  # heard, RSSI unknown: still a neighbour
                    self.table[pkt.src64] = (old[0], now)
                continue
            self.table[pkt.src64] = (rssi if old is None else a * rssi + (1 - a) * old[0], now)
        horizon = 3.5 * self.p["hello_s"]  # three missed hellos break the link
        self.table = {k: v for k, v in self.table.items() if now - v[1] <= horizon}
        if now >= self.next_hello:
            self.next_hello += self.p["hello_s"]
            self.hello_seq = (self.hello_seq + 1) & 0xFFFF
            r.xbee.send_nowait(None, HELLO + struct.pack("<HH", r.id & 0xFFFF, self.hello_seq), radius=1)

    def _good(self, margin: float = 0.0) -> int:
        q = self.p["q_min_dbm"] + margin
        return sum(1 for rssi, _ in self.table.values() if rssi >= q)

    # -- UWB ---------------------------------------------------------------------------------------------
    def _uwb(self, now: float) -> None:
        r = self.robot
        if self.tracker is None or r.uwb is None:
            return
        if now >= self.next_uwb:
            self.next_uwb += self.p["uwb_poll_s"]
            for m in r.uwb.loc_get():
                self.tracker.update_reading(m.addr16, m)
                self.raw[m.addr16] = (m.range_m, m.t)
        if now >= self.next_log:
            # score the filter against the raw ranges of the last update period only (both as the logic holds them
            # now): an older raw range would be blamed for the robots' motion since
            est = self.tracker.estimates(now)
            fresh = 1.5 * self.p["uwb_update_s"]
            self.raw = {p: v for p, v in self.raw.items() if now - v[1] <= fresh}
            peers = sorted(p for p in est if p in self.raw)
            if peers:
                self.robot.log("uwb_ranges", peers=peers, raw=[self.raw[p][0] for p in peers],
                               filtered=[est[p].range_m for p in peers])

    # -- control -----------------------------------------------------------------------------------------
    def step(self) -> None:
        r = self.robot
        now = r.clock.now()
        self._radio(now)
        self._uwb(now)
        k = int(self.p["k"])
        if self.returning_until is None and self.table is not None and self._good() < k and self.state != "avoid":
            self.returning_until = now + self.p["return_s"]
            self.turn_until = now + math.pi / self.p["turn_rate_rps"]
        if self.returning_until is not None:
            done = self._good(self.p["hysteresis_db"]) >= k or now >= self.returning_until
            blocked = r.llc.state.sonar_m < self.p["avoid_m"]
            if done or blocked:
                self.returning_until = None
                self.state = "run"
                self.until = now + self._run_time()
            else:
                if now < self.turn_until:
                    r.llc.drive(0.0, self.p["turn_rate_rps"])
                else:
                    r.llc.drive(self.p["speed_mps"], 0.0)
                self._show_count()
                self._log(now)
                return
        super().step()
        self._show_count()
        self._log(now)

    def _show(self, rgb: tuple[int, int, int]) -> None:
        """The random walk's state colours give way to the neighbour count."""

    def _show_count(self) -> None:
        rgb = COUNT_COLOURS[min(len(self.table), len(COUNT_COLOURS) - 1)]
        if rgb != self.led:
            self.led = rgb
            self.robot.llc.set_led(*rgb)

    def _log(self, now: float) -> None:
        if now >= self.next_log:
            self.next_log += self.p["log_every_s"]
            self.robot.log("neighbours", count=len(self.table), good=self._good(),
                           rssi=sorted(round(v[0], 1) for v in self.table.values()),
                           returning=self.returning_until is not None)
