"""ZigBee mesh routing inside an XBee ZB module (the network layer of its EmberZNet stack), sans-IO: address and
route discovery, route tables, hop-by-hop unicasts with an end-to-end acknowledgement and retries, and broadcasts
relayed by every router with the broadcast transmission table and passive acknowledgements.

Sources (digested from the XBee ZB manual 90000976 and the ZigBee PRO specification; the EmberZNet constants are
Silicon Labs' "constants from the ZigBee specification" as its stack sets them):

- Unicast: the destination's 16-bit address is found by a broadcast NWK_addr_req when unknown (discovery status
  0x01), a route by AODV route discovery when the destination is not a neighbour and no route is known (0x02): a
  route request (RREQ) broadcast, each router adding its link cost and rebroadcasting a better request after a
  jitter of 2-128 ms, the destination answering each better request with a route reply (RREP) unicast back along
  the reverse path, each node on it learning the route. A request goes out four times from its originator and
  three times from each relay, 254 ms apart (nwkcInitialRREQRetries 3, nwkcRREQRetries 2, nwkcRREQRetryInterval);
  a route reply a hop did not acknowledge is sent again after 400 ms, twice at most; route discovery gives up after
  5 s (both EmberZNet's). The data then goes hop by hop (each hop acknowledged by the MAC, three MAC retries in the
  medium); the destination acknowledges end to end; an unacknowledged attempt is retried after the unicast timeout
  (50 x NH + 100) ms, three attempts in all. Transmit status: 0x00, 0x21 (network ACK failure), 0x24 (address not
  found), 0x25 (route not found); its retry count and discovery status (0x01 | 0x02) say what the delivery cost.
- Route repair: a router that has no route for a frame it must forward discovers one itself and holds the frame
  meanwhile (the NWK header's "discover route" flag, on by default); a frame held longer than a discovery lasts is
  dropped and its source told (network status, no route). A hop that does not acknowledge a frame loses its routes,
  and the source is told (link failure): it forgets its route and discovers a new one for its next attempt.
- Broadcast: every router relays a broadcast it has not seen (radius decremented; BH 0 is the maximum, 2 x NH), after
  a jitter of 0-63 ms, and sends it up to three times in all, 500 ms apart, stopping early once it has heard every
  neighbour relay it (passive acknowledgement). Each broadcast a node originates or relays takes an entry of its
  broadcast transmission table (8 entries, each kept 8 s); a full table relays nothing new, and refuses a broadcast
  from the host (status 0x32, resource error). A broadcast of radius 1 is not relayed, and takes no entry at its
  receivers (an assumption: whether EmberZNet enters one is not published).
- Tables: 16 routes (the least recently used goes first), 8 route discoveries at once (a request beyond that is
  dropped, as Ember drops it), neighbours learned from every frame heard (link cost 1-7 from the received power, as
  Ember maps its LQI) and forgotten after 45 s of silence (three link-status periods; link-status frames themselves
  are not sent, which is an approximation).

Not modelled: many-to-one routes and source routing (AR 0xFF, the default, sends none), route records, link-status
frames, end devices and their parents, security, fragmentation.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass

MS = 1_000_000
DATA, RREQ, RREP, STATUS = 0, 1, 2, 3  # the NWK frame kinds carried (``nwk`` field of an air frame)
NO_ROUTE, LINK_FAILURE = 0x00, 0x01  # network status codes a relay sends back to the source
ACK_REQUESTED, IS_ACK = 0x01, 0x02  # NWK ``flags``: the APS acknowledgement asked for, or this frame is one
ROUTES, DISCOVERIES, BTT_ENTRIES = 16, 8, 8
BTT_NS = 8000 * MS
ROUTE_DISCOVERY_NS = 5000 * MS
PASSIVE_ACK_NS = 500 * MS
BROADCAST_SENDS = 3
INITIAL_RREQ_RETRIES, RREQ_RETRIES, RREQ_RETRY_NS = 3, 2, 254 * MS  # nwkcInitialRREQRetries, nwkcRREQRetries
RREP_RETRIES, RREP_RETRY_NS = 2, 400 * MS  # EmberZNet: a route reply that a hop did not acknowledge, sent again
NEIGHBOUR_AGE_NS = 45_000 * MS
APS_DUP_NS = 5000 * MS
BCAST_ADDRS = frozenset((0xFFFF, 0xFFFD, 0xFFFC))


def valid_nwk(n: object) -> bool:
    """A network header as frames carry it: [kind, source, destination, radius, sequence, source IEEE, APS counter,
    flags]."""
    return (isinstance(n, list | tuple) and len(n) == 8 and all(type(v) is int for v in n)
            and n[0] in (DATA, RREQ, RREP, STATUS) and 0 <= n[1] <= 0xFFFF and 0 <= n[2] <= 0xFFFF and 0 <= n[3] <= 0xFF
            and 0 <= n[4] <= 0xFF and 0 <= n[5] < 1 << 64 and 0 <= n[6] <= 0xFF and 0 <= n[7] <= 0x03)


def air_hops(fr: dict) -> int:
    """The hops a unicast took to get here: the simulation's count that travels with the frame (``hops``), which a
    real frame does not carry (its NWK radius only counts down from a value the receiver does not know)."""
    h = fr.get("hops")
    return h if type(h) is int and 0 < h < 256 else 1


def link_cost(rssi_dbm: float, sensitivity_dbm: float) -> int:
    """ZigBee link cost 1 (strong) .. 7 (at the edge): Ember's LQI-to-cost steps, the LQI taken from the margin
    over the sensitivity (assumed: a 30 dB margin is a perfect link)."""
    margin = rssi_dbm - sensitivity_dbm
    for cost, least in ((1, 30), (2, 24), (3, 18), (5, 12)):
        if margin >= least:
            return cost
    return 7


STAT_KEYS = ("relayed", "relay_no_route", "relay_link_failures", "status_sent", "bcast_relayed", "btt_full",
             "rreq_sent", "rrep_sent", "route_found", "route_not_found", "address_not_found", "aps_acks",
             "aps_duplicates", "discovery_table_full", "data_delivered", "data_hops")


class StatsView:
    """The network layer's counts, kept in the module's counters under ``nwk_<name>`` (so that they reach the
    session's summary with the module's other counters) and read here by their short names."""

    def __init__(self, counters: dict[str, int]) -> None:
        self.c = counters

    def __getitem__(self, k: str) -> int:
        return self.c["nwk_" + k]

    def __setitem__(self, k: str, v: int) -> None:
        self.c["nwk_" + k] = v


@dataclass
class MacFrame:
    """One frame for the radio: to a neighbour (``dst16``) or a broadcast (None); ``on_done(t, status)``."""

    dst16: int | None
    payload: bytes
    aps: tuple[int, int, int, int]
    nwk: list[int]
    on_done: Callable[[int, str], None] | None = None
    handle: int = -1
    hops: int = 1  # transmissions this frame has taken so far, this one included (the statistics' count, not on air)


@dataclass
class Tx:
    """A unicast on its way: the host's, or one of the module's own (an answer, an acknowledgement)."""

    job: object  # the module's _TxJob
    dest64: int
    dst16: int | None
    ack: bool
    counter: int
    attempts: int = 0
    disc: int = 0
    state: str = "new"  # "addr" (finding the address), "route" (finding a route), "sent" (awaiting the ack)
    token: int = 0  # which timer is current


@dataclass
class Discovery:
    """A route discovery this node runs or relays (its row in the route discovery table)."""

    reverse: int  # the neighbour the best request came from (the originator's own: itself)
    cost: int
    expires: int
    target: int = -1  # the destination sought (known to the originator)
    found: bool = False  # the originator has its route: a later need for one starts a new discovery


class Nwk:
    """The network layer of one module. ``m`` is the XBee module: it sends ``MacFrame`` s for it (``m.mac_send``),
    keeps its timers (``m._at_event``), hands it what the air brought (``on_rx``) and takes what reaches it."""

    def __init__(self, m) -> None:
        self.m = m
        self.reset()

    def reset(self) -> None:
        self.routes: OrderedDict[int, tuple[int, int]] = OrderedDict()  # dst16 -> (next hop, path cost)
        self.discoveries: dict[tuple[int, int], Discovery] = {}  # (originator, request id) -> row
        self.neighbours: dict[int, tuple[int, int, int]] = {}  # nwk16 -> (ieee, link cost, last heard)
        self.addresses: dict[int, int] = {}  # ieee -> nwk16, learned from every NWK header heard
        self.btt: dict[tuple[int, int], dict] = {}  # (source, sequence) -> {"until", "heard", "sends", ...}
        self.txs: dict[int, Tx] = {}  # APS counter -> a unicast of this node awaiting its acknowledgement
        self.addr_wait: dict[int, list[Tx]] = {}  # ieee -> unicasts waiting for its address
        self.held: dict[int, list[tuple[int, MacFrame]]] = {}  # dst16 -> (since, frame): relays and acks awaiting
        # a route this node is discovering (a router discovers the route of a frame it cannot forward, as the NWK
        # header's "discover route" flag asks by default)
        self.seen_aps: dict[tuple[int, int], int] = {}  # (source, counter) -> when: duplicates from retries
        self.q: deque[MacFrame] = deque()
        self.busy: MacFrame | None = None
        self.by_handle: dict[int, MacFrame] = {}
        self.seq = int(self.m.rng.integers(0, 256))
        self.rreq_id = int(self.m.rng.integers(0, 256))
        self.counter = int(self.m.rng.integers(0, 256))
        self.stats = StatsView(self.m.counters)  # counted with the module's counters, as nwk_*

    # -- what the module asks ------------------------------------------------------------------------------------
    @property
    def me(self) -> int:
        return self.m._nwk

    def radius(self, hops: int) -> int:
        return hops if hops else 2 * int(self.m._set["NH"])

    def start(self, t: int, job) -> None:
        """A unicast or broadcast from the queue (the host's, or the module's own); ends in ``m._finish``."""
        if job.dst == "bcast":
            status = self.broadcast(t, job.aps, job.payload, self.radius(job.radius), job.dest16)
            self.m._finish(t, job, status)
            return
        self.counter = (self.counter + 1) & 0xFF
        dst16 = job.dest16 if job.dest16 < 0xFFF8 else self.addresses.get(job.dest64)
        if job.dest64 == 0 and job.dest16 >= 0xFFF8:
            dst16 = 0x0000  # the coordinator
        tx = Tx(job, job.dest64, dst16, ack=not job.opts & 0x01, counter=self.counter)
        self.txs[tx.counter] = tx
        self._route(t, tx)

    def broadcast(self, t: int, aps: tuple, payload: bytes, radius: int, dst16: int = 0xFFFF) -> int:
        """Originate a network broadcast: 0x00, or 0x32 when the broadcast transmission table is full."""
        self._expire_btt(t)
        if len(self.btt) >= BTT_ENTRIES:
            self.stats["btt_full"] += 1
            return 0x32
        self.seq = (self.seq + 1) & 0xFF
        dst = dst16 if dst16 in BCAST_ADDRS else 0xFFFF
        nwk = [DATA, self.me, dst, radius, self.seq, self.m.serial64, 0, 0]
        self._relay_broadcast(t, MacFrame(None, payload, tuple(aps), nwk), first=True)
        return 0x00

    def mac_done(self, t: int, handle: int, status: str) -> bool:
        """The radio finished a frame (True if it was one of ours)."""
        f = self.by_handle.pop(handle, None)
        if f is None:
            return False
        self.busy = None
        if f.on_done is not None:
            f.on_done(t, status)
        self.pump(t)
        return True

    def pump(self, t: int) -> None:
        if self.busy is None and self.q:
            f = self.q.popleft()
            self.busy = f
            f.handle = self.m.mac_send(t, f)
            self.by_handle[f.handle] = f

    def _send(self, t: int, f: MacFrame) -> None:
        self.q.append(f)
        self.pump(t)

    # -- unicast -------------------------------------------------------------------------------------------------
    def _next_hop(self, t: int, dst16: int) -> int | None:
        n = self.neighbours.get(dst16)
        if n is not None and t - n[2] < NEIGHBOUR_AGE_NS:
            return dst16
        r = self.routes.get(dst16)
        if r is not None:
            self.routes.move_to_end(dst16)
            return r[0]
        return None

    def _route(self, t: int, tx: Tx) -> None:
        if tx.dst16 is None:  # the address first: a broadcast NWK_addr_req for the IEEE address
            tx.disc |= 0x01
            tx.state = "addr"
            waiting = self.addr_wait.setdefault(tx.dest64, [])
            waiting.append(tx)
            if len(waiting) == 1:
                self.m._zdo_nwk_addr_req(t, tx.dest64)
            tx.token += 1
            self.m._at_event(t + ROUTE_DISCOVERY_NS, "nwk_timeout", (tx.counter, tx.token))
            return
        if self._next_hop(t, tx.dst16) is not None:
            self._send_data(t, tx)
            return
        tx.disc |= 0x02
        tx.state = "route"
        tx.token += 1
        self.m._at_event(t + ROUTE_DISCOVERY_NS, "nwk_timeout", (tx.counter, tx.token))
        self._discover(t, tx.dst16)

    def _send_data(self, t: int, tx: Tx) -> None:
        hop = self._next_hop(t, tx.dst16)
        if hop is None:
            self._route(t, tx)
            return
        job = tx.job
        tx.attempts += 1
        tx.state = "sent"
        tx.token += 1
        token = tx.token
        nwk = [DATA, self.me, tx.dst16, self.radius(job.radius), self._next_seq(), self.m.serial64, tx.counter,
               ACK_REQUESTED if tx.ack else 0]

        def done(t2: int, status: str, tx: Tx = tx, token: int = token) -> None:
            if tx.token != token or self.txs.get(tx.counter) is not tx:
                return
            if status != "ok":  # the first hop did not acknowledge: its route is gone; try again, or give up
                self._forget(tx.dst16, hop)
                self._retry(t2, tx)
            elif not tx.ack:
                self._end(t2, tx, 0x00)
            else:
                self.m._at_event(t2 + self.m._unicast_timeout_ns(), "nwk_ack_due", (tx.counter, token))

        self._send(t, MacFrame(hop, job.payload, tuple(job.aps), nwk, done))

    def _retry(self, t: int, tx: Tx) -> None:
        if tx.attempts >= 3:
            self._end(t, tx, 0x21)
        else:
            self._route(t, tx)

    def _end(self, t: int, tx: Tx, status: int) -> None:
        self.txs.pop(tx.counter, None)
        tx.token += 1
        job = tx.job
        job.attempts = max(tx.attempts, 1)
        job.disc = tx.disc
        job.dest16_found = tx.dst16 if status == 0 else None
        self.m._finish(t, job, status)

    def on_timer(self, t: int, what: str, arg: tuple) -> None:
        counter, token = arg
        tx = self.txs.get(counter)
        if tx is None or tx.token != token:
            return
        if what == "nwk_ack_due":
            self._retry(t, tx)
        elif tx.state == "addr":
            self.stats["address_not_found"] += 1
            waiting = self.addr_wait.get(tx.dest64, [])
            if tx in waiting:
                waiting.remove(tx)
            self._end(t, tx, 0x24)
        elif tx.state == "route":
            self.stats["route_not_found"] += 1
            self._end(t, tx, 0x25)

    def learned_address(self, t: int, ieee: int, nwk16: int) -> None:
        """A NWK_addr_rsp (or any header) gave ``ieee``'s address: the unicasts waiting for it go on."""
        self.addresses[ieee] = nwk16
        for tx in self.addr_wait.pop(ieee, []):
            if self.txs.get(tx.counter) is tx:
                tx.dst16 = nwk16
                self._route(t, tx)

    def _forget(self, dst16: int, hop: int) -> None:
        if self.routes.get(dst16, (None,))[0] == hop:
            del self.routes[dst16]
        self.neighbours.pop(hop, None)
        for d, (nh, _) in list(self.routes.items()):
            if nh == hop:
                del self.routes[d]

    def _learn_route(self, dst16: int, hop: int, cost: int, fresh: bool = False) -> None:
        """A route to ``dst16`` through ``hop``: kept if cheaper than the known one, or ``fresh`` (from a route
        discovery under way, which supersedes what older ones found)."""
        old = self.routes.get(dst16)
        if not fresh and old is not None and old[1] <= cost and old[0] != hop:
            return
        self.routes[dst16] = (hop, cost)
        self.routes.move_to_end(dst16)
        while len(self.routes) > ROUTES:
            self.routes.popitem(last=False)

    def _tell_source(self, t: int, src: int, dst: int, code: int) -> None:
        """Network status to the source of a frame this relay could not forward (if it knows the way back)."""
        hop = self._next_hop(t, src)
        if hop is None or src == self.me:
            return
        self.stats["status_sent"] += 1
        self._send(t, MacFrame(hop, bytes((code,)) + dst.to_bytes(2, "big"), (0, 0, 0, 0),
                               [STATUS, self.me, src, self.radius(0), self._next_seq(), self.m.serial64, 0, 0]))

    def _on_status(self, t: int, body: bytes) -> None:
        """A relay could not forward to ``dst``: forget the route; a unicast awaiting its acknowledgement tries again
        at once, with a new route discovery."""
        if len(body) < 3:
            return
        dst = int.from_bytes(body[1:3], "big")
        self.routes.pop(dst, None)
        for tx in list(self.txs.values()):
            if tx.dst16 == dst and tx.state == "sent":
                self._retry(t, tx)

    # -- route discovery -----------------------------------------------------------------------------------------
    def _discover(self, t: int, dst16: int) -> None:
        """Start a route discovery for ``dst16`` unless one runs; what waits for it goes on in ``_route_ready``."""
        for (orig, _), d in self.discoveries.items():
            if orig == self.me and d.target == dst16 and d.expires > t and not d.found:
                return
        self._expire_discoveries(t)
        if len(self.discoveries) >= DISCOVERIES:
            self.stats["discovery_table_full"] += 1
            return  # the timers end what waits: route not found
        self.rreq_id = (self.rreq_id + 1) & 0xFF
        self.discoveries[(self.me, self.rreq_id)] = Discovery(self.me, 0, t + ROUTE_DISCOVERY_NS, target=dst16)
        self.stats["rreq_sent"] += 1
        body = bytes((self.rreq_id,)) + dst16.to_bytes(2, "big") + bytes((0,))
        nwk = [RREQ, self.me, 0xFFFC, self.radius(0), self._next_seq(), self.m.serial64, 0, 0]
        self.rreq_timer(t, (MacFrame(None, body, (0, 0, 0, 0), nwk), 1 + INITIAL_RREQ_RETRIES))

    def _route_ready(self, t: int, dst16: int) -> None:
        """A route to ``dst16`` was found: the frames held for it and the unicasts waiting for it go."""
        for _, f in self.held.pop(dst16, []):
            hop = self._next_hop(t, dst16)
            if hop is not None:
                self._send(t, MacFrame(hop, f.payload, f.aps, f.nwk, self._hop_failed(hop, dst16, f.nwk[1]),
                                       hops=f.hops))
        for tx in list(self.txs.values()):
            if tx.state == "route" and tx.dst16 == dst16:
                self._send_data(t, tx)

    def _forward(self, t: int, f: MacFrame, dst16: int) -> None:
        """Send ``f`` towards ``dst16`` (through its next hop), or hold it while this node discovers a route; held
        longer than a route discovery lasts, it is dropped and its source told. A hop that does not acknowledge it
        loses its routes, and the source is told (link failure)."""
        hop = self._next_hop(t, dst16)
        if hop is not None:
            self._send(t, MacFrame(hop, f.payload, f.aps, f.nwk, self._hop_failed(hop, dst16, f.nwk[1]), hops=f.hops))
            return
        self.held.setdefault(dst16, []).append((t, f))
        self._discover(t, dst16)
        self.m._at_event(t + ROUTE_DISCOVERY_NS, "nwk_held_due", dst16)

    def _hop_failed(self, hop: int, dst16: int, src: int) -> Callable[[int, str], None]:
        def done(t: int, status: str) -> None:
            if status != "ok":
                self.stats["relay_link_failures"] += 1
                self._forget(dst16, hop)
                self._tell_source(t, src, dst16, LINK_FAILURE)

        return done

    def held_timer(self, t: int, dst16: int) -> None:
        keep = []
        for since, f in self.held.pop(dst16, []):
            if t - since < ROUTE_DISCOVERY_NS:
                keep.append((since, f))
            else:
                self.stats["relay_no_route"] += 1
                self._tell_source(t, f.nwk[1], dst16, NO_ROUTE)
        if keep:
            self.held[dst16] = keep

    def _expire_discoveries(self, t: int) -> None:
        for k in [k for k, d in self.discoveries.items() if d.expires <= t]:
            del self.discoveries[k]

    def _on_rreq(self, t: int, mac_src: int, nwk: list[int], body: bytes, cost_in: int) -> None:
        if len(body) < 4 or nwk[1] == self.me:
            return
        rid, dst16, cost = body[0], int.from_bytes(body[1:3], "big"), body[3] + cost_in
        key = (nwk[1], rid)
        self._expire_discoveries(t)
        d = self.discoveries.get(key)
        if d is not None and d.cost <= cost:
            return
        if d is None and len(self.discoveries) >= DISCOVERIES:
            self.stats["discovery_table_full"] += 1
            return
        self.discoveries[key] = Discovery(mac_src, cost, t + ROUTE_DISCOVERY_NS)
        self._learn_route(nwk[1], mac_src, cost, fresh=True)  # the reverse route: the answer and acks go back on it
        if dst16 == self.me:
            self.stats["rrep_sent"] += 1
            rep = bytes((rid,)) + nwk[1].to_bytes(2, "big") + self.me.to_bytes(2, "big") + bytes((0,))
            self._send_rrep(t, MacFrame(mac_src, rep, (0, 0, 0, 0), [RREP, self.me, nwk[1], self.radius(0),
                                                                    self._next_seq(), self.m.serial64, 0, 0]))
        elif nwk[3] > 1:
            fwd = bytes((rid,)) + dst16.to_bytes(2, "big") + bytes((min(cost, 0xFF),))
            f = MacFrame(None, fwd, (0, 0, 0, 0), [RREQ, nwk[1], 0xFFFC, nwk[3] - 1, nwk[4], nwk[5], 0, 0])
            self.m._at_event(t + int(self.m.rng.integers(2, 129)) * MS, "nwk_rreq", (f, 1 + RREQ_RETRIES))

    def rreq_timer(self, t: int, arg: tuple[MacFrame, int]) -> None:
        """Send a route request, and again 254 ms later while it has sends left (retries are not cut short by
        passive acknowledgements)."""
        f, left = arg
        self._send(t, MacFrame(None, f.payload, f.aps, list(f.nwk)))
        if left > 1:
            self.m._at_event(t + RREQ_RETRY_NS, "nwk_rreq", (f, left - 1))

    def _on_rrep(self, t: int, mac_src: int, body: bytes, cost_in: int) -> None:
        if len(body) < 6:
            return
        rid, orig, resp, cost = body[0], int.from_bytes(body[1:3], "big"), int.from_bytes(body[3:5], "big"), \
            body[5] + cost_in
        self._learn_route(resp, mac_src, cost, fresh=True)
        d = self.discoveries.get((orig, rid))
        if d is None:
            return
        if orig == self.me:
            if not d.found:
                self.stats["route_found"] += 1
            d.found = True
            self._route_ready(t, resp)
            return
        fwd = bytes((rid,)) + orig.to_bytes(2, "big") + resp.to_bytes(2, "big") + bytes((min(cost, 0xFF),))
        self._send_rrep(t, MacFrame(d.reverse, fwd, (0, 0, 0, 0), [RREP, resp, orig, self.radius(0),
                                                                  self._next_seq(), self.m.serial64, 0, 0]))

    def _send_rrep(self, t: int, f: MacFrame, left: int = RREP_RETRIES) -> None:
        """A route reply to the previous hop; sent again 400 ms later, twice at most, if that hop did not
        acknowledge it (its neighbours relaying the request's flood are the usual reason)."""

        def done(t2: int, status: str) -> None:
            if status != "ok" and left > 0:
                self.m._at_event(t2 + RREP_RETRY_NS, "nwk_rrep", (f, left - 1))

        self._send(t, MacFrame(f.dst16, f.payload, f.aps, list(f.nwk), done))

    def rrep_timer(self, t: int, arg: tuple[MacFrame, int]) -> None:
        self._send_rrep(t, *arg)

    # -- broadcast -----------------------------------------------------------------------------------------------
    def _expire_btt(self, t: int) -> None:
        for k in [k for k, e in self.btt.items() if e["until"] <= t]:
            del self.btt[k]

    def _relay_broadcast(self, t: int, f: MacFrame, first: bool = False) -> None:
        """Take the broadcast's table entry and send it (at once from its originator, after a jitter from a relay),
        then again every 500 ms until every neighbour was heard relaying it or it went out three times."""
        key = (f.nwk[1], f.nwk[4])
        entry = {"until": t + BTT_NS, "heard": set(), "sends": 0, "frame": f,
                 "expect": {n for n, (_, _, last) in self.neighbours.items() if t - last < NEIGHBOUR_AGE_NS}}
        self.btt[key] = entry
        delay = 0 if first else int(self.m.rng.integers(0, 64)) * MS
        self.m._at_event(t + delay, "nwk_bcast", key)

    def bcast_timer(self, t: int, key: tuple[int, int]) -> None:
        e = self.btt.get(key)
        if e is None or e["sends"] >= BROADCAST_SENDS or (e["sends"] and e["expect"] <= e["heard"]):
            return
        e["sends"] += 1
        f = e["frame"]
        self._send(t, MacFrame(None, f.payload, f.aps, list(f.nwk)))
        self.m._at_event(t + PASSIVE_ACK_NS, "nwk_bcast", key)

    # -- receive -------------------------------------------------------------------------------------------------
    def _next_seq(self) -> int:
        self.seq = (self.seq + 1) & 0xFF
        return self.seq

    def on_rx(self, t: int, fr: dict, rssi: int) -> tuple[int, int, bool] | None:
        """A frame the MAC accepted. Returns (source IEEE, source NWK, broadcast) when its data is for this node
        (the module delivers it), else None (a relay, a routing frame, a duplicate)."""
        mac_src, mac_ieee = fr["src16"], fr["src64"]
        cost = link_cost(rssi, self.m.prof.sensitivity_dbm)
        if mac_src < 0xFFF8:
            self.neighbours[mac_src] = (mac_ieee, cost, t)
            self.addresses[mac_ieee] = mac_src
        nwk = fr.get("nwk")
        if nwk is None:  # a frame without a network header: one hop, as sent
            return mac_ieee, mac_src, fr["dst"] == "bcast"
        kind, src, dst, radius, seq, src64, counter, flags = nwk
        if src != self.me and src < 0xFFF8:
            self.addresses[src64] = src
        if kind == RREQ:
            if (e := self.btt.get((src, seq))) is not None:
                e["heard"].add(mac_src)
                return None
            self._on_rreq(t, mac_src, nwk, fr["payload"], cost)
            return None
        if kind == RREP:
            self._on_rrep(t, mac_src, fr["payload"], cost)
            return None
        if fr["dst"] == "bcast":
            self._expire_btt(t)
            key = (src, seq)
            if key in self.btt:
                self.btt[key]["heard"].add(mac_src)  # a neighbour relayed it: a passive acknowledgement
                return None
            if src == self.me:
                return None
            if len(self.btt) >= BTT_ENTRIES:
                self.stats["btt_full"] += 1  # not relayed; still heard
            elif radius > 1:
                self.stats["bcast_relayed"] += 1
                self._relay_broadcast(t, MacFrame(None, fr["payload"], tuple(fr.get("aps", (0, 0, 0, 0))),
                                                  [kind, src, dst, radius - 1, seq, src64, counter, flags]))
            return src64, src, True
        if kind == STATUS:
            if dst == self.me:
                self._on_status(t, fr["payload"])
            elif (hop := self._next_hop(t, dst)) is not None and radius > 1:
                self._send(t, MacFrame(hop, fr["payload"], (0, 0, 0, 0), [STATUS, src, dst, radius - 1, seq, src64,
                                                                         0, 0]))
            return None
        if dst != self.me:  # a relay: on towards the destination (discovering a route if need be), or dropped
            if radius <= 1:
                self.stats["relay_no_route"] += 1
                return None
            self.stats["relayed"] += 1
            self._forward(t, MacFrame(None, fr["payload"], tuple(fr.get("aps", (0, 0, 0, 0))),
                                      [kind, src, dst, radius - 1, seq, src64, counter, flags],
                                      hops=air_hops(fr) + 1), dst)
            return None
        if src != mac_src:
            self._learn_route(src, mac_src, cost)  # the way back to the source, for its acknowledgement
        if flags & IS_ACK:
            tx = self.txs.get(counter)
            if tx is not None and tx.state == "sent" and tx.dst16 == src:
                self.stats["aps_acks"] += 1
                self._end(t, tx, 0x00)
            return None
        if flags & ACK_REQUESTED:
            self._forward(t, MacFrame(None, b"", tuple(fr.get("aps", (0, 0, 0, 0))),
                                      [DATA, self.me, src, self.radius(0), self._next_seq(), self.m.serial64, counter,
                                       IS_ACK]), src)
            key = (src, counter)
            seen = self.seen_aps.get(key)
            self.seen_aps[key] = t
            if seen is not None and t - seen < APS_DUP_NS:
                self.stats["aps_duplicates"] += 1
                return None
            if len(self.seen_aps) > 256:
                self.seen_aps = {k: v for k, v in self.seen_aps.items() if t - v < APS_DUP_NS}
        return src64, src, False
