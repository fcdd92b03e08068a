"""The Zebro's forward utility sensor (Agrawal 2019, sections 3.2 and 4.2.1): a cone 60 degrees wide and three body
lengths long in the walking direction that reads, as one integer, the sum of the utilities of the food particles in
it (0: nothing; negative: an obstacle). The thesis assumes error-free sensing; the particles are what a study puts in
the world (``world.objects["particles"]``)."""

from __future__ import annotations

import math
from typing import Any

from bridge.core.parts import Part, WorldModel


class UtilityParams(Part):
    cone_deg: float = 60.0  # the cone's full angle (A-15: NetLogo's in-cone)
    range_m: float = 0.804  # three body lengths of 268 mm


class UtilitySensor(WorldModel):
    name = "utility"

    def sense(self, r: int) -> dict[str, Any]:
        """The sum of the utilities in the cone now."""
        w = self.world
        particles = w.objects.get("particles")
        if particles is None or not w.alive[r]:
            return {"utility": 0}
        q = self.parts[self.local[r]]
        return {"utility": particles.in_cone(float(w.pos[r, 0]), float(w.pos[r, 1]), float(w.yaw[r]),
                                             math.radians(q.cone_deg) / 2, q.range_m)}


UtilityParams.world_model = UtilitySensor
