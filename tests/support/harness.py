"""In-process plant for firmware tests: a pybullet ``World`` wired to LLC boards, without transports."""

from __future__ import annotations

from bridge.core.config import Config
from bridge.core.entities import entity
from bridge.core.plan import make_plan
from bridge.hosts.firmware import FirmwareHost


class Plant:
    """Runs LLCs against the world at the session's quantum, in one process (no zenoh, no hub)."""

    def __init__(self, cfg: Config) -> None:
        from bridge.core.world import World

        self.cfg = cfg
        self.plan = make_plan(cfg)
        self.world = World(cfg, self.plan.robots)
        self.fw = FirmwareHost(self.plan, tuple(r.id for r in self.plan.robots))
        self.q = cfg.session.quantum_ns
        self.t = 0
        self.wake = {r.id: 0 for r in self.plan.robots}
        self.inbox: dict[int, list] = {r.id: [] for r in self.plan.robots}
        self.tx: dict[int, list] = {r.id: [] for r in self.plan.robots}
        self.pending_pins: list = []

    def send(self, robot: int, arb_id: int, data: bytes) -> None:
        self.inbox[robot].append(["can0", arb_id, bytes(data), False, self.t])

    def step(self) -> None:
        for r, pins in self.pending_pins:
            self.world.model("differential_drive").set_pwm(r, *pins["pwm"])
        self.pending_pins = []
        for r in sorted(self.wake):
            if self.wake[r] <= self.t:
                s = self.world.sensors(r)
                res = self.fw.run(entity(r, "llc"), self.t, {
                    "in": self.inbox[r],
                    "sens": {"enc": list(s["encoders"]), "sonar_m": s["sonar_m"], "lux": s["lux"],
                             "battery_v": s["battery_v"]}})
                self.inbox[r] = []
                self.tx[r].extend(res["out"])
                self.wake[r] = res["wake"]
                if "pins" in res:
                    self.pending_pins.append((r, res["pins"]))
        self.world.step_quantum(self.t, self.q)
        self.t += self.q

    def run_for(self, seconds: float) -> None:
        end = self.t + round(seconds * 1e9)
        while self.t < end:
            self.step()
