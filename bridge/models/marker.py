"""A marker on the robot's top for an overhead camera to find it by: a coloured disc. It does nothing in the world's
physics; a camera or localisation service reads each robot's marker from its profile (``profile.part(TopMarker)``)
or, in the world process, from ``world.model("marker")``."""

from __future__ import annotations

from pydantic import Field

from bridge.core.parts import Part, WorldModel


class TopMarker(Part):
    rgb: tuple[int, int, int] = Field(description="the disc's colour (0-255 each)")
    radius_m: float = Field(gt=0, description="the disc's radius")


class TopMarkers(WorldModel):
    name = "marker"

    def rgb(self, r: int) -> tuple[int, int, int]:
        """Robot ``r``'s marker colour."""
        return self.parts[self.local[r]].rgb


TopMarker.world_model = TopMarkers
