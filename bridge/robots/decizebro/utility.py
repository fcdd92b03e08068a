"""The Zebro's forward utility sensor (Agrawal 2019, sections 3.2 and 4.2.1): a cone 60 degrees wide and three body
lengths long in the walking direction that reads, as one integer, the sum of the utilities of the food particles in
it (0: nothing; negative: an obstacle). The thesis assumes error-free sensing; the particles are what a study puts in
the world (``world.objects["particles"]``).

On the robot the sensor is a board on its own serial line to the Raspberry Pi (``utility``: our protocol,
``swarm_logic.robots.decizebro.utility_protocol``), streaming its reading at 10 Hz; here are its world part, its pins'
wiring and its firmware entity."""

from __future__ import annotations

import math
from typing import Any

from bridge.core.parts import Part, WorldModel
from bridge.core.recorder import register_schema
from firmware_sim.robots.decizebro.utility_board import UtilityBoard
from swarm_logic.robots.decizebro.utility_protocol import BAUD


class UtilityParams(Part):
    cone_deg: float = 60.0  # the cone's full angle (A-15: NetLogo's in-cone)
    range_m: float = 0.804  # three body lengths of 268 mm


class UtilitySensor(WorldModel):
    name = "utility"

    def sense(self, r: int) -> dict[str, Any]:
        """The sum of the utilities in the cone now, the direction of what it sees (rad, + = left; None: nothing),
        and the particles the robot has eaten (count and utilities' sum since power-up)."""
        w = self.world
        particles = w.objects.get("particles")
        if particles is None or not w.alive[r]:
            return {"utility": 0, "utility_bearing": None, "eaten": 0, "eaten_sum": 0}
        q = self.parts[self.local[r]]
        total, bearing = particles.cone(float(w.pos[r, 0]), float(w.pos[r, 1]), float(w.yaw[r]),
                                        math.radians(q.cone_deg) / 2, q.range_m)
        meals = particles.eaten.get(r, [])
        return {"utility": total, "utility_bearing": bearing, "eaten": len(meals), "eaten_sum": sum(meals)}


UtilityParams.world_model = UtilitySensor


register_schema("swarm_sitl.UtilityPins", {
    "type": "object",
    "description": "One report of the utility sensor board: what its sensor read",
    "properties": {"utility": {"type": "integer"}, "bearing_rad": {"type": ["number", "null"]},
                   "eaten": {"type": "integer"}, "eaten_sum": {"type": "integer"}},
})


class UtilityWiring:
    """What the utility sensor board's pins meet in the world: the utility sensor part's reading; it drives nothing."""

    schema = "swarm_sitl.UtilityPins"

    def sense(self, world: Any, r: int, media: dict[str, Any], ideal_pose: bool) -> tuple[dict, dict]:
        s = world.model("utility").sense(r)  # its own part only: not every part the robot has
        reading = {"utility": s["utility"], "bearing_rad": s["utility_bearing"], "eaten": s["eaten"],
                   "eaten_sum": s["eaten_sum"]}
        return reading, reading

    def valid(self, pins: Any) -> bool:
        return False  # the board has no outputs

    def actuate(self, world: Any, r: int, pins: dict[str, Any]) -> None:
        pass


class UtilityEntity:
    """The utility sensor board as the firmware host runs it: a report every 100 ms on its serial line."""

    def __init__(self, rp: Any, cfg: Any) -> None:
        self.board = UtilityBoard()
        self.counters = self.board.counters
        self.link: Any = None
        if pty := _pty(rp):
            from bridge.hosts.firmware import PtyLink

            self.link = PtyLink(pty, "utility_pty")

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        uart = b"".join(item[1] for item in inputs["in"] if item[0] == "uart")
        if self.link is not None:
            uart += self.link.read()
        tx = self.board.step(t_ns, inputs.get("sens"), uart)
        out: list[list] = []
        if tx and self.link is not None:
            self.link.write(tx)
        elif tx:
            out.append(["uart", UTILITY, tx, BAUD])
        wake = self.board.next_wake(t_ns)
        if self.link is not None:  # poll the pseudo-terminal every quantum
            wake = t_ns + 1 if wake is None else min(wake, t_ns + 1)
        return {"out": out, "wake": wake, "wom": False}

    def close(self) -> None:
        if self.link is not None:
            self.link.close()


def _pty(rp: Any) -> str | None:
    """The group's ``utility_pty`` (a ``RadioOptions`` field), if it exposes the board."""
    pty = (rp.options or {}).get("utility_pty")
    return pty if isinstance(pty, str) and pty else None


UTILITY = "utility"
UTILITY_PORTS = {UTILITY: BAUD}


def utility_hal(rp: Any, cfg: Any) -> dict[str, Any]:
    """The board's HAL table, unless its line is on a pseudo-terminal for a program outside the session."""
    return {} if _pty(rp) else {UTILITY: {"port": "sitl://utility", "baudrate": BAUD}}
