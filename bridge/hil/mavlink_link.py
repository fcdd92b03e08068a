"""The swarm's MAVLink endpoint as a medium of the session: ground stations' packets to the addressed robots' faces
(``uart:mavlink``, recorded on ``/mavlink/from_gcs``) at the start of each quantum, and what a face writes to
``sitl://mavlink`` to its ground station at once. A ground station's MAV_CMD_INJECT_FAILURE is the world's, not the
face's: it becomes an injected fault, answered from the robot's system id (``bridge.hil.mavlink_failures``). Only a
session with ``[mavlink] endpoint`` builds it (and loads pymavlink)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bridge.core.entities import entity
from bridge.core.medium import Medium

if TYPE_CHECKING:
    from bridge.core.hub import Hub


class MavlinkLink(Medium):
    """The swarm's MAVLink UDP endpoint: ground stations to every robot's face, by system id. A service may be a
    ground station too, inside the lock-step (a test's probe): its ``["mavlink", bytes]`` outputs reach the faces at
    the next quantum, routed as a UDP ground station's, and what the faces write reaches it as the records it hears
    (``/mavlink/to_gcs``: robot, bytes as hex), without being recorded."""

    name = "mavlink"
    order = 50
    routes = {("mavlink", "service"): "from_service"}  # noqa: RUF012 (a class-level table)

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        return bool(hub.cfg.mavlink.endpoint)

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        from bridge.hil.mavlink_failures import FailureInjector
        from bridge.hil.mavlink_gateway import MavlinkGateway

        m = hub.cfg.mavlink
        self.gateway = MavlinkGateway(m.endpoint, {r: m.system_id_base + r for r, rp in enumerate(hub.plan.robots)
                                                   if rp.has_logic and rp.vehicle is None}, m.per_robot)
        hub.medium("uart").links["mavlink"] = self.from_robot  # sitl://mavlink is a network port
        self.parsers: dict[str, Any] = {}  # a ground station service's own parser (its bytes may span packets)
        self.failures = FailureInjector(hub, self.from_robot, self.gateway.system_ids)  # MAV_CMD_INJECT_FAILURE

    def from_robot(self, r: int, data: bytes) -> None:
        """Bytes robot ``r``'s face wrote: to its UDP ground station now, and to the services that hear them."""
        self.gateway.from_robot(r, data)
        self.hub.overhear(self.hub.k * self.hub.q_ns, "/mavlink/to_gcs", {"robot": r, "data": data.hex()})

    def from_service(self, e: str, r: int, t: int, item: list) -> None:
        """``["mavlink", bytes]`` a service sent as a ground station: to the addressed faces at the next quantum,
        recorded as a UDP ground station's are."""
        _, data = item
        if not isinstance(data, bytes):
            raise ValueError
        parser = self.parsers.get(e)
        if parser is None:
            parser = self.parsers[e] = self.gateway.parser()
        self.hub.deliver_at(t + self.hub.q_ns, self._to_faces, self.gateway.route(parser, data))

    def started(self) -> dict[str, Any]:
        return {"mavlink": self.gateway.endpoints}

    def start_quantum(self, t: int) -> None:
        """What ground stations sent since the last quantum: to the robots' faces now, and to the recording (it
        comes from outside the session, in wall time)."""
        self._to_faces(t, self.gateway.poll())

    def _to_faces(self, t: int, packets: list[tuple[int, bytes, str]]) -> None:
        hub = self.hub
        for r, data, kind in packets:
            if r in hub.dead:
                continue
            if not self.failures.take(t, r, data, kind):  # a failure injection is the world's, as in PX4 SITL
                hub.inbox[entity(r, "logic")].append(["uart:mavlink", data])
            hub.rec.write(t, "/mavlink/from_gcs", "swarm_sitl.MavlinkIn",
                          {"robot": r, "type": kind, "data": data.hex()})

    def report(self, result: dict[str, Any]) -> None:
        result["mavlink"] = self.gateway.stats()
        if self.failures.counts:
            result["mavlink"]["inject_failure"] = self.failures.stats()

    def close(self) -> None:
        self.gateway.close()
