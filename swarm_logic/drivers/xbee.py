"""Driver for a Digi XBee module (Series 1 802.15.4 or Series 2 ZigBee) in API mode over any pyserial port.

The same code runs on a real robot (``/dev/ttyUSB0``, a pty) and in a session (``sitl://xbee``). It is
single-threaded and lives by a ``swarm_logic.clock.Clock``: every wait is a ``port.read`` with ``port.timeout``
set to what is left of the deadline, so a SITL port blocks in simulated time and a real one in wall time.

Frames are built and decoded with digi-xbee's packet classes (``digi.xbee.packets.common/raw``,
``factory.build_frame``, the address and status models, ``XBeeProtocol.determine_protocol`` for the series).
Not used as is: digi-xbee's ``XBeeDevice``. It reads the port in a ``PacketListener`` thread and waits on
wall-clock timeouts (``threading.Event.wait``, ``time.time``); in a session only one robot thread runs at a
time and time advances only when that thread blocks in the port, so a second reader thread and wall-clock
deadlines can neither run nor mean anything there. Hand-written instead, and only these: the byte reader
(``FrameReader``: start-delimiter hunt, API 2 framing, length sanity, checksum, resynchronisation after noise;
digi-xbee's reader is part of its thread) and the request/response bookkeeping (frame IDs, deadlines).

Frame formats: Digi, "XBee/XBee-PRO RF Modules, Product Manual v1.xEx - 802.15.4 Protocol" (90000982), API
operation (0x08/0x09 AT command, 0x88 response, 0x00 TX request 64, 0x80/0x81 RX packet 64/16 with the RSSI byte
in -dBm, 0x89 TX status, 0x8A modem status); "XBee/XBee-PRO ZB RF Modules" (90000976), API operation (0x10
transmit request, 0x8B transmit status, 0x90 receive packet, which carries no RSSI: the host reads ``ATDB``,
"RSSI of the last packet received", right after it).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.mode import OperatingMode
from digi.xbee.models.protocol import XBeeProtocol
from digi.xbee.models.status import ModemStatus, TransmitStatus
from digi.xbee.packets.base import XBeeAPIPacket
from digi.xbee.packets.common import (
    ATCommPacket,
    ATCommQueuePacket,
    ATCommResponsePacket,
    ModemStatusPacket,
    ReceivePacket,
    TransmitPacket,
    TransmitStatusPacket,
)
from digi.xbee.packets.factory import build_frame
from digi.xbee.packets.raw import RX16Packet, RX64Packet, TX64Packet, TXStatusPacket

from swarm_logic.clock import Clock

START = 0x7E
ESCAPE = 0x7D
# Longest frame data (type .. last byte before the checksum) accepted. The largest frames these modules send
# are an S1 RX64 of 100 payload bytes (111) and an S2 receive packet of NP=84 bytes (96), or up to 267 with
# fragmented 255-byte payloads; a longer length field is line noise, and rejecting it early resynchronises sooner.
MAX_FRAME_DATA = 300
BROADCAST64 = 0x000000000000FFFF
RX_QUEUE_MAX = 256  # received packets kept for recv(); older ones are dropped and counted beyond this
DB_TIMEOUT = 0.5  # s, for the ATDB query after a Series 2 receive packet
# A module clocks a frame out back to back, so a frame still incomplete this long after the last byte began at a
# noise 0x7E (API 1: it may be holding real frames back); it is abandoned and the bytes after it searched again.
# Far above the gaps a USB adapter (16 ms latency timer) or a 10 ms simulation quantum puts inside a frame.
STALL_S = 0.1
EPS = 1e-6  # s: deadlines closer than this count as reached (clock times are floats)

COUNTER_NAMES = (
    "rx_bytes",  # bytes read from the port
    "frame_bytes",  # bytes that were part of a frame with a good checksum
    "dropped_bytes",  # bytes discarded: noise before a start delimiter, a rejected frame's delimiter, cut frames
    "frames",  # frames with a good checksum
    "checksum_errors",
    "bad_length",  # length field 0 or beyond MAX_FRAME_DATA
    "truncated",  # API 2: a raw 0x7E inside a frame (it starts a new one)
    "stalled",  # a frame left incomplete for STALL_S: its delimiter was noise
    "malformed",  # good checksum, but digi-xbee cannot decode the frame (too short for its type, ...)
    "unhandled",  # a frame type this driver does not act on
    "unexpected",  # a response nobody waits for (unknown or expired frame ID, wrong command)
    "rx_packets",  # received RF packets queued for recv()
    "rx_overflow",  # received packets dropped because the queue was full
    "modem_status",
    "tx_frames",  # frames written to the port
    "at_errors",  # AT responses with a non-zero status
    "db_ambiguous",  # Series 2 packets handed out without RSSI: a later packet made ATDB ambiguous
    "timeouts",
    "db_failed",  # ATDB after a Series 2 packet failed or timed out
)


class SerialPort(Protocol):
    """What the driver uses of a pyserial port."""

    timeout: float | None

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...


class XBeeError(Exception):
    """An AT command answered with a non-zero status (``status``), or no answer (``XBeeTimeout``)."""

    def __init__(self, message: str, status: int | None = None, command: str | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.command = command


class XBeeTimeout(XBeeError, TimeoutError):
    """The module did not answer in time."""


@dataclass(frozen=True)
class ModuleInfo:
    """What ``identify`` read from the module: SH/SL, MY, NI, HV, VR and the series they imply."""

    serial64: int
    addr16: int
    node_id: str
    hw_version: int
    fw_version: int
    series: int  # 1: 802.15.4 (TX64/RX64 frames), 2: ZigBee and other 0x10/0x90 firmwares


@dataclass(frozen=True)
class TxStatus:
    """The module's report on one transmission (0x89 on Series 1, 0x8B on Series 2)."""

    frame_id: int
    status: int  # raw delivery status code: 0 = success
    retries: int | None = None  # Series 2 transmit retry count
    discovery: int | None = None  # Series 2 discovery status
    t: float = 0.0  # clock time the status was read

    @property
    def ok(self) -> bool:
        return self.status == 0

    @property
    def description(self) -> str:
        st = TransmitStatus.get(self.status)
        return st.description if st is not TransmitStatus.UNKNOWN else f"status 0x{self.status:02X}"


