"""A serial line from a robot's computer to one of its modules: bytes leave at the sender's baud rate.

Each byte takes 10 bit times (start, 8 data, stop). Chunks queue behind each other, and at every quantum
boundary the receiver gets the bytes that have fully arrived by then, so a 100-byte API frame at 9600 baud
reaches the module over about 104 ms, as on the wire. When the two ends disagree on the baud rate the
receiver samples garbage: every byte arrives as a framing error and is replaced by what a UART would
latch (modelled as a fixed scrambling), which the module's parser then rejects and counts.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from bridge.core.entities import entity
from bridge.core.medium import Medium

if TYPE_CHECKING:
    from bridge.core.hub import Hub

BITS_PER_BYTE = 10


def garble(data: bytes) -> bytes:
    """What a UART sampling at the wrong baud rate latches instead of ``data`` (a fixed scrambling)."""
    return bytes(((b * 73 + 41) ^ 0x5A) & 0xFF for b in data)


class SerialLine:
    def __init__(self, baud: int) -> None:
        self.baud = baud  # the receiving end's rate
        self._q: deque[tuple[int, int, bytes]] = deque()  # (start ns, sender baud, data)
        self.busy_until = 0
        self.bytes = 0
        self.garbled = 0

    @property
    def pending(self) -> bool:
        return bool(self._q)

    def offer(self, t_ns: int, data: bytes, baud: int) -> None:
        """``data`` handed to the sender's UART at ``t_ns`` (it starts when the line is free)."""
        start = max(t_ns, self.busy_until)
        self.busy_until = start + len(data) * BITS_PER_BYTE * 1_000_000_000 // baud
        self._q.append((start, baud, data))

    def arrived(self, t_ns: int) -> bytes:
        """The bytes that have fully arrived by ``t_ns`` (and were not taken before)."""
        out = bytearray()
        q = self._q
        while q:
            start, baud, data = q[0]
            done = (t_ns - start) * baud // (BITS_PER_BYTE * 1_000_000_000) if t_ns > start else 0
            if done <= 0:
                break
            chunk = data[:done]
            if baud != self.baud:
                self.garbled += len(chunk)
                chunk = garble(chunk)
            out += chunk
            if done >= len(data):
                q.popleft()
            else:
                q[0] = (start + done * BITS_PER_BYTE * 1_000_000_000 // baud, baud, data[done:])
                break
        self.bytes += len(out)
        return bytes(out)


MODULE_PORTS = ("xbee", "uwb")  # modules whose UART a robot's computer reaches over a serial line
NETWORK_PORTS = ("mavlink",)  # sitl:// ports that are network links, not lines: a medium of their own serves them


class SerialLines(Medium):
    """Each robot's serial lines from its computer to its modules (the XBee, the UWB module, a robot model's own:
    ``RobotSpec.ports``), paced at the host port's baud rate, and the bytes the modules send back (garbled when the
    host listens at another rate)."""

    name = "uart"
    order = 20
    # a module's writes: the shared modules' and a robot model's own (RobotSpec.ports), checked against its lines
    routes = {("uart", "logic"): "host_write", ("baud", "logic"): "host_baud",  # noqa: RUF012
              ("uart", "*"): "module_write", ("baud", "*"): "module_baud"}

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        self.lines: dict[tuple[int, str], SerialLine] = {}  # host -> module, paced at the host's baud
        self.host_baud: dict[tuple[int, str], int] = {}  # what the host's port is set to (last write)
        self.own: set[tuple[int, str]] = set()  # (robot, role) of a robot model's own modules with a port
        uwb_baud = hub.cfg.uwb.uart_baud
        for r, rp in enumerate(hub.plan.robots):
            if rp.sim_xbee and not rp.xbee.get("pty") and rp.has_logic:
                self.lines[(r, "xbee")] = SerialLine(rp.xbee["baud"])
                self.host_baud[(r, "xbee")] = rp.xbee["baud"]
            if rp.uwb:
                self.lines[(r, "uwb")] = SerialLine(uwb_baud)
                self.host_baud[(r, "uwb")] = uwb_baud
            if rp.gateway is None:  # a robot model's own modules on a serial line
                for role, baud in hub.robot_spec(r).own_ports(rp).items():
                    self.own.add((r, role))
                    if rp.has_logic:
                        self.lines[(r, role)] = SerialLine(baud)
                        self.host_baud[(r, role)] = baud
        self.links: dict[str, Callable[[int, bytes], None]] = {}  # NETWORK_PORTS served by another medium

    def start_quantum(self, t: int) -> None:
        """Bytes that finished crossing a host-to-module serial line by ``t`` go to the module."""
        dead, inbox = self.hub.dead, self.hub.inbox
        for (r, dev), line in self.lines.items():
            if line.pending and r not in dead:
                data = line.arrived(t)
                if data:
                    inbox[entity(r, dev)].append(["uart", data])

    def host_write(self, e: str, r: int, t: int, item: list) -> None:
        """``["uart", dev, bytes, baud]``: the robot's computer wrote to its ``sitl://dev`` port."""
        hub = self.hub
        if item[1] in NETWORK_PORTS:
            link = self.links.get(item[1])
            if link is not None and isinstance(item[2], bytes):
                link(r, item[2])
            else:
                hub.counts["uart_unrouted_writes"] += 1
            return
        _, dev, data, baud = item
        line = self.lines.get((r, dev))
        if line is None or not isinstance(data, bytes) or type(baud) is not int or baud <= 0:
            hub.counts["uart_unrouted_writes"] += 1
            return
        self.host_baud[(r, dev)] = baud
        line.offer(t + hub.q_ns, data, baud)
        hub.rec.write(t, f"/r{r:03d}/{dev}/uart", "swarm_sitl.Uart", {"dir": "to_module", "data": data.hex()})

    def host_baud(self, e: str, r: int, t: int, item: list) -> None:
        """``["baud", dev, rate]``: the host set its port's rate."""
        if item[1] in NETWORK_PORTS:
            return
        _, dev, baud = item
        if (r, dev) not in self.host_baud or type(baud) is not int or baud <= 0:
            raise ValueError
        self.host_baud[(r, dev)] = baud

    def module_write(self, e: str, r: int, t: int, item: list) -> None:
        """``["uart", dev, bytes, baud]`` from a module, already paced at its own rate: to its host at t+q."""
        hub = self.hub
        role = e[e.index("/") + 1:]
        _, dev, data, baud = item
        if not isinstance(data, bytes) or dev != role or (dev not in MODULE_PORTS and (r, dev) not in self.own):
            raise ValueError
        if "logic" not in hub.roles[r]:  # nobody in the session listens on that line
            hub.counts["uart_unrouted_writes"] += 1
            return
        if baud != self.host_baud.get((r, dev), baud):  # the host listens at another rate: garbage
            hub.counts["uart_garbled_bytes"] += len(data)
            data = garble(data)
        q = hub.q_ns
        hub.deliver_at(t + q, hub.to_inbox, entity(r, "logic"), [f"uart:{dev}", data])
        hub.deliver_at(t + q, hub.record, f"/r{r:03d}/{dev}/uart", "swarm_sitl.Uart",
                       {"dir": "to_host", "data": data.hex()})

    def module_baud(self, e: str, r: int, t: int, item: list) -> None:
        """``["baud", dev, rate]``: the module's BD setting changed; the line from its host is sampled at it."""
        role = e[e.index("/") + 1:]
        _, dev, baud = item
        if dev != role or type(baud) is not int or baud <= 0 or (dev not in MODULE_PORTS and (r, dev) not in self.own):
            raise ValueError
        if (r, dev) in self.lines:
            self.lines[(r, dev)].baud = baud
