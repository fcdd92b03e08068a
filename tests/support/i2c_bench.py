"""A one-robot lock-step bench for the I2C medium, without processes: the medium under a stand-in hub, DeciZebro leg
modules run as the firmware host runs them (on their wake times and on bus traffic), each on a first-order leg motor
as the world's legs model has it, a robot program in a ``RobotRuntime`` thread as the logic host runs it, and
optionally other slaves (a SonPI's Arduino) and an adapter entity that is another master of the bus (a USB-ISS on a
pseudo-terminal). One
``step()`` is one quantum, in the hub's order: deliveries, the entities that are due, their outputs to the medium
(sorted by entity), the medium's ``end_outputs`` and ``advance``."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

from bridge.hosts.sim_context import RobotRuntime, SessionClock
from bridge.media.i2c import I2cBuses
from firmware_sim.robots.decizebro.leg_module import LegModule

Q = 10_000_000
LOGIC = "r000/logic"
ADAPTER = "r000/i2c_adapter"


class I2cBench:
    def __init__(
        self,
        program: Callable[[RobotRuntime, SessionClock], None] | None = None,
        legs: int = 6,
        boot_ns: int = 0,
        q_ns: int = Q,
        adapter: Any = None,
        slaves: dict[str, Any] | None = None,
    ) -> None:
        self.q_ns, self.n = q_ns, 1
        self.plan = SimpleNamespace(robots=[None])
        self.dead: set[int] = set()
        self.counts: dict[str, int] = defaultdict(int)
        self.records: list[tuple[int, str, dict]] = []
        self.deliveries: dict[int, list[tuple]] = defaultdict(list)
        self.inbox: dict[str, list] = defaultdict(list)
        self.medium = I2cBuses(self)  # type: ignore[arg-type]
        self.modules: dict[str, Any] = {f"r000/leg{i}": LegModule(i) for i in range(legs)}
        self.modules.update(slaves or {})  # other slaves on the bus (entity -> firmware), powered up with the legs
        self.next_wake: dict[str, int | None] = dict.fromkeys(self.modules, boot_ns)
        self.angle = [0.0] * 6
        self.omega = [0.0] * 6
        self.duty = [0.0] * 6
        self.duty_log: list[tuple[int, list[float]]] = []
        self.k = 0
        self.rt: RobotRuntime | None = None
        self.adapter = adapter  # a master entity on the bus (a USB-ISS: bridge.hil.usb_iss), run every quantum
        if program is not None:
            rt = RobotRuntime(0)
            clock = SessionClock(rt)
            rt.start(lambda: program(rt, clock))
            self.rt = rt

    # -- what the medium asks of its hub ------------------------------------------------------------------------
    def deliver_at(self, t_ns: int, handler: Callable[..., None], *args: Any) -> None:
        self.deliveries[t_ns].append((handler, args))

    def to_inbox(self, t: int, e: str, msg: list) -> None:
        self.inbox[e].append(msg)

    def record(self, t: int, topic: str, schema: str, payload: Any) -> None:
        self.records.append((t, topic, payload))

    # -- one quantum ------------------------------------------------------------------------------------------------
    @property
    def t(self) -> int:
        return self.k * self.q_ns

    def step(self) -> None:
        t, q = self.t, self.q_ns
        for handler, args in self.deliveries.pop(t, []):
            handler(t, *args)
        outputs: list[tuple[str, list]] = []
        for e in sorted(self.modules):
            w = self.next_wake[e]
            if not ((w is not None and w <= t) or any(item[0] == "i2c" for item in self.inbox[e])):
                continue
            leg = e.startswith("r000/leg")  # other slaves (a test's own, a SonPI board) sense nothing here
            i = int(e[-1]) if leg else -1
            sens = {"angle": self.angle[i] % (2 * math.pi), "omega": self.omega[i], "battery_v": 14.4} if leg else {}
            res = self.modules[e].run(t, {"in": self.inbox.pop(e, []), "sens": sens})
            w = res.get("wake")
            self.next_wake[e] = None if w is None else max(t + q, -(-w // q) * q)
            outputs += [(e, item) for item in res["out"]]
            if "pins" in res and leg:
                self.deliver_at(t + q, self._duty, i, res["pins"]["duty"])
        rt = self.rt
        if rt is not None:
            arrived = set()
            for item in self.inbox.pop(LOGIC, []):
                rt.deliver(item[0], item[1])
                arrived.add(item[0])
            rt.run_timers(t)
            if rt.due(t, arrived):
                rt.resume(t)
            if rt.error:
                raise AssertionError(rt.error)
            outputs += [(LOGIC, item) for item in rt.outbox]
            rt.outbox = []
        if self.adapter is not None:
            res = self.adapter.run(t, {"in": self.inbox.pop(ADAPTER, [])})
            outputs += [(ADAPTER, item) for item in res["out"]]
        for e, item in outputs:
            kind = item[0]
            if e in (LOGIC, ADAPTER):
                self.medium.master(e, 0, t, item)
            elif kind == "i2c":
                self.medium.slave(e, 0, t, item)
            else:
                self.medium.attach(e, 0, t, item)
        self.medium.end_outputs(t)
        self.medium.advance(t)
        self._motors(q / 1e9)
        self.k += 1

    def _duty(self, t: int, leg: int, duty: float) -> None:
        self.duty[leg] = duty

    def _motors(self, dt: float) -> None:
        """The legs' first-order response over the quantum, as the world's legs model integrates it."""
        decay = math.exp(-dt / 0.08)
        for i in range(6):
            w_ss = self.duty[i] * 170 * 2 * math.pi / 60 * 1.2
            self.angle[i] += w_ss * dt + (self.omega[i] - w_ss) * 0.08 * (1 - decay)
            self.omega[i] = w_ss + (self.omega[i] - w_ss) * decay
        self.duty_log.append((self.t, list(self.duty)))

    def run_until(self, t_ns: int) -> None:
        while self.t < t_ns:
            self.step()

    def close(self) -> None:
        if self.rt is not None:
            self.rt.stop()

    def transactions(self) -> list[dict]:
        return [p for _, topic, p in self.records if topic == "/r000/i2c"]
