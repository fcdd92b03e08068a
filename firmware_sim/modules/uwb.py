"""A DWM1001-class UWB ranging module (nRF52832 + Decawave DW1000), sans-IO and deterministic.

What it does, and where the behaviour comes from:

- **Two-way ranging with every team-mate under a TDMA budget.** The Zebro swarm's module (Agrawal, *Zebro
  swarm*, App. B.2: DW1000 on a DWM1001-DEV, "Anarchic TDMA", agents wait for their turn) shares
  ``frames_per_s`` = 512 UWB frames per second among the whole swarm, aims at a 1 Hz update and works from
  1 to 60 m. One ranging exchange is double-sided two-way ranging with a report (poll, response, final,
  report: ``frames_per_exchange`` = 4 frames; Decawave APS013), so a TDMA slot lasts
  ``frames_per_exchange / frames_per_s`` (7.8125 ms) and the swarm completes at most
  ``frames_per_s / frames_per_exchange`` (128) exchanges per second. Module ``slot`` of ``n_slots`` owns
  slots ``k * n_slots + slot`` (slot clocks assumed synchronised, as AN-TDMA does by predicting the DW1000
  system time from the nRF timers). In each of its turns it ranges the peer whose last range (from either
  end: the responder also learns the result from the final/report) is the oldest, provided that one is at
  least one update period old; ties go round-robin. So a small swarm gets every pair ranged at the update
  rate, and a large one at ``tdma_budget(...)["pair_rate_hz"]`` (see there): with 16 robots about 1.07 Hz,
  capped at 1 Hz; with 32 robots 0.26 Hz.
- **Host UART with the DWM1001 TLV API** (Decawave *DWM1001 Firmware API Guide*): requests and responses
  are type, length, value; every request is answered first by ``0x40 0x01 err`` (0 ok, 1 unknown command or
  broken TLV frame, 2 internal error, 3 invalid parameter). A request ends when the line has been quiet for
  25/32768 s (about 763 us, the API guide's UART delay timer); a frame whose length byte does not match what
  arrived gets error 1. Responses are clocked out at 115200 baud, 8N1.
- **Ranging quality.** ``dwm_loc_get`` lists the new ranges as ``0x48`` entries (address, distance in mm,
  quality factor) and adds a vendor TLV with the DW1000 diagnostics a host needs to spot NLOS: estimated RX
  power, first-path power, an NLOS hint from their difference (Decawave APS006 Part 2: RX - FP below 6 dB
  likely LOS, above 10 dB likely NLOS) and the age of the measurement.

TLV requests understood (all integers little-endian):

==========  ====================  =============================================================================
request     name                  response after ``40 01 00``
==========  ====================  =============================================================================
``03 04``   dwm_upd_rate_set      none; value ``ur u16, ur_static u16`` in 100 ms units (1..600, ur <= static)
``04 00``   dwm_upd_rate_get      ``45 04 ur u16, ur_static u16``
``0C 00``   dwm_loc_get           ``41 0D x y z i32 mm, qf u8`` (no position engine: zeros),
                                  ``48 L cnt u8, cnt x (addr u64, dist u32 mm, qf u8)``,
                                  ``C0 L cnt u8, cnt x (addr u16, rx i16 cdBm, fp i16 cdBm, flags u8, age u16 ms)``
``14 00``   dwm_reset             none; ranging table and schedule restart
``15 00``   dwm_ver_get           ``50 04 fw``, ``51 04 cfg``, ``52 04 hw``
``32 00``   dwm_status_get        ``5A 02 status u16`` (bit 0 location data ready, bit 1 UWB MAC joined)
``A0 00``   swarm_info_get (ven.) ``C1 08 addr16 u16, slot u16, n_slots u16, n_peers u16``
==========  ====================  =============================================================================

``dwm_loc_get`` returns the ranges measured since the previous call (one per peer, the latest), oldest first,
at most 15 (``DWM_LOC_CNT_MAX``); the rest wait for the next call. Vendor flags: bit 0 likely NLOS, bit 1
possibly NLOS (RX - FP between the two thresholds).

Left out: the UART shell mode (two Enters), position engine, anchors, BLE, GPIO, sleep, user data, busy
states, the module's own processing time, and clock drift between slots.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import Any, Protocol

# TLV types (Decawave DWM1001 Firmware API Guide, TLV type list)
CMD_UR_SET = 0x03
CMD_UR_GET = 0x04
CMD_LOC_GET = 0x0C
CMD_RESET = 0x14
CMD_VER_GET = 0x15
CMD_STATUS_GET = 0x32
CMD_SWARM_INFO_GET = 0xA0  # vendor
RET_VAL = 0x40
POS_XYZ = 0x41
UR = 0x45
DIST = 0x48
RNG_AN_POS_DIST = 0x49
FW_VER = 0x50
CFG_VER = 0x51
HW_VER = 0x52
STATUS = 0x5A
VENDOR_QUALITY = 0xC0  # vendor: per-range DW1000 diagnostics
VENDOR_SWARM_INFO = 0xC1  # vendor: address and TDMA slot

ERR_OK = 0
ERR_TLV = 1  # unknown command or broken TLV frame
ERR_INTERNAL = 2
ERR_PARAM = 3

TLV_MAX_SIZE = 255  # DWM1001_TLV_MAX_SIZE: longest request the module buffers
LOC_CNT_MAX = 15  # DWM_LOC_CNT_MAX
FLAG_NLOS = 0x01
FLAG_NLOS_POSSIBLE = 0x02
FW_VERSION = (1, 0, 0, 1)  # maj, min, patch, var of this emulation
CFG_VERSION = 0x00010000
HW_VERSION = 0xDECA002A  # the DWM1001's hardware id


class UwbTiming(Protocol):
    """The configuration fields the module reads (``bridge.media.uwb.UwbCfg`` has them)."""

    frames_per_s: int
    frames_per_exchange: int
    update_rate_hz: float
    uart_baud: int
    uart_gap_ns: int
    los_fp_gap_db: float
    nlos_fp_gap_db: float


def tdma_budget(frames_per_s: int, frames_per_exchange: int, n_robots: int, update_rate_hz: float) -> dict[str, float]:
    """Ranging rates a swarm of ``n_robots`` (one slot each) can reach under the shared frame budget.

    ``turns_per_s``: TDMA turns each module gets; ``swarm_exchanges_per_s``: exchanges the swarm can make;
    ``pair_rate_hz``: ranges per second of each pair of robots (either end initiating, both learn it), the
    update rate or the budget share ``swarm_exchanges_per_s / (n (n - 1) / 2)``, whichever is smaller;
    ``robot_rate_hz``: ranges per second each robot receives, over all its peers.
    """
    swarm = frames_per_s / frames_per_exchange
    n = max(1, n_robots)
    pairs = n * (n - 1) / 2
    pair_rate = min(update_rate_hz, swarm / pairs) if pairs else 0.0
    return {
        "slot_s": frames_per_exchange / frames_per_s,
        "turns_per_s": swarm / n,
        "swarm_exchanges_per_s": swarm,
        "pair_rate_hz": pair_rate,
        "robot_rate_hz": pair_rate * (n - 1),
        "budget_limited": bool(pairs and swarm / pairs < update_rate_hz),
    }


def qf_from_gap(gap_db: float, los_gap_db: float, nlos_gap_db: float) -> int:
    """Quality factor 0..100 from RX - FP power: 100 up to the LOS threshold, 50 at the NLOS one, 0 beyond."""
    span = max(1e-9, nlos_gap_db - los_gap_db)
    q = 100.0 - 50.0 * (gap_db - los_gap_db) / span
    return int(max(0, min(100, round(q))))


def tlv(typ: int, value: bytes = b"") -> bytes:
    """One TLV: type, length, value (length 0..253 per the API guide; 255 hard limit)."""
    if len(value) > 253:
        raise ValueError(f"TLV value of {len(value)} bytes exceeds 253")
    return bytes((typ & 0xFF, len(value))) + bytes(value)


class TdmaSlots:
    """One module's turns in a TDMA frame shared by ``n_slots`` modules: the air carries ``frames_per_s`` frames a
    second, a slot lasts ``frames_per_slot`` frames, and module ``slot`` owns slots ``k * n_slots + slot`` (turn k).
    Integer arithmetic only, so every module agrees on every slot edge."""

    def __init__(self, frames_per_s: int, frames_per_slot: int, slot: int, n_slots: int) -> None:
        if not 0 <= slot < n_slots:
            raise ValueError(f"slot {slot} outside 0..{n_slots - 1}")
        self.fps = frames_per_s
        self.fpt = frames_per_slot
        self.slot = slot
        self.n_slots = n_slots

    def slot_time(self, m: int) -> int:
        """Start of slot ``m`` of the swarm's frame (ns)."""
        return (m * self.fpt * 1_000_000_000) // self.fps

    def turn_time(self, k: int) -> int:
        """Start of this module's turn ``k`` (ns)."""
        return self.slot_time(k * self.n_slots + self.slot)

    def first_turn_at_or_after(self, t: int) -> int:
        """Smallest turn index k >= 0 whose start is at or after ``t``."""
        den = self.fpt * 1_000_000_000
        m = -((-t * self.fps) // den)  # ceil(t * fps / den): first slot starting at or after t
        k = max(0, -((-(m - self.slot)) // self.n_slots))
        while k > 0 and self.turn_time(k - 1) >= t:
            k -= 1
        while self.turn_time(k) < t:
            k += 1
        return k


class PacedTx:
    """A module's UART transmitter: bytes queued at a time leave one every 10 bit times (8N1) after the line is
    free; ``clock_out(t)`` returns those whose last bit has left by ``t``."""

    def __init__(self, baud: int) -> None:
        self.byte_ns = (10 * 1_000_000_000) // int(baud)
        self._tx = bytearray()
        self._next_ns = 0  # completion time of the first queued byte
        self._line_free_ns = 0  # completion time of the last byte queued

    def send(self, t: int, data: bytes) -> None:
        if not data:
            return
        if not self._tx:
            self._next_ns = max(t, self._line_free_ns) + self.byte_ns
        self._tx += data
        self._line_free_ns = max(t, self._line_free_ns) + len(data) * self.byte_ns

    def clock_out(self, t: int) -> bytes:
        if not self._tx or self._next_ns > t:
            return b""
        n = min(len(self._tx), (t - self._next_ns) // self.byte_ns + 1)
        out = bytes(self._tx[:n])
        del self._tx[:n]
        self._next_ns += n * self.byte_ns
        return out

    @property
    def pending(self) -> int:
        """Bytes queued that have not left yet."""
        return len(self._tx)

    def next_wake(self) -> int | None:
        """When the next queued byte has left (None: nothing queued)."""
        return self._next_ns if self._tx else None


@dataclass
class UwbOutput:
    uart_tx: bytes = b""
    requests: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class _Range:
    range_m: float
    rx_dbm: float
    fp_dbm: float
    t_ns: int


class UwbModule:
    """One robot's UWB module: TDMA ranging scheduler, ranging table and TLV UART server.

    ``step(t_ns, uart_rx, events)``: ``uart_rx`` are the host's bytes since the last step (already paced by
    the line); ``events`` the medium's results, ``{"ev": "range", "peer": robot, "ok": bool, "range_m",
    "rx_dbm", "fp_dbm", "t_ns", "responder": bool}`` (extra ground-truth keys are ignored). It returns
    ``UwbOutput(uart_tx, requests)`` with ``{"op": "range", "peer": robot, "t_ns": slot start}`` for every
    TDMA turn up to ``t_ns`` (turns of the quantum just passed run at its end, at their own slot times).
    """

    def __init__(self, *, addr16: int, robot: int, peers: list[tuple[int, int]], slot: int, n_slots: int,
                 rng: Any, cfg: UwbTiming) -> None:
        if not 0 <= slot < n_slots:
            raise ValueError(f"slot {slot} outside 0..{n_slots - 1}")
        self.addr16 = addr16 & 0xFFFF
        self.robot = robot
        self.peers = [(int(r), int(a) & 0xFFFF) for r, a in peers if int(r) != robot]
        self._addr_of = dict(self.peers)
        self.slot = slot
        self.n_slots = n_slots
        self.rng = rng  # kept for interface symmetry; the module itself draws nothing
        self.cfg = cfg
        self.tdma = TdmaSlots(int(cfg.frames_per_s), int(cfg.frames_per_exchange), slot, n_slots)
        self.tx = PacedTx(int(cfg.uart_baud))
        self._gap_ns = int(cfg.uart_gap_ns)
        self.counters: dict[str, int] = {k: 0 for k in (
            "uart_rx_bytes", "uart_tx_bytes", "uart_frames", "uart_broken_frames", "uart_unknown_cmd",
            "uart_bad_param", "uart_overflow_bytes", "loc_get", "range_requests", "ranges_ok", "ranges_failed",
            "ranges_as_responder", "ranges_replaced", "ranges_reported", "events_unknown_peer", "resets")}
        self._reset_state()
        self._rx = bytearray()
        self._rx_deadline: int | None = None
        self._booted = False

    # -- schedule --------------------------------------------------------------------------------------
    def _reset_state(self) -> None:
        self.period_ns = max(1, round(1e9 / float(self.cfg.update_rate_hz)))
        self.ur_static = max(1, round(self.period_ns / 100_000_000))
        self._last: dict[int, int] = {}  # peer robot -> time of its last range attempt or report
        self._rr = 0  # round-robin pointer into self.peers
        self._k: int | None = None  # next turn index
        self._pending: dict[int, _Range] = {}

    def _turn_time(self, k: int) -> int:
        return self.tdma.turn_time(k)

    def _first_turn_at_or_after(self, t: int) -> int:
        return self.tdma.first_turn_at_or_after(t)

    def _next_due(self) -> int | None:
        if not self.peers:
            return None
        if any(p not in self._last for p, _ in self.peers):
            return -(2**62)
        return min(self._last.values()) + self.period_ns

    def _pick(self, t: int) -> int | None:
        best, best_t, best_i = None, None, 0
        n = len(self.peers)
        for off in range(n):
            i = (self._rr + off) % n
            p = self.peers[i][0]
            lt = self._last.get(p)
            if lt is not None and t - lt < self.period_ns:
                continue
            key = -(2**62) if lt is None else lt
            if best_t is None or key < best_t:
                best, best_t, best_i = p, key, i
        if best is not None:
            self._rr = (best_i + 1) % n
        return best

    def _run_turns(self, t: int, out: UwbOutput) -> None:
        while self._k is not None:
            tk = self._turn_time(self._k)
            if tk > t:
                return
            p = self._pick(tk)
            if p is None:
                due = self._next_due()
                if due is None:
                    self._k = None
                    return
                self._k = max(self._k + 1, self._first_turn_at_or_after(due))
                continue
            self._last[p] = tk
            self.counters["range_requests"] += 1
            out.requests.append({"op": "range", "peer": p, "t_ns": tk})
            self._k += 1

    # -- ranging results ---------------------------------------------------------------------------
    def _on_event(self, ev: dict[str, Any]) -> None:
        if ev.get("ev") != "range":
            return
        p = ev.get("peer")
        if p not in self._addr_of:
            self.counters["events_unknown_peer"] += 1
            return
        t_ev = int(ev.get("t_ns", 0))
        if not ev.get("ok"):
            self.counters["ranges_failed"] += 1
            return
        self.counters["ranges_ok"] += 1
        if ev.get("responder", False):
            # the peer ranged us: that pair needs no exchange from this end for one update period
            self.counters["ranges_as_responder"] += 1
            self._last[p] = max(self._last.get(p, t_ev), t_ev)
        if p in self._pending:
            self.counters["ranges_replaced"] += 1
        self._pending[p] = _Range(float(ev["range_m"]), float(ev["rx_dbm"]), float(ev["fp_dbm"]), t_ev)

    # -- UART ---------------------------------------------------------------------------------------
    def _send(self, t: int, data: bytes) -> None:
        self.counters["uart_tx_bytes"] += len(data)
        self.tx.send(t, data)

    def _clock_out(self, t: int) -> bytes:
        return self.tx.clock_out(t)

    def _answer(self, t: int, req: bytes) -> bytes:
        """The full response to one buffered request (its bytes as they arrived between two quiet gaps)."""
        self.counters["uart_frames"] += 1
        if len(req) < 2 or req[1] != len(req) - 2:
            self.counters["uart_broken_frames"] += 1
            return tlv(RET_VAL, bytes((ERR_TLV,)))
        typ, val = req[0], bytes(req[2:])
        ok = tlv(RET_VAL, bytes((ERR_OK,)))
        fixed = {CMD_UR_GET: 0, CMD_LOC_GET: 0, CMD_RESET: 0, CMD_VER_GET: 0, CMD_STATUS_GET: 0,
                 CMD_SWARM_INFO_GET: 0, CMD_UR_SET: 4}
        if typ not in fixed:
            self.counters["uart_unknown_cmd"] += 1
            return tlv(RET_VAL, bytes((ERR_TLV,)))
        if len(val) != fixed[typ]:
            self.counters["uart_broken_frames"] += 1
            return tlv(RET_VAL, bytes((ERR_TLV,)))
        if typ == CMD_LOC_GET:
            return ok + self._loc_tlvs(t)
        if typ == CMD_UR_SET:
            ur, ur_static = struct.unpack("<HH", val)
            if not (1 <= ur <= 600 and ur <= ur_static <= 600):
                self.counters["uart_bad_param"] += 1
                return tlv(RET_VAL, bytes((ERR_PARAM,)))
            self.period_ns = ur * 100_000_000
            self.ur_static = ur_static
            if self.peers:
                self._k = self._first_turn_at_or_after(t)
            return ok
        if typ == CMD_UR_GET:
            return ok + tlv(UR, struct.pack("<HH", max(1, round(self.period_ns / 100_000_000)), self.ur_static))
        if typ == CMD_RESET:
            self.counters["resets"] += 1
            self._reset_state()
            self._k = self._first_turn_at_or_after(t) if self.peers else None
            return ok
        if typ == CMD_VER_GET:
            maj, mnr, patch, var = FW_VERSION
            fw = bytes((var & 0x0F, patch, mnr, maj))
            return ok + tlv(FW_VER, fw) + tlv(CFG_VER, struct.pack("<I", CFG_VERSION)) + tlv(
                HW_VER, struct.pack("<I", HW_VERSION))
        if typ == CMD_STATUS_GET:
            status = (1 if self._pending else 0) | 0x02
            return ok + tlv(STATUS, struct.pack("<H", status))
        # CMD_SWARM_INFO_GET
        return ok + tlv(VENDOR_SWARM_INFO, struct.pack("<HHHH", self.addr16, self.slot & 0xFFFF,
                                                       self.n_slots & 0xFFFF, len(self.peers) & 0xFFFF))

    def _loc_tlvs(self, t: int) -> bytes:
        self.counters["loc_get"] += 1
        order = sorted(self._pending.items(), key=lambda kv: (kv[1].t_ns, kv[0]))[:LOC_CNT_MAX]
        dist = bytearray((len(order),))
        qual = bytearray((len(order),))
        for p, r in order:
            del self._pending[p]
            addr = self._addr_of[p]
            gap = r.rx_dbm - r.fp_dbm
            qf = qf_from_gap(gap, self.cfg.los_fp_gap_db, self.cfg.nlos_fp_gap_db)
            mm = max(0, min(0xFFFFFFFF, round(r.range_m * 1000.0))) if math.isfinite(r.range_m) else 0
            dist += struct.pack("<QIB", addr, mm, qf)
            flags = FLAG_NLOS if gap > self.cfg.nlos_fp_gap_db else (
                FLAG_NLOS_POSSIBLE if gap > self.cfg.los_fp_gap_db else 0)
            age_ms = max(0, min(0xFFFF, (t - r.t_ns) // 1_000_000))
            qual += struct.pack("<HhhBH", addr, _cdb(r.rx_dbm), _cdb(r.fp_dbm), flags, age_ms)
        self.counters["ranges_reported"] += len(order)
        pos = struct.pack("<iiiB", 0, 0, 0, 0)
        return tlv(POS_XYZ, pos) + tlv(DIST, bytes(dist)) + tlv(VENDOR_QUALITY, bytes(qual))

    def _uart(self, t: int, uart_rx: bytes) -> None:
        if self._rx_deadline is not None and t >= self._rx_deadline:
            self._send(self._rx_deadline, self._answer(self._rx_deadline, bytes(self._rx)))
            self._rx.clear()
            self._rx_deadline = None
        if uart_rx:
            self.counters["uart_rx_bytes"] += len(uart_rx)
            # keep one byte more than the longest TLV, so an overlong request still reads as broken (error 1)
            room = TLV_MAX_SIZE + 1 - len(self._rx)
            if len(uart_rx) > room:
                self.counters["uart_overflow_bytes"] += len(uart_rx) - room
            self._rx += uart_rx[: max(0, room)]
            self._rx_deadline = t + self._gap_ns

    # -- host interface ------------------------------------------------------------------------------
    def step(self, t_ns: int, uart_rx: bytes, events: list[dict[str, Any]]) -> UwbOutput:
        """Advance to ``t_ns``: take ranging events and host bytes, run due TDMA turns, clock out the UART."""
        t = int(t_ns)
        out = UwbOutput()
        if not self._booted:
            self._booted = True
            self._k = self._first_turn_at_or_after(t) if self.peers else None
        for ev in events:
            self._on_event(ev)
        self._uart(t, bytes(uart_rx))
        self._run_turns(t, out)
        out.uart_tx = self._clock_out(t)
        return out

    def next_wake(self) -> int | None:
        """Earliest time the module has something to do: end of a request, a byte to clock out, a useful turn."""
        cands = []
        if self._rx_deadline is not None:
            cands.append(self._rx_deadline)
        if (w := self.tx.next_wake()) is not None:
            cands.append(w)
        if self._k is not None:
            due = self._next_due()
            if due is not None:
                k = self._k if due <= self._turn_time(self._k) else max(self._k, self._first_turn_at_or_after(due))
                cands.append(self._turn_time(k))
        return min(cands) if cands else None


def _cdb(dbm: float) -> int:
    """dBm to centi-dBm, saturated to int16."""
    if not math.isfinite(dbm):
        return -32768
    return max(-32768, min(32767, round(dbm * 100.0)))