@dataclass(frozen=True)
class Received:
    """One RF packet as the module handed it over."""

    src64: int | None  # None for a Series 1 RX16 frame (16-bit source addressing)
    src16: int | None  # None for a Series 1 RX64 frame; 0xFFFE when the module does not know it
    data: bytes
    rssi_dbm: int | None
    broadcast: bool
    t: float  # clock time the frame was read from the port


@dataclass(frozen=True)
class ModemStatusEvent:
    code: int
    t: float

    @property
    def name(self) -> str:
        st = ModemStatus.get(self.code)
        return st.name if st is not ModemStatus.UNKNOWN else f"0x{self.code:02X}"


class FrameReader:
    """Splits a byte stream into API frames: start-delimiter hunt, API 2 unescaping, length sanity, checksum.

    Returns each frame unescaped (``0x7E``, length, data, checksum), ready for digi-xbee's ``build_frame``.
    Never raises on any input. A frame whose length field is insane or whose checksum is wrong is rejected and
    the search resumes at the byte after its delimiter, so a real frame swallowed by a noise ``0x7E`` is found
    again. In API 2 a raw ``0x7E`` always starts a frame (the module escapes every data ``0x7E``), so a frame cut
    short by it is dropped at once; in API 1 a noise ``0x7E`` can hold the following frames back until its length
    is reached or the owner calls ``abandon`` (the driver does when the line has been quiet for ``STALL_S``).
    Invariant: ``rx_bytes == frame_bytes + dropped_bytes + pending``.
    """

    def __init__(self, api_mode: int, counters: dict[str, int]) -> None:
        if api_mode not in (1, 2):
            raise ValueError(f"api_mode must be 1 or 2, got {api_mode!r}")
        self.escaped = api_mode == 2
        self.counters = counters
        self._buf = bytearray()

    @property
    def pending(self) -> int:
        """Bytes held back: a frame whose end has not arrived yet."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytearray]:
        c, buf = self.counters, self._buf
        c["rx_bytes"] += len(data)
        buf += data
        frames: list[bytearray] = []
        while buf:
            start = buf.find(START)
            if start < 0:
                c["dropped_bytes"] += len(buf)
                buf.clear()
                break
            if start:
                c["dropped_bytes"] += start
                del buf[:start]
            kind, n = self._delimit()
            if kind == "partial":
                break
            if kind == "frame":
                raw = bytes(buf[:n])
                frame = XBeeAPIPacket.unescape_data(raw) if self.escaped else bytearray(raw)
                if (sum(frame[3:]) & 0xFF) == 0xFF:
                    c["frames"] += 1
                    c["frame_bytes"] += n
                    frames.append(frame)
                    del buf[:n]
                    continue
                c["checksum_errors"] += 1
                n = 1  # resume after this delimiter
            elif kind == "bad_length":
                c["bad_length"] += 1
                n = 1
            else:  # truncated: drop up to the raw 0x7E that starts the next frame
                c["truncated"] += 1
            c["dropped_bytes"] += n
            del buf[:n]
        return frames

    def abandon(self) -> list[bytearray]:
        """Give up the incomplete frame held back (no more bytes came): drop its delimiter and search the rest
        again, repeatedly, so every complete frame in it is returned and the rest dropped."""
        frames: list[bytearray] = []
        while self._buf:
            self.counters["stalled"] += 1
            self.counters["dropped_bytes"] += 1
            del self._buf[:1]
            frames += self.feed(b"")
        return frames

    def _delimit(self) -> tuple[str, int]:
        """Find where the frame at ``buf[0]`` ends: ("frame", raw length), ("partial", 0), ("bad_length", 0),
        ("truncated", index of the raw 0x7E that cuts it)."""
        buf, escaped = self._buf, self.escaped
        i, count, length, total = 1, 1, 0, 0  # count: unescaped bytes so far, delimiter included
        n = len(buf)
        while True:
            if count == 3 and not total:
                if not 0 < length <= MAX_FRAME_DATA:
                    return "bad_length", 0
                total = length + 4
            if total and count == total:
                return "frame", i
            if i >= n:
                return "partial", 0
            b = buf[i]
            if escaped:
                if b == START:
                    return "truncated", i
                if b == ESCAPE:
                    if i + 1 >= n:
                        return "partial", 0
                    b = buf[i + 1]
                    if b == START:
                        return "truncated", i + 1
                    i += 1
                    if b == ESCAPE:  # as digi-xbee's unescape_data: an escape after an escape is an escape
                        continue
                    b ^= 0x20
            if count < 3:
                length = (length << 8) | b
            count += 1
            i += 1


def _int_param(value: int) -> bytes:
    """An AT parameter as the module expects a number: big-endian, no leading zero bytes, at least one byte."""
    if value < 0:
        raise ValueError(f"AT parameter must be >= 0, got {value}")
    return value.to_bytes(max(1, (value.bit_length() + 7) // 8), "big")


def _at_param(value: bytes | bytearray | int | str | None) -> bytearray | None:
    if value is None:
        return None
    if isinstance(value, bool):
        return bytearray(_int_param(int(value)))
    if isinstance(value, int):
        return bytearray(_int_param(value))
    if isinstance(value, str):
        return bytearray(value.encode("ascii"))
    return bytearray(value)


def series_of(hw_version: int, fw_version: int) -> int:
    """1 for 802.15.4 firmware (TX64/RX64 frames), else 2, from HV and VR as digi-xbee's XBeeDevice decides."""
    fw = fw_version.to_bytes(max(2, (fw_version.bit_length() + 7) // 8), "big")
    proto = XBeeProtocol.determine_protocol(hw_version >> 8 if hw_version > 0xFF else hw_version, fw)
    if proto is XBeeProtocol.RAW_802_15_4:
        return 1
    if proto is XBeeProtocol.UNKNOWN:  # unknown hardware: 802.15.4 firmware versions are 1xxx
        return 1 if f"{fw_version:04X}".startswith("1") else 2
    return 2


class XBee:
    """An XBee module in API mode over a pyserial port, single-threaded, all time from ``clock``.

    ``poll()`` reads what is waiting without blocking; ``recv``, ``at`` and ``send`` block (in ``port.read``)
    up to their timeouts. Received packets wait in a queue for ``recv``; modem status frames are kept in
    ``modem_status``; ``counters`` counts every byte and frame that was noise, malformed or unexpected.
    """

    def __init__(self, port: SerialPort, clock: Clock, *, api_mode: int = 1, rssi_from_db: bool = False,
                 series: int | None = None) -> None:
        """``port``: an open pyserial port (``serial.Serial``, ``serial_for_url("sitl://xbee")``, ...).
        ``api_mode``: the module's AP setting, 1 or 2 (escaped). ``rssi_from_db``: on Series 2, ask ``ATDB``
        for the RSSI of each received packet. ``series``: skip the HV/VR detection (1 or 2)."""
        if series not in (None, 1, 2):
            raise ValueError(f"series must be 1, 2 or None, got {series!r}")
        self.port = port
        self.clock = clock
        self.api_mode = api_mode
        self.rssi_from_db = rssi_from_db
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.reader = FrameReader(api_mode, self.counters)
        self.modem_status: list[ModemStatusEvent] = []
        self.info: ModuleInfo | None = None
        self._series = series
        self._rx: deque[Received] = deque()
        self._next_id = 0
        self._pending: dict[int, str] = {}  # frame ID -> "AT:<cmd>" or "TX"
        self._at_done: dict[int, tuple[int, bytes]] = {}
        self._tx_done: dict[int, TxStatus] = {}
        self._last_rx = clock.now()  # clock time of the last byte read
        self.last_rssi_dbm: int | None = None  # RSSI of the newest packet ``recv`` handed out with one

    # -- public API ----------------------------------------------------------------------------------------
    @property
    def series(self) -> int:
        """1 or 2; asks the module (HV, VR) the first time it is needed."""
        if self._series is None:
            self.identify()
        assert self._series is not None
        return self._series

    def at(self, cmd: str, value: bytes | int | str | None = None, *, timeout: float = 1.0,
           apply: bool = True) -> bytes:
        """Run a local AT command (query without ``value``, set with it) and return the response value.

        ``apply=False`` queues a setting (frame 0x09) until an ``AC``/applying command. Raises ``XBeeError``
        with the module's status (1 error, 2 invalid command, 3 invalid parameter) or ``XBeeTimeout``.
        """
        if len(cmd) != 2 or not cmd.isascii():
            raise ValueError(f"AT command must be two ASCII characters, got {cmd!r}")
        fid = self._new_frame_id(f"AT:{cmd.upper()}")
        cls = ATCommPacket if apply else ATCommQueuePacket
        self._write(cls(fid, cmd.upper(), _at_param(value)))
        if not self._wait(lambda: fid in self._at_done, timeout):
            self._pending.pop(fid, None)
            self.counters["timeouts"] += 1
            raise XBeeTimeout(f"no answer to AT{cmd} within {timeout} s", command=cmd)
        status, data = self._at_done.pop(fid)
        if status:
            self.counters["at_errors"] += 1
            raise XBeeError(f"AT{cmd} failed with status {status}", status=status, command=cmd)
        return data

    def identify(self, *, timeout: float = 1.0) -> ModuleInfo:
        """Read SH, SL, MY, NI, HV and VR; sets ``info`` and the series (unless given to the constructor)."""
        sh = self.at("SH", timeout=timeout)
        sl = self.at("SL", timeout=timeout)
        my = self.at("MY", timeout=timeout)
        ni = self.at("NI", timeout=timeout)
        hv = int.from_bytes(self.at("HV", timeout=timeout), "big")
        vr = int.from_bytes(self.at("VR", timeout=timeout), "big")
        if self._series is None:
            self._series = series_of(hv, vr)
        self.info = ModuleInfo(
            serial64=(int.from_bytes(sh, "big") << 32) | int.from_bytes(sl, "big"),
            addr16=int.from_bytes(my, "big"),
            node_id=ni.decode("ascii", "replace").rstrip("\r\x00"),
            hw_version=hv,
            fw_version=vr,
            series=self._series,
        )
        return self.info

    def send_nowait(self, dest64: int | None, data: bytes, *, options: int = 0, radius: int = 0) -> int:
        """Hand ``data`` to the module for ``dest64`` (None: broadcast) in a TX64 (Series 1) or transmit request
        (Series 2, 16-bit address unknown) frame; returns the frame ID of its TX status (see ``tx_result``).
        ``options`` is the frame's transmit options byte (0x01: Series 1 no MAC ACK, Series 2 no APS retries).
        ``radius`` is a Series 2 broadcast's radius in hops (0: the module's BH; 1: the neighbours only, nobody
        relays it in a ZigBee mesh); Series 1 frames have none. Payload limits are the module's: Series 2 answers
        0x74 beyond NP, Series 1 drops the frame silently."""
        dest = BROADCAST64 if dest64 is None else dest64
        if not 0 <= dest < 1 << 64:
            raise ValueError(f"dest64 out of range: {dest64!r}")
        if not 0 <= options <= 0xFF:
            raise ValueError(f"options must be a byte: {options!r}")
        if not 0 <= radius <= 0xFF:
            raise ValueError(f"radius must be a byte: {radius!r}")
        addr = XBee64BitAddress(dest.to_bytes(8, "big"))
        series = self.series
        fid = self._new_frame_id("TX")
        if series == 1:
            pkt = TX64Packet(fid, addr, options, bytearray(data))
        else:
            pkt = TransmitPacket(fid, addr, XBee16BitAddress.UNKNOWN_ADDRESS, radius, options, bytearray(data))
        self._write(pkt)
        return fid

    def send(self, dest64: int | None, data: bytes, *, timeout: float = 2.0) -> TxStatus:
        """Send and wait for the module's TX status; raises ``XBeeTimeout`` if none comes."""
        fid = self.send_nowait(dest64, data)
        if not self._wait(lambda: fid in self._tx_done, timeout):
            self._pending.pop(fid, None)
            self.counters["timeouts"] += 1
            raise XBeeTimeout(f"no TX status for frame {fid} within {timeout} s")
        return self._tx_done.pop(fid)

    def tx_result(self, frame_id: int) -> TxStatus | None:
        """The TX status of a ``send_nowait`` once read (taken: returned once), else None."""
        return self._tx_done.pop(frame_id, None)

    def recv(self, timeout: float | None = 0.0) -> Received | None:
        """The next received packet, waiting up to ``timeout`` s (None: forever, 0: only what has arrived).

        With ``rssi_from_db`` a Series 2 packet's RSSI is read with ``ATDB`` when it is handed out. The module
        reports the RSSI of its *last* packet, so the answer belongs to this packet only if no later one has
        arrived, before the query or while it was answered; otherwise ``rssi_dbm`` is None (counted as
        ``db_ambiguous``) rather than another neighbour's value.
        """
        if not self._rx and not self._wait(lambda: bool(self._rx), timeout):
            return None
        pkt = self._rx.popleft()
        if pkt.rssi_dbm is None and self.rssi_from_db:  # a Series 2 receive packet: ask ATDB at once
            self.poll()  # anything already on the line may be a later packet
            rssi = None
            if not self._rx:
                before = self.counters["rx_packets"]
                rssi = self._query_db()
                if self.counters["rx_packets"] != before:
                    rssi = None
            if rssi is None:
                self.counters["db_ambiguous"] += 1
            pkt = Received(pkt.src64, pkt.src16, pkt.data, rssi, pkt.broadcast, pkt.t)
        if pkt.rssi_dbm is not None:
            self.last_rssi_dbm = pkt.rssi_dbm
        return pkt

    def poll(self) -> None:
        """Read what is waiting on the port without blocking and dispatch it."""
        n = self.port.in_waiting
        if n:
            self._set_timeout(0)
            self._feed(self.port.read(n))
        else:
            self._check_stall()

    # -- internals -------------------------------------------------------------------------------------------
    def _query_db(self) -> int | None:
        """RSSI of the last packet the module received (ATDB, -dBm), as a Series 2 host reads it."""
        try:
            v = self.at("DB", timeout=DB_TIMEOUT)
        except XBeeError:
            self.counters["db_failed"] += 1
            return None
        if not v:
            self.counters["db_failed"] += 1
            return None
        return -int.from_bytes(v, "big")

    def _new_frame_id(self, what: str) -> int:
        """Next frame ID in 1..255 (0 asks for no response), skipping those still awaited if any is free."""
        for _ in range(255):
            self._next_id = self._next_id % 255 + 1
            if self._next_id not in self._pending:
                break
        fid = self._next_id
        self._pending[fid] = what
        self._at_done.pop(fid, None)
        self._tx_done.pop(fid, None)
        return fid

    def _write(self, pkt: XBeeAPIPacket) -> None:
        self.port.write(bytes(pkt.output(escaped=self.api_mode == 2)))
        self.counters["tx_frames"] += 1

    def _set_timeout(self, t: float | None) -> None:
        if self.port.timeout != t:
            self.port.timeout = t

    def _wait(self, done: Callable[[], bool], timeout: float | None) -> bool:
        """Dispatch incoming frames until ``done()`` or the deadline; blocking happens in ``port.read``."""
        self.poll()
        if done():
            return True
        deadline = None if timeout is None else self.clock.now() + timeout
        while True:
            now = self.clock.now()
            wait = None if deadline is None else deadline - now
            if wait is not None and wait < EPS:
                return False
            if self.reader.pending:  # wake up when the frame in progress would count as stalled
                wait = min(wait if wait is not None else STALL_S, self._last_rx + STALL_S - now)
            self._set_timeout(max(wait, EPS) if wait is not None else None)
            first = self.port.read(1)
            if first:
                self._feed(first)
            self.poll()
            if done():
                return True

    def _feed(self, data: bytes) -> None:
        self._last_rx = self.clock.now()
        for frame in self.reader.feed(data):
            self._dispatch(frame)

    def _check_stall(self) -> None:
        if self.reader.pending and self.clock.now() >= self._last_rx + STALL_S - EPS:
            for frame in self.reader.abandon():
                self._dispatch(frame)

    def _dispatch(self, frame: bytearray) -> None:
        try:
            pkt = build_frame(frame, OperatingMode.API_MODE)
        except Exception:  # digi-xbee raises several kinds on a frame too short for its type
            self.counters["malformed"] += 1
            return
        c, now = self.counters, self.clock.now()
        if isinstance(pkt, ATCommResponsePacket):
            what = self._pending.get(pkt.frame_id)
            if what != f"AT:{pkt.command.upper()}":
                c["unexpected"] += 1
                return
            del self._pending[pkt.frame_id]
            # the status is the low nibble (digi-xbee's ATCommandStatus.get does the same)
            self._at_done[pkt.frame_id] = (frame[7] & 0x0F, bytes(pkt.command_value or b""))
        elif isinstance(pkt, TXStatusPacket | TransmitStatusPacket):
            if self._pending.get(pkt.frame_id) != "TX":
                c["unexpected"] += 1
                return
            del self._pending[pkt.frame_id]
            if isinstance(pkt, TXStatusPacket):
                st = TxStatus(pkt.frame_id, frame[5], t=now)
            else:
                st = TxStatus(pkt.frame_id, frame[8], retries=frame[7], discovery=frame[9], t=now)
            self._tx_done[pkt.frame_id] = st
        elif isinstance(pkt, RX64Packet | RX16Packet | ReceivePacket):
            data = bytes(pkt.rf_data or b"")
            if isinstance(pkt, RX64Packet):
                r = Received(_addr(pkt.x64bit_source_addr), None, data, -pkt.rssi, pkt.is_broadcast(), now)
            elif isinstance(pkt, RX16Packet):
                r = Received(None, _addr(pkt.x16bit_source_addr), data, -pkt.rssi, pkt.is_broadcast(), now)
            else:
                r = Received(_addr(pkt.x64bit_source_addr), _addr(pkt.x16bit_source_addr), data, None,
                             pkt.is_broadcast(), now)
            if len(self._rx) >= RX_QUEUE_MAX:
                self._rx.popleft()
                c["rx_overflow"] += 1
            self._rx.append(r)
            c["rx_packets"] += 1
        elif isinstance(pkt, ModemStatusPacket):
            self.modem_status.append(ModemStatusEvent(frame[4], now))
            c["modem_status"] += 1
        else:
            c["unhandled"] += 1


def _addr(a: XBee64BitAddress | XBee16BitAddress) -> int:
    return int.from_bytes(bytes(a.address), "big")
