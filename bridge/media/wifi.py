"""A Wi-Fi network (IEEE 802.11, one access point): UDP datagrams between a session's nodes, unicast or broadcast.

The nodes are the robots whose swarm logic the session runs (a companion computer has Wi-Fi; address ``rNNN``) and
the session's services (``[[services]]``; address: the service's name). A node sends ``["wifi", dest, data]``:
``dest`` an address or None for a broadcast to every other node, ``data`` the UDP payload (bytes, at most
``max_datagram`` bytes). Each receiver gets ``["wifi", [src, data]]`` in its inbox.

What the air does to a datagram is drawn per link (sender, receiver) from a seeded stream of its own
(``rng.stream(seed, "wifi", src, dst)``), a fixed number of draws per datagram, so adding a node shifts no other
link's draws:

- ``ideal`` (the default; the thesis assumes lossless links): every datagram arrives one quantum after it was sent.
- ``lossy``: a datagram leaves at the end of its quantum and arrives ``latency_ms`` + N(0, ``jitter_ms``) later
  (never before it left), delivered at the first quantum boundary after that (so datagrams may overtake each other,
  as UDP's do), and is lost with probability ``loss`` per receiver (a broadcast is not acknowledged, nor is a unicast
  over UDP).

An item that is not a datagram (a destination that is no node, a payload that is not bytes or is too long) is
counted ``malformed`` and dropped. Recorded: ``/wifi/tx`` per datagram (sender, destination, length, payload, who
got it and who lost it). ``summary.json``: ``wifi`` (sent, delivered, lost, malformed, per node).

A robot whose logic runs outside the session (``logic = "external"``) is a node too when its group sets
``wifi_udp = "HOST:PORT"``: the session binds a UDP socket there (port 0: any free one; the bound address is in the
``started`` status and ``summary.json``'s ``wifi.udp``). Every datagram waiting on it at the start of a quantum enters
the network as that robot's broadcast, as a real SonPI broadcasts on the shared port (an empty or over-long one is
counted ``malformed`` and dropped); what the network delivers to the robot is sent from the socket to whoever last
sent to it (``unsent`` counts those that came before anyone did, or that the system refused). The outside program
runs in wall time: what it sends is not reproducible, and is recorded like the rest.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from bridge.core.endpoints import UdpPort
from bridge.core.entities import entity
from bridge.core.medium import Medium
from bridge.core.recorder import register_schema
from bridge.core.rng import stream
from swarm_logic.drivers.wifi import split_host_port

if TYPE_CHECKING:
    from bridge.core.hub import Hub

KIND = "wifi"
UDP_MAX = 65507  # the largest UDP payload over IPv4

register_schema(
    "swarm_sitl.WifiTx",
    {
        "type": "object",
        "properties": {
            "src": {"type": "string", "description": "sender's address"},
            "dest": {"type": ["string", "null"], "description": "addressee, null for a broadcast"},
            "len": {"type": "integer"},
            "data": {"type": "string", "description": "the payload, hex"},
            "heard": {"type": "array", "description": "addresses that received it"},
            "lost": {"type": "array", "description": "addresses it was meant for that did not"},
        },
    },
)


class WifiCfg(BaseModel):
    """The session's Wi-Fi network (``[wifi]``): how datagrams between robots and services fare."""

    model_config = ConfigDict(extra="forbid")

    mode: Literal["ideal", "lossy"] = Field(
        "ideal",
        description="ideal: no loss, one-quantum latency (the thesis' assumption); lossy: latency, jitter, loss",
    )
    enabled: bool = Field(
        False, description="give the robots Wi-Fi even without a service (a session with [[services]] always has it)"
    )
    latency_ms: float = Field(3.0, ge=0, le=10_000, description="lossy: mean one-way latency")
    jitter_ms: float = Field(1.0, ge=0, le=10_000, description="lossy: standard deviation of the latency")
    loss: float = Field(0.0, ge=0, le=1, description="lossy: probability a receiver loses a datagram")
    max_datagram: int = Field(
        1472,
        ge=1,
        le=UDP_MAX,
        description="the largest payload (bytes; 1472 fits one 802.11 frame without IP fragmentation)",
    )
    record_payload: bool = Field(True, description="record each datagram's payload in /wifi/tx")

    @model_validator(mode="after")
    def _ideal_is_ideal(self) -> WifiCfg:
        if self.mode == "ideal":
            fields = type(self).model_fields
            stray = sorted(f for f in ("latency_ms", "jitter_ms", "loss") if getattr(self, f) != fields[f].default)
            if stray:
                raise ValueError(f"{', '.join(stray)} do(es) not apply to mode = 'ideal' (set mode = 'lossy')")
        return self


def robot_address(r: int) -> str:
    """A robot's address on the Wi-Fi network."""
    return f"r{r:03d}"


