"""Host driver for a DWM1001-class UWB module over any pyserial port (SITL URL port, pty, /dev/ttyUSB0).

It speaks the DWM1001 TLV API (Decawave *DWM1001 Firmware API Guide*): a request is ``type, length, value``;
the module answers ``0x40 0x01 err`` and, when ``err`` is 0, the response TLVs of that command. Single
threaded, no wall clock: every wait is ``port.read`` with ``port.timeout`` set to what is left of a deadline
on the ``Clock`` (simulated time in SITL). Before each request the input is flushed, so a late answer to an
earlier, timed-out request cannot be mistaken for this one.

``loc_get()`` returns the ranges measured since the last call as ``RangeReading``s. A stock DWM1001 reports
address, distance and quality factor; the swarm firmware also sends a vendor TLV (0xC0) with the DW1000
diagnostics (RX and first-path power, NLOS hint, age), detected once by ``identify()`` (vendor request 0xA0;
a stock module answers it with error 1). TLV layouts: see ``firmware_sim/modules/uwb.py`` and docs/uwb.md.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from swarm_logic.clock import Clock

CMD_UR_SET, CMD_UR_GET, CMD_LOC_GET, CMD_RESET, CMD_VER_GET, CMD_STATUS_GET = 0x03, 0x04, 0x0C, 0x14, 0x15, 0x32
CMD_SWARM_INFO_GET = 0xA0
RET_VAL, POS_XYZ, UR, DIST, RNG_AN_POS_DIST = 0x40, 0x41, 0x45, 0x48, 0x49
FW_VER, CFG_VER, HW_VER, STATUS = 0x50, 0x51, 0x52, 0x5A
VENDOR_QUALITY, VENDOR_SWARM_INFO = 0xC0, 0xC1
FLAG_NLOS, FLAG_NLOS_POSSIBLE = 0x01, 0x02
ERRORS = {1: "unknown command or broken TLV frame", 2: "internal error", 3: "invalid parameter", 4: "busy",
          5: "operation not permitted"}


class UwbError(Exception):
    """The module answered with a non-zero status (``status``), or could not be understood."""

    def __init__(self, status: int, msg: str | None = None) -> None:
        super().__init__(msg or f"UWB module error {status}: {ERRORS.get(status, 'unknown')}")
        self.status = status


class UwbTimeout(UwbError):
    def __init__(self, msg: str = "no answer from the UWB module") -> None:
        super().__init__(-1, msg)


class UwbProtocolError(UwbError):
    def __init__(self, msg: str) -> None:
        super().__init__(-2, msg)


@dataclass(frozen=True)
class RangeReading:
    """One range to a peer. ``t`` is the clock time of the measurement when the module gave its age, else
    the time it was read; ``rx_dbm``/``fp_dbm``/``age_s`` are None from a stock module."""

    addr16: int
    range_m: float
    qf: int
    t: float
    rx_dbm: float | None = None
    fp_dbm: float | None = None
    nlos: bool = False
    nlos_possible: bool = False
    age_s: float | None = None


@dataclass(frozen=True)
class UwbInfo:
    fw_version: tuple[int, int, int, int]  # major, minor, patch, variant
    cfg_version: int
    hw_version: int
    swarm: dict[str, int] | None  # addr16, slot, n_slots, n_peers (swarm firmware only)


def parse_tlvs(data: bytes) -> list[tuple[int, bytes]]:
    """Split a byte string into TLVs; raises ``UwbProtocolError`` when the last one is truncated."""
    out, i = [], 0
    while i < len(data):
        if i + 2 > len(data) or i + 2 + data[i + 1] > len(data):
            raise UwbProtocolError(f"truncated TLV at byte {i}")
        out.append((data[i], bytes(data[i + 2:i + 2 + data[i + 1]])))
        i += 2 + data[i + 1]
    return out


def decode_loc(tlvs: list[tuple[int, bytes]], t_read: float) -> list[RangeReading]:
    """The ranges in a ``dwm_loc_get`` response (the TLVs after the status), validated field by field."""
    dist: list[tuple[int, int, int]] = []
    qual: dict[int, tuple[float, float, int, int]] = {}
    for typ, val in tlvs:
        if typ == POS_XYZ:
            if len(val) != 13:
                raise UwbProtocolError(f"position TLV of {len(val)} bytes, expected 13")
        elif typ in (DIST, RNG_AN_POS_DIST):
            size = 13 if typ == DIST else 20
            if not val or len(val) != 1 + val[0] * size:
                raise UwbProtocolError(f"distance TLV 0x{typ:02X} of {len(val)} bytes does not match its count")
            for k in range(val[0]):
                e = val[1 + k * size:1 + (k + 1) * size]
                addr, mm, qf = struct.unpack_from("<QIB", e) if typ == DIST else struct.unpack_from("<HIB", e)
                dist.append((addr & 0xFFFF, mm, qf))
        elif typ == VENDOR_QUALITY:
            if not val or len(val) != 1 + val[0] * 9:
                raise UwbProtocolError(f"quality TLV of {len(val)} bytes does not match its count")
            for k in range(val[0]):
                addr, rx, fp, flags, age = struct.unpack_from("<HhhBH", val, 1 + k * 9)
                qual[addr] = (rx / 100.0, fp / 100.0, flags, age)
        # other TLVs are ignored, as Decawave's host library does
    out = []
    for addr, mm, qf in dist:
        q = qual.get(addr)
        if q is None:
            out.append(RangeReading(addr, mm / 1000.0, qf, t_read))
        else:
            rx, fp, flags, age = q
            out.append(RangeReading(addr, mm / 1000.0, qf, t_read - age / 1000.0, rx, fp,
                                    bool(flags & FLAG_NLOS), bool(flags & FLAG_NLOS_POSSIBLE), age / 1000.0))
    return out


# TLVs that follow a successful status, per command (the vendor TLV is added when the module has it)
_FOLLOW = {CMD_UR_SET: 0, CMD_UR_GET: 1, CMD_LOC_GET: 2, CMD_RESET: 0, CMD_VER_GET: 3, CMD_STATUS_GET: 1,
           CMD_SWARM_INFO_GET: 1}


class Uwb:
    """A DWM1001-class module on ``port``; all timeouts in ``clock`` seconds."""

    def __init__(self, port: Any, clock: Clock, *, timeout: float = 0.5, vendor: bool | None = None) -> None:
        self.port = port
        self.clock = clock
        self.timeout = timeout
        self.vendor = vendor  # None: find out in identify()/first loc_get
        self.info: UwbInfo | None = None
        self.counters: dict[str, int] = {k: 0 for k in (
            "requests", "timeouts", "errors", "protocol_errors", "flushed_bytes", "ranges")}

    # -- transport ------------------------------------------------------------------------------------
    def _read(self, n: int, deadline: float) -> bytes:
        buf = bytearray()
        idle = 0
        while len(buf) < n:
            left = deadline - self.clock.now()
            if left <= 0:
                # what already arrived counts (the program may have been stopped, or slow, while it came): one
                # look without waiting before the deadline is called missed
                self.port.timeout = 0
                buf += self.port.read(n - len(buf))
                if len(buf) < n:
                    raise UwbTimeout()
                break
            self.port.timeout = left
            chunk = self.port.read(n - len(buf))
            if chunk:
                buf += chunk
                idle = 0
            else:
                idle += 1
                if idle >= 2 and self.clock.now() < deadline:
                    raise UwbTimeout("the port returned nothing before the deadline")
        return bytes(buf)

    def _flush(self) -> None:
        waiting = getattr(self.port, "in_waiting", 0) or 0
        if waiting:
            self.counters["flushed_bytes"] += waiting
        self.port.reset_input_buffer()

    def request(self, typ: int, value: bytes = b"", *, follow: int | None = None,
                timeout: float | None = None) -> list[tuple[int, bytes]]:
        """Send one TLV request; return the TLVs after the status. Raises UwbError/UwbTimeout."""
        if len(value) > 253:
            raise ValueError("a TLV value holds at most 253 bytes")
        n_follow = _FOLLOW.get(typ, 0) if follow is None else follow
        self._flush()
        self.counters["requests"] += 1
        self.port.write(bytes((typ, len(value))) + value)
        deadline = self.clock.now() + (self.timeout if timeout is None else timeout)
        try:
            head = self._read(3, deadline)
            if head[0] != RET_VAL or head[1] != 1:
                self._flush()
                raise UwbProtocolError(f"expected a status TLV, got {head.hex(' ')}")
            if head[2] != 0:
                self.counters["errors"] += 1
                raise UwbError(head[2])
            out = []
            for _ in range(n_follow):
                th = self._read(2, deadline)
                out.append((th[0], self._read(th[1], deadline)))
            return out
        except UwbTimeout:
            self.counters["timeouts"] += 1
            raise
        except UwbProtocolError:
            self.counters["protocol_errors"] += 1
            raise

    # -- commands ---------------------------------------------------------------------------------------
    def identify(self) -> UwbInfo:
        """Firmware, configuration and hardware versions, and the swarm firmware's address and TDMA slot."""
        tl = dict(self.request(CMD_VER_GET))
        fw, cfg, hw = tl.get(FW_VER, b""), tl.get(CFG_VER, b""), tl.get(HW_VER, b"")
        if len(fw) != 4 or len(cfg) != 4 or len(hw) != 4:
            self.counters["protocol_errors"] += 1
            raise UwbProtocolError("malformed version response")
        swarm = None
        try:
            (typ, val), = self.request(CMD_SWARM_INFO_GET)
            if typ == VENDOR_SWARM_INFO and len(val) == 8:
                a, s, n, p = struct.unpack("<HHHH", val)
                swarm = {"addr16": a, "slot": s, "n_slots": n, "n_peers": p}
        except UwbError as e:
            if e.status != 1:
                raise
        if self.vendor is None:
            self.vendor = swarm is not None
        self.info = UwbInfo((fw[3], fw[2], fw[1], fw[0] & 0x0F), struct.unpack("<I", cfg)[0],
                            struct.unpack("<I", hw)[0], swarm)
        return self.info

    def loc_get(self, *, timeout: float | None = None) -> list[RangeReading]:
        """Ranges measured since the previous call (the module keeps the latest per peer, at most 15 a call)."""
        if self.vendor is None:
            self.identify()
        tlvs = self.request(CMD_LOC_GET, follow=2 + int(bool(self.vendor)), timeout=timeout)
        try:
            out = decode_loc(tlvs, self.clock.now())
        except UwbProtocolError:
            self.counters["protocol_errors"] += 1
            raise
        self.counters["ranges"] += len(out)
        return out

    def update_rate(self) -> tuple[float, float]:
        """(update period, stationary update period) in seconds."""
        (typ, val), = self.request(CMD_UR_GET)
        if typ != UR or len(val) != 4:
            self.counters["protocol_errors"] += 1
            raise UwbProtocolError("malformed update-rate response")
        ur, st = struct.unpack("<HH", val)
        return ur / 10.0, st / 10.0

    def set_update_rate(self, period_s: float, static_period_s: float | None = None) -> None:
        """Target ranging period per peer (0.1 s steps, 0.1..60 s)."""
        ur = round(period_s * 10)
        st = round((static_period_s if static_period_s is not None else period_s) * 10)
        if not (1 <= ur <= 600 and ur <= st <= 600):
            raise ValueError("update period must be 0.1..60 s and not above the stationary one")
        self.request(CMD_UR_SET, struct.pack("<HH", ur, st))

    def status(self) -> dict[str, bool]:
        (typ, val), = self.request(CMD_STATUS_GET)
        if typ != STATUS or len(val) not in (1, 2):
            self.counters["protocol_errors"] += 1
            raise UwbProtocolError("malformed status response")
        return {"loc_ready": bool(val[0] & 1), "uwbmac_joined": bool(val[0] & 2)}

    def reset(self) -> None:
        self.request(CMD_RESET)
