"""Multi-hop routing for the RDPSO over XBee frames: AODV, and the thesis' RDPSO-based AODV (section 6.2).

The thesis' robots relied on the AODV built into the XBee ZigBee firmware. An emulated module here delivers a
unicast frame to a neighbour in range only, so the routing runs in the robot's logic, on ordinary XBee transmit
requests: routing frames are broadcast (RREQ, RERR) or unicast to a neighbour (RREP, DATA), and every frame
goes through the same module, serial buffer and radio medium as the hellos.

AODV (RFC 3561, the parts the thesis describes): a route request (RREQ) is flooded with the originator's
sequence number, the last known destination sequence number and a TTL; duplicates (same originator and RREQ id)
are dropped; each node keeps a reverse route to the originator; the destination (or a node with a fresher
route) answers with a route reply (RREP) carrying the hop count and its sequence number, unicast back along the
reverse routes; each node keeps only the next hop. Neighbours are known from the RDPSO hellos (each iteration's
position broadcast is the AODV hello); a neighbour silent for ``miss_limit`` (3) iterations, or a unicast to it
that the module reports undelivered, breaks the link: routes over it are invalidated and a route error (RERR,
the thesis' unsolicited route reply with an infinite metric) tells the upstream nodes.

Route requests and replies count only from a neighbour, a robot whose hellos arrive over a link the swarm judges
good (eq. 4.12: RSSI >= q_min, or within d_max). A faint frame still gets through now and then; a route built on
one leaves the MANET the swarm keeps and makes nearly every route one hop, and on real radios such a link is the
"communication gray zone" (Lundgren et al., WoWMoM 2002), where broadcasts arrive and unicasts are often lost.
Their remedy, a signal-strength threshold on control packets, is this rule; such frames are counted
(``control_not_neighbour``) and dropped. Data and route errors are taken from anyone: a packet that arrived is
delivered, and an error only touches routes through its sender.

RDPSO-AODV (``mode = "rdpso"``, Algorithm 6.1): a node forwards a data packet to the neighbour whose *predicted*
next position is nearest the destination's predicted position (eq. 6.3), each neighbour's prediction being one
deterministic step of the RDPSO (eq. 4.11 with r = 1/2, only the cognitive and social terms, digest A on the
sign of eq. 6.2) from its last five positions, its personal best chi_1 (from its improvement packets) and its
subgroup best chi_2 (from its hello). A packet that comes back to a node that already forwarded it, or for whose
destination no position is known, falls back to AODV route discovery.

``mode = "module"`` leaves the routing to the radio, as the thesis' "regular" robots did with the AODV inside their
XBee ZigBee firmware: each data packet goes straight to its destination's 64-bit address (learnt from any frame it
sent, the hellos included), and the module finds the address and the route, relays and retries; its transmit
status says whether the packet arrived. It needs modules that route (an XBee's ``routing = "mesh"``); over one-hop
modules a destination out of range is simply not reached. The logic sees one hop; the hops on the air are the
modules' count (``nwk_data_hops`` over ``nwk_data_delivered`` in the session's summary).

The router owns the radio's transmit side: frames go to the module while their transmit requests fit in its
serial receive buffer (``module_buffer``, 202 bytes: the host honours the module's flow control, as a real host
does with CTS), each until its TX status; the rest wait in a queue of ``buffer`` packets, and a packet that does
not fit there is dropped and counted (the finite buffer of R9). Counters (``stats``) give packets per robot,
time blocked, delivery, routing overhead and hop count.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

MAGIC = 0x41  # "A": routing layer frames
T_RREQ, T_RREP, T_RERR, T_DATA = 1, 2, 3, 4
RREQ = struct.Struct("<BBBBBBHBHBH")  # magic, type, sender, ttl, hops, orig, orig_seq, dest, dest_seq, flags, id
RREP = struct.Struct("<BBBBBHBB")  # magic, type, sender, hops, dest, dest_seq, orig, ttl
RERR_HEAD = struct.Struct("<BBBB")  # magic, type, sender, count; then count x (dest, dest_seq)
RERR_ITEM = struct.Struct("<BH")
DATA = struct.Struct("<BBBBBBBHff")  # magic, type, sender, src, dst, ttl, hops, seq, src_x, src_y; then payload
F_UNKNOWN_SEQ = 1  # RREQ: the originator knows no sequence number for the destination
F_AODV = 1  # DATA: fell back to AODV (a loop, or no position for the destination)
ACTIVE_ROUTE_S = 3.0  # AODV ACTIVE_ROUTE_TIMEOUT (RFC 3561 section 10)
CCA_FAILURE = 0x02  # TX status: the channel stayed busy (CSMA-CA gave up): congestion, not a broken link
CCA_TRIES = 3  # a frame the channel was too busy for is handed to the module again this many times
TX_STATUS_TIMEOUT_S = 6.0  # longer than three APS attempts of a Series 2 module (NH = 30: 1.6 s each)
SEEN_MAX = 512
API_OVERHEAD = 18  # bytes of a Series 2 transmit request around its payload, as the module's buffer holds it


ROUTING_MODES = ("aodv", "rdpso", "module")


def seq_newer(a: int, b: int) -> bool:
    """16-bit sequence number comparison with wrap-around (RFC 3561 section 6.1)."""
    return 0 < ((a - b) & 0xFFFF) < 0x8000


@dataclass(slots=True)
class Route:
    next_hop: int
    hops: int
    seq: int
    valid_seq: bool
    expires: float
    valid: bool = True
    precursors: set[int] = field(default_factory=set)


@dataclass(slots=True)
class Neighbour:
    addr64: int
    last_k: int
    track: deque[tuple[float, float]]  # its last positions, newest first (at most 5)
    chi2: tuple[float, float] | None = None  # its subgroup's best position, from its hello


@dataclass(slots=True)
class _Out:
    dest64: int | None  # None: broadcast
    frame: bytes
    kind: str  # hello | data | control
    hop: int | None = None  # the neighbour a unicast goes to (a failure breaks that link)
    data: tuple[int, int] | None = None  # (src, seq) of a data packet
    busy_tries: int = 0  # times the channel was found busy (CCA failure)


@dataclass(slots=True)
class _Held:
    dst: int
    frame: bytes
    src_seq: tuple[int, int]


STAT_NAMES = ("tx_frames", "tx_hello", "tx_data", "tx_forward", "tx_control", "tx_failed", "tx_channel_busy",
              "tx_status_timeout",
              "rreq_sent", "rreq_forwarded", "rrep_sent", "rerr_sent", "rreq_duplicate", "route_discoveries",
              "discovery_failed", "data_originated", "data_delivered", "data_duplicate", "data_dropped_buffer",
              "data_dropped_no_route", "control_dropped_buffer", "data_dropped_ttl", "data_dropped_link", "loops",
              "geo_forwarded", "aodv_forwarded", "hops_delivered", "link_breaks", "malformed", "rx_frames",
              "control_not_neighbour")


class Router:
    """One robot's routing layer; the RDPSO controller calls ``poll`` every step and ``tick`` every iteration."""

    def __init__(self, me: int, radio: Any, clock: Any, *, mode: str = "rdpso", buffer: int = 16, ttl: int = 10,
                 miss_limit: int = 3, discovery_timeout_s: float = 1.0, discovery_retries: int = 2,
                 module_buffer: int = 202,
                 predict: Callable[[Sequence[tuple[float, float]], tuple[float, float] | None,
                                    tuple[float, float] | None], tuple[float, float]] | None = None) -> None:
        if mode not in ROUTING_MODES:
            raise ValueError(f"routing: {mode!r} is not one of {', '.join(ROUTING_MODES)}")
        self.me = me
        self.radio = radio
        self.clock = clock
        self.mode = mode
        self.buffer = buffer
        self.ttl = ttl
        self.miss_limit = miss_limit
        self.discovery_timeout_s = discovery_timeout_s
        self.discovery_retries = discovery_retries
        self.predict = predict
        self.module_buffer = module_buffer
        self.seq = 0  # own AODV sequence number
        self.rreq_id = 0
        self.data_seq = 0
        self.routes: dict[int, Route] = {}
        self.neighbours: dict[int, Neighbour] = {}
        self.addr: dict[int, int] = {}  # robot id -> 64-bit address, learnt from any frame it sent
        self.where: dict[int, tuple[float, float]] = {}  # last known position of any robot (from data packets)
        self.chi1: dict[int, tuple[float, float]] = {}  # personal best positions (from improvement packets)
        self.txq: deque[_Out] = deque()
        self.inflight: dict[int, tuple[_Out, float]] = {}  # frame id -> (what, when handed to the module)
        self.held: list[_Held] = []  # data waiting for a route
        self.discovery: dict[int, tuple[float, int]] = {}  # dest -> (deadline, tries)
        self.seen_rreq: deque[tuple[int, int]] = deque(maxlen=SEEN_MAX)
        self.forwarded: deque[tuple[int, int]] = deque(maxlen=SEEN_MAX)  # (src, seq) of data passed on
        self.received: deque[tuple[int, int]] = deque(maxlen=SEEN_MAX)
        self.passthrough: deque[Any] = deque()  # packets that are not routing frames (the hellos)
        self.delivered: deque[tuple[int, int, float, float, bytes]] = deque()  # (src, hops, x, y, payload)
        self.stats: dict[str, int] = dict.fromkeys(STAT_NAMES, 0)
        self.busy_since: float | None = None
        self.blocked_s = 0.0  # time the radio had something to send (queue or a frame awaiting its status)

    # -- what the controller calls ----------------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return bool(self.inflight) or bool(self.txq)

    def hello(self, frame: bytes) -> None:
        """Queue this iteration's hello (a local broadcast): it goes first, ahead of data."""
        self._queue(_Out(None, frame, "hello"), front=True)

    def heard(self, rid: int, addr64: int | None, k: int, x: float, y: float,
              chi2: tuple[float, float] | None, link: bool = True) -> None:
        """A hello from ``rid`` in iteration ``k`` (its position; its subgroup best). ``link``: it came over a link
        the swarm counts (its q_min or d_max), so ``rid`` is a one-hop neighbour; otherwise only its address and
        position are noted, and a neighbour heard only so goes silent (a link break after ``miss_limit``)."""
        if addr64 is not None:
            self.addr[rid] = addr64
        if not link:
            self.where[rid] = (x, y)
            return
        nb = self.neighbours.get(rid)
        if nb is None:
            nb = self.neighbours[rid] = Neighbour(self.addr.get(rid, rid), k, deque(maxlen=5))
        nb.addr64 = self.addr.get(rid, nb.addr64)
        nb.last_k = k
        nb.track.appendleft((x, y))
        nb.chi2 = chi2
        self.where[rid] = (x, y)
        now = self.clock.now()
        r = self.routes.get(rid)
        if r is None or not r.valid or r.hops > 1:  # a neighbour is one hop away (AODV: hellos make routes)
            self.routes[rid] = Route(rid, 1, r.seq if r else 0, bool(r and r.valid_seq), now + ACTIVE_ROUTE_S)
        else:
            r.expires = max(r.expires, now + ACTIVE_ROUTE_S)

    def tick(self, k: int) -> None:
        """Iteration ``k`` begins: neighbours silent for ``miss_limit`` iterations are gone (link break)."""
        gone = [rid for rid, nb in self.neighbours.items() if k - nb.last_k > self.miss_limit]
        for rid in gone:
            self._link_break(rid)

    def send(self, dst: int, payload: bytes, x: float, y: float) -> None:
        """Originate a data packet for robot ``dst`` (``x, y``: this robot's position, which travels along)."""
        self.data_seq = (self.data_seq + 1) & 0xFFFF
        self.stats["data_originated"] += 1
        frame = DATA.pack(MAGIC, T_DATA, self.me, self.me, dst, self.ttl, 0, self.data_seq, x, y) + payload
        self._route_data(frame, dst, (self.me, self.data_seq), flags_aodv=False, prev=None)

    def poll(self) -> None:
        """Take the radio's TX statuses and received frames; start discoveries' retries; send the next frame."""
        now = self.clock.now()
        radio = self.radio
        for fid, (out, t0) in list(self.inflight.items()):
            st = radio.tx_result(fid)
            if st is not None:
                del self.inflight[fid]
                if not st.ok and getattr(st, "status", None) == CCA_FAILURE and out.busy_tries < CCA_TRIES:
                    out.busy_tries += 1
                    self.stats["tx_channel_busy"] += 1
                    self.txq.appendleft(out)  # the radio is still ours to use: try again
                elif not st.ok:
                    self.stats["tx_failed"] += 1
                    if out.hop is not None:
                        self._link_break(out.hop)
                        if out.data is not None:
                            self.stats["data_dropped_link"] += 1
            elif now - t0 > TX_STATUS_TIMEOUT_S:
                del self.inflight[fid]
                self.stats["tx_status_timeout"] += 1
        while (pkt := radio.recv(timeout=0)) is not None:
            data = bytes(pkt.data)
            if data[:1] != bytes((MAGIC,)):
                self.passthrough.append(pkt)
                continue
            self.stats["rx_frames"] += 1
            try:
                self._handle(data, pkt.src64)
            except (struct.error, IndexError):
                self.stats["malformed"] += 1
        for dst, (deadline, tries) in list(self.discovery.items()):
            if now < deadline:
                continue
            if tries > self.discovery_retries:
                del self.discovery[dst]
                self.stats["discovery_failed"] += 1
                kept = [h for h in self.held if h.dst != dst]
                self.stats["data_dropped_no_route"] += len(self.held) - len(kept)
                self.held = kept
            else:
                self._discover(dst, tries + 1)
        self._pump(now)

    def recv(self) -> Any:
        """The next received packet that is not a routing frame (for the controller), else None."""
        return self.passthrough.popleft() if self.passthrough else None

    def take_delivered(self) -> Iterator[tuple[int, int, float, float, bytes]]:
        while self.delivered:
            yield self.delivered.popleft()

    # -- sending ----------------------------------------------------------------------------------------------
    def _queue(self, out: _Out, front: bool = False) -> bool:
        if len(self.txq) >= self.buffer:
            self.stats["data_dropped_buffer" if out.data is not None else "control_dropped_buffer"] += 1
            return False
        if front:
            self.txq.appendleft(out)
        else:
            self.txq.append(out)
        return True

    def _pump(self, now: float) -> None:
        held = sum(len(o.frame) + API_OVERHEAD for o, _ in self.inflight.values())
        s = self.stats
        while self.txq and (not self.inflight or held + len(self.txq[0].frame) + API_OVERHEAD <= self.module_buffer):
            out = self.txq.popleft()
            # a broadcast (hello, RREQ, RERR) is for the neighbours: this layer relays what must go further
            fid = self.radio.send_nowait(out.dest64, out.frame, radius=1 if out.dest64 is None else 0)
            self.inflight[fid] = (out, now)
            held += len(out.frame) + API_OVERHEAD
            s["tx_frames"] += 1
            s[{"hello": "tx_hello", "data": "tx_data", "forward": "tx_forward"}.get(out.kind, "tx_control")] += 1
        busy = self.busy
        if busy and self.busy_since is None:
            self.busy_since = now
        elif not busy and self.busy_since is not None:
            self.blocked_s += now - self.busy_since
            self.busy_since = None

    def _unicast(self, hop: int, frame: bytes, kind: str, data: tuple[int, int] | None = None) -> bool:
        return self._queue(_Out(self.addr.get(hop, hop), frame, kind, hop, data))

    def _broadcast(self, frame: bytes) -> None:
        self._queue(_Out(None, frame, "control"))

    # -- data forwarding --------------------------------------------------------------------------------------
    def _route_data(self, frame: bytes, dst: int, key: tuple[int, int], flags_aodv: bool, prev: int | None) -> None:
        kind = "data" if key[0] == self.me else "forward"
        if dst in self.neighbours:  # the destination is a neighbour: straight to it
            self._unicast(dst, frame, kind, key)
            return
        if self.mode == "module":  # the module routes: straight to the destination's address, if it is known
            if dst in self.addr:
                self._unicast(dst, frame, kind, key)
            else:
                self.stats["data_dropped_no_route"] += 1
            return
        if self.mode == "rdpso" and not flags_aodv:
            if key in self.forwarded or (key[0] == self.me and prev is not None):
                self.stats["loops"] += 1  # it came back: fall back to AODV
            else:
                hop = self._geographic(dst, prev)
                if hop is not None:
                    self.forwarded.append(key)
                    self.stats["geo_forwarded"] += 1
                    self._unicast(hop, frame, kind, key)
                    return
            frame = _with_aodv_flag(frame)
        r = self.routes.get(dst)
        now = self.clock.now()
        if r is not None and r.valid and now < r.expires:
            r.expires = now + ACTIVE_ROUTE_S
            self.forwarded.append(key)
            self.stats["aodv_forwarded"] += 1
            self._unicast(r.next_hop, frame, kind, key)
            return
        if len(self.held) + len(self.txq) >= self.buffer:
            self.stats["data_dropped_buffer"] += 1
            return
        self.held.append(_Held(dst, frame, key))
        if dst not in self.discovery:
            self._discover(dst, 1)

    def _geographic(self, dst: int, prev: int | None) -> int | None:
        """Eq. 6.3: the neighbour whose predicted next position is nearest the destination's predicted one."""
        target = self.where.get(dst)
        if target is None or self.predict is None:
            return None
        nd = self.neighbours.get(dst)
        if nd is not None and len(nd.track) >= 2:
            target = self.predict(nd.track, self.chi1.get(dst), nd.chi2)
        best, best_d = None, math.inf
        for rid, nb in self.neighbours.items():
            if rid == prev:
                continue
            px, py = self.predict(nb.track, self.chi1.get(rid), nb.chi2)
            d = math.hypot(px - target[0], py - target[1])
            if d < best_d or (d == best_d and best is not None and rid < best):
                best, best_d = rid, d
        return best

    # -- AODV control -----------------------------------------------------------------------------------------
    def _discover(self, dst: int, tries: int) -> None:
        self.seq = (self.seq + 1) & 0xFFFF
        self.rreq_id = (self.rreq_id + 1) & 0xFFFF
        r = self.routes.get(dst)
        known = r is not None and r.valid_seq
        flags = 0 if known else F_UNKNOWN_SEQ
        self.seen_rreq.append((self.me, self.rreq_id))
        self._broadcast(RREQ.pack(MAGIC, T_RREQ, self.me, self.ttl, 0, self.me, self.seq, dst, r.seq if known else 0,
                                  flags, self.rreq_id))
        self.stats["rreq_sent"] += 1
        if tries == 1:
            self.stats["route_discoveries"] += 1
        # binary exponential backoff of the wait (RFC 3561 section 6.3)
        self.discovery[dst] = (self.clock.now() + self.discovery_timeout_s * 2 ** (tries - 1), tries)

    def _update_route(self, dst: int, hop: int, hops: int, seq: int, valid_seq: bool) -> bool:
        """Take a route to ``dst`` if fresher, or as fresh and shorter (RFC 3561 section 6.2)."""
        now = self.clock.now()
        r = self.routes.get(dst)
        if (r is None or not r.valid or (valid_seq and (not r.valid_seq or seq_newer(seq, r.seq)))
                or ((not valid_seq or seq == r.seq) and hops < r.hops)):
            self.routes[dst] = Route(hop, hops, seq, valid_seq, now + ACTIVE_ROUTE_S,
                                     precursors=r.precursors if r else set())
            return True
        r.expires = max(r.expires, now + ACTIVE_ROUTE_S)
        return False

    def _link_break(self, rid: int) -> None:
        if self.neighbours.pop(rid, None) is not None or any(r.next_hop == rid and r.valid
                                                            for r in self.routes.values()):
            self.stats["link_breaks"] += 1
        if self.mode == "module":  # the module keeps its own routes: nothing of the logic's to repair or report
            return
        broken = []
        for dst, r in self.routes.items():
            if r.valid and r.next_hop == rid:
                r.valid = False
                r.seq = (r.seq + 1) & 0xFFFF
                broken.append((dst, r.seq))
        if broken:
            self._rerr(broken)

    def _rerr(self, broken: list[tuple[int, int]]) -> None:
        broken = broken[:20]
        frame = RERR_HEAD.pack(MAGIC, T_RERR, self.me, len(broken)) + b"".join(RERR_ITEM.pack(d, s) for d, s in broken)
        self._broadcast(frame)
        self.stats["rerr_sent"] += 1

    def _flush(self, dst: int) -> None:
        """A route to ``dst`` arrived: send what waited for it."""
        self.discovery.pop(dst, None)
        waiting = [h for h in self.held if h.dst == dst]
        self.held = [h for h in self.held if h.dst != dst]
        r = self.routes[dst]
        for h in waiting:
            self.forwarded.append(h.src_seq)
            self.stats["aodv_forwarded"] += 1
            self._unicast(r.next_hop, h.frame, "data" if h.src_seq[0] == self.me else "forward", h.src_seq)

    def _handle(self, data: bytes, src64: int | None) -> None:
        kind = data[1]
        sender = data[2]
        if src64 is not None and sender != self.me:
            self.addr[sender] = src64
        if sender == self.me:
            return
        if kind == T_RREQ:
            self._on_rreq(data, sender)
        elif kind == T_RREP:
            self._on_rrep(data, sender)
        elif kind == T_RERR:
            self._on_rerr(data, sender)
        elif kind == T_DATA:
            self._on_data(data, sender)
        else:
            self.stats["malformed"] += 1

    def _from_neighbour(self, sender: int) -> bool:
        """Route control counts only over a link the swarm judges good; a faint one is a gray-zone link."""
        if sender in self.neighbours:
            return True
        self.stats["control_not_neighbour"] += 1
        return False

    def _on_rreq(self, data: bytes, sender: int) -> None:
        _, _, _, ttl, hops, orig, orig_seq, dst, dst_seq, flags, rid = RREQ.unpack(data)
        if not self._from_neighbour(sender):
            return
        if orig == self.me or (orig, rid) in self.seen_rreq:
            self.stats["rreq_duplicate"] += 1
            return
        self.seen_rreq.append((orig, rid))
        hops += 1
        self._update_route(orig, sender, hops, orig_seq, True)
        if sender != orig:
            self._update_route(sender, sender, 1, 0, False)
        if dst == self.me:
            if not flags & F_UNKNOWN_SEQ and seq_newer(dst_seq, self.seq):
                self.seq = dst_seq
            self.seq = (self.seq + 1) & 0xFFFF
            self._reply(self.me, self.seq, 0, orig)
            return
        r = self.routes.get(dst)
        if (r is not None and r.valid and r.valid_seq and self.clock.now() < r.expires
                and (flags & F_UNKNOWN_SEQ or not seq_newer(dst_seq, r.seq))):
            r.precursors.add(sender)
            self._reply(dst, r.seq, r.hops, orig)  # an intermediate node with a fresh enough route answers
            return
        if ttl > 1:
            self._broadcast(RREQ.pack(MAGIC, T_RREQ, self.me, ttl - 1, hops, orig, orig_seq, dst, dst_seq, flags,
                                      rid))
            self.stats["rreq_forwarded"] += 1

    def _reply(self, dst: int, dst_seq: int, hops: int, orig: int) -> None:
        back = self.routes.get(orig)
        if back is None or not back.valid:
            return
        self._unicast(back.next_hop, RREP.pack(MAGIC, T_RREP, self.me, hops, dst, dst_seq, orig, self.ttl),
                      "control")
        self.stats["rrep_sent"] += 1

    def _on_rrep(self, data: bytes, sender: int) -> None:
        _, _, _, hops, dst, dst_seq, orig, ttl = RREP.unpack(data)
        if not self._from_neighbour(sender):
            return
        hops += 1
        self._update_route(dst, sender, hops, dst_seq, True)
        if orig == self.me:
            if dst in self.discovery or any(h.dst == dst for h in self.held):
                self._flush(dst)
            return
        back = self.routes.get(orig)
        if back is None or not back.valid or ttl <= 1:
            return
        self.routes[dst].precursors.add(back.next_hop)
        self._unicast(back.next_hop, RREP.pack(MAGIC, T_RREP, self.me, hops, dst, dst_seq, orig, ttl - 1), "control")
        self.stats["rrep_sent"] += 1

    def _on_rerr(self, data: bytes, sender: int) -> None:
        _, _, _, n = RERR_HEAD.unpack_from(data)
        if len(data) != RERR_HEAD.size + n * RERR_ITEM.size:
            self.stats["malformed"] += 1
            return
        broken = []
        for i in range(n):
            dst, seq = RERR_ITEM.unpack_from(data, RERR_HEAD.size + i * RERR_ITEM.size)
            r = self.routes.get(dst)
            if r is not None and r.valid and r.next_hop == sender:
                r.valid = False
                r.seq = seq
                broken.append((dst, seq))
        if broken:
            self._rerr(broken)

    def _on_data(self, data: bytes, sender: int) -> None:
        _, _, _, src, dst, ttl, hops, seq, x, y = DATA.unpack_from(data)
        flags_aodv = bool(hops & 0x80)
        hops = (hops & 0x7F) + 1
        key = (src, seq)
        if src != self.me:
            self.where[src] = (x, y)
        if dst == self.me:
            if key in self.received:
                self.stats["data_duplicate"] += 1
                return
            self.received.append(key)
            self.stats["data_delivered"] += 1
            self.stats["hops_delivered"] += hops
            self.delivered.append((src, hops, x, y, data[DATA.size:]))
            return
        if ttl <= 1:
            self.stats["data_dropped_ttl"] += 1
            return
        frame = DATA.pack(MAGIC, T_DATA, self.me, src, dst, ttl - 1, min(hops, 0x7F) | (0x80 if flags_aodv else 0),
                          seq, x, y) + data[DATA.size:]
        self._route_data(frame, dst, key, flags_aodv, prev=sender)

    def note_best(self, rid: int, x: float, y: float) -> None:
        """``rid`` improved its personal best at (x, y): its chi_1, for predicting where it goes next."""
        self.chi1[rid] = (x, y)


def _with_aodv_flag(frame: bytes) -> bytes:
    """The data frame marked as routed by AODV from here on (the high bit of its hop count)."""
    b = bytearray(frame)
    b[6] |= 0x80
    return bytes(b)
