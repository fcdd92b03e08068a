"""The swarm's MAVLink endpoint as a medium of the session: ground stations' packets to the addressed robots' faces
(``uart:mavlink``, recorded on ``/mavlink/from_gcs``) at the start of each quantum, and what a face writes to
``sitl://mavlink`` to its ground station at once. Only a session with ``[mavlink] endpoint`` builds it (and loads
pymavlink)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bridge.core.entities import entity
from bridge.core.medium import Medium

if TYPE_CHECKING:
    from bridge.core.hub import Hub


class MavlinkLink(Medium):
    """The swarm's MAVLink UDP endpoint: ground stations to every robot's face, by system id."""

    name = "mavlink"
    order = 50

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        return bool(hub.cfg.mavlink.endpoint)

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        from bridge.hil.mavlink_gateway import MavlinkGateway

        m = hub.cfg.mavlink
        self.gateway = MavlinkGateway(m.endpoint, {r: m.system_id_base + r for r, rp in enumerate(hub.plan.robots)
                                                   if rp.has_logic and rp.vehicle is None}, m.per_robot)
        hub.medium("uart").links["mavlink"] = self.gateway.from_robot  # sitl://mavlink is a network port

    def started(self) -> dict[str, Any]:
        return {"mavlink": self.gateway.endpoints}

    def start_quantum(self, t: int) -> None:
        """What ground stations sent since the last quantum: to the robots' faces now, and to the recording (it
        comes from outside the session, in wall time)."""
        hub = self.hub
        for r, data, kind in self.gateway.poll():
            if r in hub.dead:
                continue
            hub.inbox[entity(r, "logic")].append(["uart:mavlink", data])
            hub.rec.write(t, "/mavlink/from_gcs", "swarm_sitl.MavlinkIn",
                          {"robot": r, "type": kind, "data": data.hex()})

    def report(self, result: dict[str, Any]) -> None:
        result["mavlink"] = self.gateway.stats()

    def close(self) -> None:
        self.gateway.close()
