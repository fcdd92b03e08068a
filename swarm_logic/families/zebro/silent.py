"""The silent protocol (thesis Algorithms 1-3): flocking, taxis towards a sensed particle (away from an obstacle),
then ALIGN once more "to lessen the probability of splitting". No frame is ever sent (Z-U6).

A robot learns of another's finding only through its neighbours' headings. Several robots sensing one particle
walk radially towards it; the second ALIGN can pull a robot's cone off its particle (the thesis' ignorance).
"""

from __future__ import annotations

from swarm_logic.families.zebro.base import ZebroController
from swarm_logic.families.zebro.flocking import align, flock


class ZebroSilent(ZebroController):
    """Algorithm 1: FLOCKING, UTILITY FOUND (Algorithm 3, with its second ALIGN), every tick."""

    def reset(self) -> None:
        self.sensing = False
        self.eaten = 0

    def step(self) -> None:
        h0 = self.imu.heading()
        nbrs = self.radio.neighbours()
        self.radio.receive()  # a silent robot reads nothing (it would hear only other families' frames)
        h = flock(h0, nbrs, self.rules)
        u = self.sensor.read()
        if u != 0:
            h = align(self.taxis(h, h0, u), nbrs, self.rules)
        if (u > 0) != self.sensing:
            self.sensing = u > 0
            self.robot.log("zebro_sense", utility=u)
        eaten = self.sensor.consumed()
        if eaten:
            self.eaten += eaten
            self.robot.log("zebro_consumed", utility=eaten)
        self.steer(h0, h)

    def telemetry(self) -> dict[str, float | int]:
        return {"sensing": int(self.sensing), "eaten": self.eaten}
