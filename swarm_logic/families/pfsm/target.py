"""The target: a foot-bot that waits, passive, until a searcher gives it energy (a range-and-bearing message naming
it, K-5, K-11), then drives to the light by phototaxis with obstacle avoidance and stops in the base (digest 2.4)."""

from __future__ import annotations

from swarm_logic.families.pfsm import messages as msg
from swarm_logic.families.pfsm.base import FootbotController

COLOURS = {msg.WAITING: (255, 255, 0), msg.HOMING: (255, 0, 255), msg.HOME: (0, 0, 0)}


class PfsmTarget(FootbotController):
    """Waiting, homing, home; it names itself in its payload (the board carries no sender id)."""

    def reset(self) -> None:
        self.state = msg.WAITING
        self.leds.set_all_colors(COLOURS[self.state])
        self.wheels.set_speeds(0.0, 0.0)
        self.announce()

    def announce(self) -> None:
        self.rab.send(msg.encode(msg.Payload(msg.TARGET, self.state, False, self.robot.id)))

    def enter(self, state: int) -> None:
        self.state = state
        self.leds.set_all_colors(COLOURS[state])
        self.robot.log("pfsm_target", state=msg.STATE_NAMES[msg.TARGET][state])
        self.announce()

    def step(self) -> None:
        if self.state == msg.WAITING:
            for r in self.rab.readings():
                m = msg.decode(r.data)
                if m is not None and m.found and m.kind == msg.SEARCHER and m.target_id == self.robot.id:
                    self.enter(msg.HOMING)
                    break
            else:
                return
        if self.state == msg.HOMING:
            if self.in_base():
                self.enter(msg.HOME)
                self.wheels.set_speeds(0.0, 0.0)
                return
            avoid = self.avoidance()
            if avoid is None:
                lx, ly = self.to_light()
                v = float(self.p["max_speed_mps"])
                avoid = (v * lx, v * ly)
            self.set_wheels_from_vector(*avoid)

    def telemetry(self) -> dict[str, float | int]:
        return {"state": self.state}