class WifiNetwork(Medium):
    """Datagrams between the robots' logic and the session's services, with seeded latency and loss."""

    name = "wifi"
    order = 45
    routes = {(KIND, "logic"): "transmit", (KIND, "service"): "transmit"}  # noqa: RUF012

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        return bool(hub.cfg.services) or hub.cfg.wifi.enabled or any(rp.wifi_udp for rp in hub.plan.robots)

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        self.cfg: WifiCfg = hub.cfg.wifi
        self.seed = hub.cfg.session.seed
        # address -> entity, in a fixed order: the robots' (an outside program's node: a UDP port), then the services'
        self.nodes: dict[str, str] = {}
        self.outside: dict[str, UdpPort] = {}  # entity rNNN/wifi_udp -> the UDP port of a robot whose logic is outside
        self.outside_counts: dict[str, dict[str, int]] = {}  # by entity
        for r, rp in enumerate(hub.plan.robots):
            if rp.has_logic:
                self.nodes[robot_address(r)] = entity(r, "logic")
            elif rp.wifi_udp:
                e = self.nodes[robot_address(r)] = entity(r, "wifi_udp")
                self.outside[e] = self._open(robot_address(r), rp.wifi_udp)
                self.outside_counts[e] = dict.fromkeys(("received", "sent", "unsent", "malformed", "dead"), 0)
        self.nodes.update({s: e for s, e in hub.service_entities.items()})
        self.address = {e: a for a, e in self.nodes.items()}
        self._rng: dict[tuple[str, str], np.random.Generator] = {}
        self.totals = dict.fromkeys(("sent", "broadcasts", "delivered", "lost", "malformed", "bytes"), 0)
        self.per_node: dict[str, dict[str, int]] = defaultdict(lambda: dict.fromkeys(("sent", "received", "lost"), 0))

    def _open(self, address: str, where: str) -> UdpPort:
        host, port = split_host_port(where, f"{address} wifi_udp")
        try:
            return UdpPort(host, port)
        except OSError as e:
            self.close()
            raise OSError(f"{address} wifi_udp {where}: cannot open the UDP socket: {e}") from None

    def started(self) -> dict[str, Any]:
        """The outside programs' ports as bound (``HOST:PORT`` per robot address)."""
        return {"wifi_udp": self.endpoints()} if self.outside else {}

    def endpoints(self) -> dict[str, str]:
        return {self.address[e]: f"{p.bound[0]}:{p.bound[1]}" for e, p in self.outside.items()}

    def start_quantum(self, t: int) -> None:
        """What the outside programs sent since the last quantum: their robots' broadcasts, sent now."""
        for e, port in self.outside.items():
            counts = self.outside_counts[e]
            for data in port.recv_all():
                counts["received"] += 1
                if self.hub.is_dead(e):
                    counts["dead"] += 1
                    continue
                try:
                    self._send(self.address[e], None, data, t)
                except ValueError:  # empty or too long: counted (here and in the totals) and dropped
                    counts["malformed"] += 1

    def _stream(self, src: str, dst: str) -> np.random.Generator:
        g = self._rng.get((src, dst))
        if g is None:
            g = self._rng[(src, dst)] = stream(self.seed, "wifi", src, dst)
        return g

    def transmit(self, e: str, r: int, t: int, item: list) -> None:
        """``["wifi", dest, data]`` from a node: to ``dest`` (an address) or, with None, to every other node."""
        src = self.address.get(e)
        dest = item[1] if len(item) == 3 else 0
        data = item[2] if len(item) == 3 else None
        if src is None:
            self.totals["malformed"] += 1
            raise ValueError("not a node")
        self._send(src, dest, data, t)

    def _send(self, src: str, dest: Any, data: Any, t: int) -> None:
        """A datagram from node ``src`` at ``t``: its fate per receiver drawn, its deliveries scheduled, recorded."""
        if (
            not isinstance(data, bytes)
            or not 0 < len(data) <= self.cfg.max_datagram
            or not (dest is None or (isinstance(dest, str) and dest in self.nodes and dest != src))
        ):
            self.totals["malformed"] += 1
            raise ValueError("not a datagram")
        hub = self.hub
        q = hub.q_ns
        self.totals["sent"] += 1
        self.totals["bytes"] += len(data)
        self.per_node[src]["sent"] += 1
        if dest is None:
            self.totals["broadcasts"] += 1
        to = [a for a in self.nodes if a != src] if dest is None else [dest]
        heard: list[str] = []
        lost: list[str] = []
        cfg = self.cfg
        for a in to:
            if cfg.mode == "ideal":
                t_at = t + q
            else:
                g = self._stream(src, a)
                u, z = float(g.random()), float(g.standard_normal())  # two draws per datagram, always
                if u < cfg.loss:
                    lost.append(a)
                    continue
                delay_ns = max(0.0, cfg.latency_ms + cfg.jitter_ms * z) * 1e6
                t_at = max(t + q, math.ceil((t + q + delay_ns) / q) * q)
            heard.append(a)
            hub.deliver_at(t_at, self._arrive, self.nodes[a], src, data)
        self.totals["lost"] += len(lost)
        for a in lost:
            self.per_node[a]["lost"] += 1
        rec: dict[str, Any] = {"src": src, "dest": dest, "len": len(data), "heard": heard, "lost": lost}
        if cfg.record_payload:
            rec["data"] = data.hex()
        hub.rec.write(t, "/wifi/tx", "swarm_sitl.WifiTx", rec)

    def _arrive(self, t: int, e: str, src: str, data: bytes) -> None:
        """A delivery: the datagram into the receiver's inbox, or out of an outside program's port (nothing for a
        dead robot)."""
        port = self.outside.get(e)
        if (port is not None or e in self.hub.inbox) and not self.hub.is_dead(e):
            self.totals["delivered"] += 1
            self.per_node[self.address[e]]["received"] += 1
            if port is None:
                self.hub.inbox[e].append([KIND, [src, data]])
            else:
                self.outside_counts[e]["sent" if port.send(data) else "unsent"] += 1

    def report(self, result: dict[str, Any]) -> None:
        result["wifi"] = {
            "mode": self.cfg.mode,
            "nodes": len(self.nodes),
            **self.totals,
            "per_node": {a: dict(self.per_node[a]) for a in self.nodes if a in self.per_node},
            **(
                {
                    "udp": {
                        self.address[e]: {"endpoint": f"{p.bound[0]}:{p.bound[1]}", **self.outside_counts[e]}
                        for e, p in self.outside.items()
                    }
                }
                if self.outside
                else {}
            ),
        }

    def close(self) -> None:
        for port in self.outside.values():
            port.close()
