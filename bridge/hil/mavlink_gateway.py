"""The swarm's MAVLink endpoint: one UDP socket between ground stations and every robot's MAVLink face.

Each robot's logic runs a MAVLink 2 face (``swarm_logic.mavlink.face``) that writes its packets to ``sitl://mavlink``.
The world hands them to this gateway, which sends them to the ground station as they come (wall time: a ground
station lives in it). What the ground station sends is read once per quantum and routed by ``target_system``:
to that robot, or to every robot for broadcasts (target 0) and messages without a target (a GCS heartbeat).
So MAVProxy or QGroundControl sees the whole swarm on one connection, each robot behind its own system id, as
behind a mavlink-router. With ``per_robot`` each robot has a socket of its own instead (port + robot id), and
everything arriving there is for that robot.

Endpoints are written as pymavlink writes them: ``udpout:HOST:PORT`` sends to a ground station listening there
(QGroundControl and ``mavproxy.py --master=udpin:127.0.0.1:14550`` listen on 14550) and answers it from the
gateway's own socket; ``udpin:HOST:PORT`` listens there and answers whoever spoke last (port 0: any free port,
reported as ``endpoints``). Packets with a bad checksum or garbage are counted and dropped.
"""

from __future__ import annotations

import os
import socket
from collections import defaultdict
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink2

from bridge.core.endpoints import Endpoint, UdpPort, is_loopback, parse_endpoint


class _Port(UdpPort):
    """One UDP socket and the ground station it talks to."""

    def __init__(self, ep: Endpoint) -> None:
        v6 = ":" in ep.host
        if ep.mode == "udpin":
            super().__init__(ep.host, ep.port)  # answers whoever spoke last
        else:
            family = socket.AF_INET6 if v6 else socket.AF_INET
            peer = socket.getaddrinfo(ep.host, ep.port, family, socket.SOCK_DGRAM)[0][4]
            super().__init__(("::1" if v6 else "127.0.0.1") if is_loopback(ep.host) else ("::" if v6 else ""), 0, peer)
        host, port = self.bound
        self.endpoint = Endpoint(ep.mode, ep.host, port) if ep.mode == "udpin" else ep
        self.local = f"{host}:{port}"
        self.parser = mavlink2.MAVLink(None)
        self.parser.robust_parsing = True


class MavlinkGateway:
    """Bytes between robots' faces and ground stations. ``system_ids``: robot -> MAVLink system id."""

    def __init__(self, endpoint: str, system_ids: dict[int, int], per_robot: bool = False) -> None:
        ep = parse_endpoint(endpoint)
        self.system_ids = dict(system_ids)
        self.robot_of = {s: r for r, s in system_ids.items()}
        self.per_robot = per_robot
        self.counts: dict[str, int] = defaultdict(int)
        self.ports: dict[int | None, _Port] = {}
        try:
            if per_robot:
                for r in sorted(system_ids):
                    self.ports[r] = _Port(Endpoint(ep.mode, ep.host, ep.port + r if ep.port else 0))
            else:
                self.ports[None] = _Port(ep)
        except OSError as e:
            self.close()
            raise OSError(f"mavlink.endpoint {endpoint}: cannot open the UDP socket: {e}") from None

    @property
    def endpoints(self) -> dict[str, str]:
        """What a ground station connects to, per robot (or ``swarm``), with the ports actually bound."""
        return {("swarm" if r is None else f"r{r:03d}"): str(p.endpoint) for r, p in self.ports.items()}

    def from_robot(self, r: int, data: bytes) -> None:
        """Bytes a robot's face wrote: to its ground station now."""
        port = self.ports.get(r if self.per_robot else None)
        if port is not None and port.send(data):
            self.counts["to_gcs_datagrams"] += 1
            self.counts["to_gcs_bytes"] += len(data)
        else:
            self.counts["to_gcs_dropped"] += 1

    def poll(self) -> list[tuple[int, bytes, str]]:
        """What the ground stations sent since the last call: (robot, packet bytes, message type), in the order
        it arrived; bad packets counted and dropped."""
        out: list[tuple[int, bytes, str]] = []
        for r, port in self.ports.items():
            for data in port.recv_all():
                self.counts["from_gcs_datagrams"] += 1
                out += self.route(port.parser, data, r)
        return out

    def route(self, parser: Any, data: bytes, robot: int | None = None) -> list[tuple[int, bytes, str]]:
        """The packets in ``data`` (parsed by ``parser``, a ground station's own) with the robots they are for: by
        ``target_system``, every robot for a broadcast or a message without a target, or ``robot``'s alone."""
        out: list[tuple[int, bytes, str]] = []
        for msg in parser.parse_buffer(data) or ():
            kind = msg.get_type()
            if kind == "BAD_DATA":
                self.counts["bad_packets"] += 1
                continue
            self.counts["from_gcs_packets"] += 1
            raw = bytes(msg.get_msgbuf())
            if robot is not None:
                out.append((robot, raw, kind))
                continue
            target = getattr(msg, "target_system", 0)
            if target == 0:
                out += [(rr, raw, kind) for rr in sorted(self.system_ids)]
            elif target in self.robot_of:
                out.append((self.robot_of[target], raw, kind))
            else:
                self.counts["unknown_target"] += 1
        return out

    def parser(self) -> Any:
        """A MAVLink 2 parser for one ground station's bytes."""
        parser = mavlink2.MAVLink(None)
        parser.robust_parsing = True
        return parser

    def stats(self) -> dict[str, Any]:
        return {"endpoints": self.endpoints, **dict(sorted(self.counts.items()))}

    def close(self) -> None:
        for p in self.ports.values():
            p.sock.close()
