"""An XBee radio module's firmware in API mode, as the robot's host sees it over its UART (sans-IO).

Sources (Digi manuals; section names as printed):

- [S1] "XBee/XBee-PRO RF Modules, Product Manual v1.xEx - 802.15.4 Protocol" (90000982): API frames 0x00/0x01
  TX Request 64/16, 0x08/0x09 AT Command (Queue), 0x80/0x81 RX Packet 64/16 (RSSI byte in -dBm, options bit 1
  address broadcast, bit 2 PAN broadcast, "up to 100 bytes per packet"), 0x88 AT Command Response, 0x89 TX Status
  (0 success, 1 no ACK, 2 CCA failure, 3 purged; a broadcast only ever reports 0 or 2), 0x8A Modem Status
  (0 hardware reset, 1 watchdog timer reset); "Flow Control": DI buffer 202 bytes; DO buffer drops incoming RF data
  when full; RR: XBee retries on top of the MAC's three, "(RR + 2) packets are sent on each broadcast", a retry
  follows "within a random period up to 48 msec"; DB: "-dBm of last good packet", range 0x17-0x5C; RP: RSSI PWM
  timer in 100 ms, default 0x28; PL: -10/-6/-4/-2/0 dBm; defaults CH 0x0C, ID 0x3332, RR 0, BD 3 (9600).
- [ZB] "XBee/XBee-PRO ZB RF Modules" (90000976, firmware 23xx = router API) and the later "XBee/XBee-PRO ZigBee RF
  Modules User Guide": 0x10 Transmit Request (options 0x01 disable retries, 0x20 APS encryption, 0x40 extended
  timeout), 0x8B Transmit Status (0x00 success, 0x01 MAC ACK failure, 0x02 CCA failure, 0x21 network ACK failure,
  0x22 not joined, 0x23 self-addressed, 0x2E APS unicast with EE=0, 0x74 payload too large; 0xFFFD as the address
  when not delivered), 0x90 Receive Packet (options 0x01 acknowledged, 0x02 broadcast, no RSSI), 0x8A Modem Status
  (0x02 joined network, 0x03 disassociated); "Maximum RF payload size": NP = 84 for unencrypted unicast, broadcasts
  carry 8 bytes more (92); AI 0x00 joined, 0xFF scanning, 0x21/0x22 no (valid) PAN found; scan time
  = channels x (2^SD x 15.36 ms + 38 ms) + 20 ms (SD 3); MY 0xFFFE until joined; unicast timeout
  (50 x NH + 100) ms per attempt, NH 0x1E; CE is not a command of the separate-role 2x7x firmware.
- Digi knowledge base "Maximum payload size for Digi RF radios": Series 1 100 bytes; ZB 84 unicast, 92 broadcast.
- eSwarBot thesis (Couceiro), eq. 3.9: RSSI PWM duty on the module's RSSI pin; sensitivity -94 dBm (Series 2).

Modelled: API 1 and API 2 (escaped) framing with checksum, per-instance Series 1 (802.15.4 firmware 10EF on an
XB24-A, HV 0x17xx) or Series 2 (ZB router API firmware 23A7 on an XB24-Z7, HV 0x19xx), the AT commands a host and
digi-xbee's ``XBeeDevice.open()`` use (AP, HV, VR, SH, SL, NI, MY, CE on Series 1; CE answers "invalid command" on
Series 2 as the 2x7x firmware does) plus ID CH AI DB PL RP BD SM DH DL AC WR FR (RR EA EC on Series 1; OP OI SC NH
AO NP NR on Series 2), 0x09 queued parameters applied by AC or the next 0x08, unsaved settings lost on FR,
XBee-level retries (RR) and broadcast repeats on Series 1, APS retries (three attempts) on Series 2, the serial
receive buffer (queued transmit requests; a frame that does not fit is lost without a word) and the RF-to-serial
buffer (a received packet that does not fit is dropped whole), UART output paced at the module's baud (10 bits a
byte), duplicate suppression by source and sequence number, power-up modem status (Series 1: 0x00 at once;
Series 2: 0x02 after the scan-time join delay), and the eSwarBot RSSI PWM hack.

Series 2 also answers what digi-xbee and XCTU send beyond data ([ZB]; Digi's C library's DIN clusters; digi-xbee
1.5.0's own code for what it expects, e.g. that ``open()`` reads the role of a module without CE from a node
descriptor request to itself, waiting for a 0x8B of status 0x00 or 0x23 and a 0x91 from cluster 0x8002):
explicit addressing (0x11 out; 0x91 in when AO is 1 or 3, AO accepting 0, 1, 3), a ZDO request to itself
(self-addressed 0x23, answered by its own ZDO), the ZDO server of ``zigbee`` for requests from the air, remote AT
commands (0x17/0x97: option 0x02 applies, else the change is queued; status 4 when the request is not acknowledged
after its three attempts or its answer does not come within a unicast timeout; to itself, status 4 at once;
a broadcast one collects every answer), node discovery (ND with or without an NI, DN: every joined module in range
of that NI answers after a uniform random wait within the asker's NT; answers after NT are ignored; no closing
empty frame, as on ZB; an ND for an NI nobody has, or a DN, ends in ERROR after NT; NO 0x01 appends DD, 0x02 puts
the asker's own record first; BH is the discovery's radius), and the 2x7x AT commands NT, NO, BH, DD (0x30000),
EE (0 only: encryption is not modelled), %V (raw, 1200/1024 mV a count, of the 3.3 V rail), NC (12, assumed).
CE, N?, TP (PRO only) and MP (end devices only) answer "invalid command", as on a 2x7x router.

ZigBee mesh routing is ``zigbee_nwk`` (``routing="mesh"``); with ``routing="one_hop"`` (the default) a Series 2
unicast reaches one hop (its addressee must hear it; the 16-bit address of a neighbour is learned from frames it
sent) and nobody relays. Not modelled, on purpose: the coordinator (the network is taken as formed, with the
extended PAN ID and channel given to the constructor), association/beacons and end devices on Series 1, encryption
(EE = 0; the APS-encryption option is refused), sleep modes (SM accepts only 0), transparent mode and command mode
(+++), Series 1 remote AT, explicit frames and ND, I/O sampling, CTS/RTS flow control, and non-standard baud rates
(BD 0..7 only), AP 0 (AP accepts 1 and 2). Malformed input never raises: it is counted
in ``counters`` and answered the way the real module does, which for framing errors is silence.

Assumptions where the manuals are silent (change them here if a measurement says otherwise): the DO buffer and
both Series 2 serial buffers hold 202 bytes like the Series 1 DI buffer; the Series 2 PL table is the ZB manual's
boost-mode table as remembered (-5/-3/-1/+1/+3 dBm), not re-checked; FR resets 100 ms after its OK; a Series 1 API
frame with more than 100 payload bytes is discarded without a TX status; frames of an unknown type are ignored
silently; the Series 1 ``psdu_len`` counts the 802.15.4 MAC header and FCS but not Digi's (unpublished) MM = 0
application header; Series 2 ``psdu_len`` = MAC 11 + NWK 8 + IEEE source 8 (+ IEEE destination 8 for unicast)
+ APS 8 + payload, which is exactly what makes the 84/92-byte limits fill a 127-byte PSDU.
"""

from __future__ import annotations

import heapq
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from firmware_sim.modules import zigbee as zb
from firmware_sim.modules.zigbee_nwk import STAT_KEYS as NWK_STAT_KEYS
from firmware_sim.modules.zigbee_nwk import MacFrame, Nwk, air_hops, valid_nwk

MS = 1_000_000  # ns
START, ESC, XON, XOFF = 0x7E, 0x7D, 0x11, 0x13
ESCAPED = frozenset((START, ESC, XON, XOFF))
BROADCAST64 = 0x000000000000FFFF
BAUD_CODES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)  # BD 0..7
DUP_WINDOW_NS = 1000 * MS  # a repeated (source, sequence) pair within this window is a duplicate
FR_DELAY_NS = 100 * MS  # FR answers OK at once and resets this much later (assumed)

# AT command response status
AT_OK, AT_ERROR, AT_INVALID_COMMAND, AT_INVALID_PARAMETER = 0, 1, 2, 3
# modem status
MS_HW_RESET, MS_WDT_RESET, MS_JOINED, MS_DISASSOCIATED = 0x00, 0x01, 0x02, 0x03


@dataclass(frozen=True)
class SeriesProfile:
    """What differs between the two module generations (sources in the module docstring)."""

    series: int
    vr: int
    hv: int
    sensitivity_dbm: float
    pl_dbm: tuple[float, ...]
    max_unicast: int
    max_broadcast: int
    serial_rx_buffer: int  # host -> module (DI buffer)
    serial_tx_buffer: int  # module -> host (DO buffer)
    db_min: int  # DB saturates here (-dBm)


S1 = SeriesProfile(1, 0x10EF, 0x1744, -92.0, (-10.0, -6.0, -4.0, -2.0, 0.0), 100, 100, 202, 202, 0x17)
# ZB PL table with boost mode (PM = 1, the default); buffer sizes are not published for the EM250 module and are
# taken equal to Series 1 (assumption).
S2 = SeriesProfile(2, 0x23A7, 0x1941, -94.0, (-5.0, -3.0, -1.0, 1.0, 3.0), 84, 92, 202, 202, 0x17)

COUNTER_KEYS = (
    # framing: every frame that starts ends in exactly one of the next six (or is still being received)
    "frames_started", "frames_ok", "checksum_errors", "oversize_frames", "zero_length_frames",
    "truncated_frames", "escape_errors",
    # bytes seen outside any frame
    "discarded_bytes",
    # every frames_ok ends in exactly one of the next four
    "frames_handled", "unknown_frame_type", "malformed_frames", "serial_rx_overflow",
    # AT commands
    "at_commands", "at_errors",
    # radio
    "tx_requests", "tx_air_frames", "tx_ok", "tx_failed", "tx_too_large",
    "rx_frames", "rx_filtered", "rx_duplicates", "rx_delivered", "rx_buffer_drops", "rx_malformed",
    "bad_air_events", "stale_done",
    "resets",
    # Series 2 beyond data: explicit addressing, the ZDO server, remote AT and node discovery
    "zdo_requests", "zdo_answered", "remote_at_served", "remote_at_timeouts", "nd_answered", "ddo_malformed",
    # Series 2 mesh routing (zigbee_nwk): relays, route and address discoveries, the broadcast table
    *(f"nwk_{k}" for k in NWK_STAT_KEYS),
)


@dataclass
class ModuleOutput:
    """What one ``step`` produced."""

    uart_tx: bytes = b""
    air_tx: list[dict] = field(default_factory=list)
    node: dict | None = None
    rssi_pwm: float | None = None


def checksum(data: bytes) -> int:
    """API checksum: 0xFF minus the 8-bit sum of the frame data."""
    return 0xFF - (sum(data) & 0xFF)


def encode_frame(data: bytes, api_mode: int) -> bytes:
    """Frame data -> wire bytes (start delimiter, length, data, checksum; escaped in API 2)."""
    body = len(data).to_bytes(2, "big") + data + bytes((checksum(data),))
    if api_mode == 2:
        out = bytearray()
        for b in body:
            if b in ESCAPED:
                out += bytes((ESC, b ^ 0x20))
            else:
                out.append(b)
        body = bytes(out)
    return bytes((START,)) + body


def rssi_dbm_from_pwm(duty: float, sensitivity_dbm: float) -> float:
    """Eq. 3.9 inverted, as the robot's controller reads the PWM: received power (dBm) from the duty (0..1). A
    saturated (100 %) duty reads as its floor, about -52 dBm for Series 2: anything stronger looks the same."""
    return sensitivity_dbm + (duty * 100 * 10.24 - 295) / 17.5


def rssi_pwm_formula(rssi_dbm: float, sensitivity_dbm: float) -> float:
    """Thesis eq. 3.9: duty % = (295 + 17.5 (RSSI - sensitivity)) / 10.24, clamped to 0..100 %; as 0..1."""
    pct = (295.0 + 17.5 * (rssi_dbm - sensitivity_dbm)) / 10.24
    return min(100.0, max(0.0, pct)) / 100.0


@dataclass
class _TxJob:
    frame_id: int
    ftype: int
    dst: str
    dst_addr: int
    dest64: int
    dest16: int
    payload: bytes
    opts: int
    size: int  # bytes held in the serial receive buffer
    seq: int = 0
    handle: int = -1
    attempts: int = 0  # air attempts made (XBee-level / APS)
    copies_ok: int = 0
    attempt_t: int = 0
    aps: tuple[int, int, int, int] = zb.DATA_APS  # Series 2: (profile, cluster, source endpoint, destination endpoint)
    radius: int = 0  # Series 2 broadcast radius (0: the network's maximum hops)
    kind: str = "host"  # whose frame: "host" (a transmit status answers it), "remote_at" (its request), "internal"
    ctx: int = 0  # kind "remote_at": the request's transaction number
    disc: int = 0  # mesh: the transmit status's discovery status (0x01 address, 0x02 route)
    dest16_found: int | None = None  # mesh: the destination's network address, once delivered


@dataclass(frozen=True)
class _Param:
    width: int  # response width in bytes (0 = string)
    lo: int = 0
    hi: int = 0
    readonly: bool = False


def _params(series: int) -> dict[str, _Param]:
    p = {
        "SH": _Param(4, readonly=True), "SL": _Param(4, readonly=True), "NI": _Param(0, 0, 20),
        "AP": _Param(1, 1, 2), "BD": _Param(4, 0, 7), "VR": _Param(2, readonly=True), "HV": _Param(2, readonly=True),
        "AI": _Param(1, readonly=True), "DB": _Param(1, readonly=True), "PL": _Param(1, 0, 4),
        "RP": _Param(1, 0, 0xFF), "SM": _Param(1, 0, 0), "DH": _Param(4, 0, 0xFFFFFFFF),
        "DL": _Param(4, 0, 0xFFFFFFFF),
    }
    if series == 1:
        p |= {"MY": _Param(2, 0, 0xFFFF), "ID": _Param(2, 0, 0xFFFF), "CH": _Param(1, 0x0B, 0x1A),
              "RR": _Param(1, 0, 6), "CE": _Param(1, 0, 1), "EA": _Param(2, 0, 0), "EC": _Param(2, 0, 0)}
    else:
        p |= {"MY": _Param(2, readonly=True), "ID": _Param(8, 0, 0xFFFFFFFFFFFFFFFF), "OP": _Param(8, readonly=True),
              "OI": _Param(2, readonly=True), "CH": _Param(1, readonly=True), "SC": _Param(2, 1, 0xFFFF),
              "NH": _Param(1, 1, 0xFF), "AO": _Param(1, 0, 3), "NP": _Param(2, readonly=True),
              "NT": _Param(1, 0x20, 0xFF), "NO": _Param(1, 0, 3), "BH": _Param(1, 0, 0x1E),
              "DD": _Param(4, 0, 0xFFFFFFFF), "EE": _Param(1, 0, 0), "%V": _Param(2, readonly=True),
              "NC": _Param(1, readonly=True)}
    return p


EXEC_COMMANDS = {1: frozenset(("AC", "WR", "FR")), 2: frozenset(("AC", "WR", "FR", "NR"))}
DISCOVERY_COMMANDS = frozenset(("ND", "DN"))  # Series 2: answered as nodes reply, not at once
AO_VALUES = (0, 1, 3)  # Series 2 AO: native (0x90), explicit (0x91), explicit with ZDO pass-through
SUPPLY_MV = 3300  # %V: the eSwarBot's regulated 3.3 V rail (the module reads its own supply)
ROUTER_CHILDREN = 12  # NC: end-device children a router can still take (none ever join here; the count is assumed)
REMOTE_AT_FAILED = 0x04  # 0x97 status: the remote command could not be sent or was not answered


def network_pan16(epid: int) -> int:
    """The 16-bit PAN of the (unmodelled) coordinator's network: a fixed fold of its extended PAN ID."""
    v = 0
    while True:
        v ^= epid & 0x3FFF
        epid >>= 14
        if not epid:
            return v


class XBeeModule:
    """One XBee module (Series 1 or 2) in API mode; stepped by its host with simulated time (ns)."""

    def __init__(self, *, series: int, serial64: int, node_id: str, rng: np.random.Generator, api_mode: int = 1,
                 baud: int = 9600, my16: int | None = None, pan_id: int = 0x3332, channel: int = 0x0C,
                 power_level: int = 4, routing: str = "one_hop") -> None:
        if series not in (1, 2):
            raise ValueError(f"series must be 1 or 2, got {series}")
        if api_mode not in (1, 2):
            raise ValueError(f"api_mode must be 1 or 2, got {api_mode}")
        if baud not in BAUD_CODES:
            raise ValueError(f"baud must be one of {BAUD_CODES}")
        if not 0 <= serial64 < 1 << 64:
            raise ValueError("serial64 out of range")
        if not _valid_ni(node_id.encode("ascii", "replace")):
            raise ValueError("node_id: at most 20 printable ASCII characters")
        if not 0x0B <= channel <= 0x1A or not 0 <= power_level <= 4:
            raise ValueError("channel must be 0x0B..0x1A and power_level 0..4")
        if my16 is not None and not 0 <= my16 <= 0xFFFF:
            raise ValueError("my16 out of range")
        if routing not in ("mesh", "one_hop"):
            raise ValueError(f"routing must be 'mesh' or 'one_hop', got {routing!r}")
        self.mesh = series == 2 and routing == "mesh"  # Series 1 (802.15.4) is always one hop
        self.prof = S1 if series == 1 else S2
        self.series = series
        self.serial64 = serial64
        self.rng = rng
        self._spec = _params(series)
        self._exec = EXEC_COMMANDS[series]
        # settings (what WR would save); Series 1 MY None -> 0xFFFE: 64-bit source addressing (the factory MY = 0
        # would give every robot the same 16-bit address)
        s: dict[str, int | bytes] = {
            "NI": node_id.encode("ascii"), "AP": api_mode, "BD": BAUD_CODES.index(baud), "PL": power_level,
            "RP": 0x28, "SM": 0, "DH": 0, "DL": 0, "ID": pan_id,
        }
        if series == 1:
            s |= {"MY": 0xFFFE if my16 is None else my16, "CH": channel, "RR": 0, "CE": 0}
            if not 0 <= pan_id <= 0xFFFF:
                raise ValueError("Series 1 pan_id is 16-bit")
        else:
            s |= {"SC": 0x1FFE, "NH": 0x1E, "AO": 0, "NT": 0x3C, "NO": 0, "BH": 0, "DD": 0x30000, "EE": 0}
            if not 0 <= pan_id < 1 << 64:
                raise ValueError("Series 2 pan_id is the 64-bit extended PAN ID")
        self._set = s
        self._saved = dict(s)
        self._queued: dict[str, int | bytes] = {}
        self.net_channel = channel  # Series 2: the network's channel and extended PAN ID (the coordinator's)
        self.net_epid = pan_id
        self._fixed_nwk = my16
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_KEYS, 0)
        self._booted = False
        self._t = 0
        self._reset_state()

    # -- public API ------------------------------------------------------------------------------------------------
    @property
    def api_mode(self) -> int:
        return int(self._set["AP"])

    @property
    def baud(self) -> int:
        return BAUD_CODES[int(self._set["BD"])]

    @property
    def joined(self) -> bool:
        return self.series == 1 or self._ai == 0

    def addr16(self) -> int:
        """The 16-bit source address on air: Series 1 MY (0xFFFE = none), Series 2 network address."""
        if self.series == 1:
            my = int(self._set["MY"])
            return 0xFFFE if my >= 0xFFFE else my
        return self._nwk

    def tx_power_dbm(self) -> float:
        return self.prof.pl_dbm[int(self._set["PL"])]

    def node(self) -> dict:
        """The radio-node settings the medium needs."""
        if self.series == 1:
            ch, pan = int(self._set["CH"]), int(self._set["ID"])
        else:
            ch, pan = self.net_channel, network_pan16(self.net_epid)
        return {"channel": ch, "pan_id": pan, "addr64": self.serial64, "addr16": self.addr16(),
                "tx_power_dbm": self.tx_power_dbm(), "sensitivity_dbm": self.prof.sensitivity_dbm,
                "series": self.series}

    def rssi_pwm_duty(self) -> float:
        return self._pwm

    def next_wake(self) -> int | None:
        """Earliest own timer: next UART frame fully clocked out, retry, join, reset, RSSI PWM timeout."""
        if not self._booted:
            return None
        times = [t for t in (self._join_at, self._reset_at, self._retry_at, self._pwm_until) if t is not None]
        if self._events:
            times.append(self._events[0][0])
        if self._uart:
            s, data, bns = self._uart[0]
            times.append(s + len(data) * bns)  # the next frame is complete
        return min(times) if times else None

    def step(self, t_ns: int, uart_rx: bytes, air_events: list[dict]) -> ModuleOutput:
        """Advance to ``t_ns``: air events (in time order), own timers, then the host's bytes (arrived by ``t_ns``)."""
        t_ns = max(int(t_ns), self._t)
        self._out = ModuleOutput()
        pwm_before = self._pwm
        if not self._booted:
            self._booted = True
            self._t = t_ns
            self._power_up(t_ns, MS_HW_RESET)
            self._last_node = None
        for ev in air_events if isinstance(air_events, list) else ():
            te = ev.get("t_ns") if isinstance(ev, dict) else None
            te = min(max(te, self._t), t_ns) if isinstance(te, int) and not isinstance(te, bool) else t_ns
            self._run_timers(te)
            self._t = te
            self._air_event(te, ev)
        if not isinstance(air_events, list):
            self.counters["bad_air_events"] += 1
        self._run_timers(t_ns)
        self._t = t_ns
        if uart_rx:
            self._feed(t_ns, bytes(uart_rx) if isinstance(uart_rx, bytes | bytearray | memoryview) else b"")
        self._pump()
        out = self._out
        out.uart_tx = self._clock_out(t_ns)
        node = self.node()
        if node != self._last_node:
            out.node = node
            self._last_node = node
        if self._pwm != pwm_before:
            out.rssi_pwm = self._pwm
        return out

    # -- state -----------------------------------------------------------------------------------------------------
    def _reset_state(self) -> None:
        self._rx = bytearray()  # frame being received (unescaped, from the length on)
        self._in_frame = False
        self._esc = False
        self._need = -1  # bytes still expected after the length (data + checksum), -1 = length not known yet
        self._uart: deque[list] = deque()  # one entry a frame: [start_ns, unsent bytes, byte_ns]
        self._uart_free = 0
        self._txq: deque[_TxJob] = deque()
        self._inflight: _TxJob | None = None
        self._retry_at: int | None = None
        self._reset_at: int | None = None
        self._join_at: int | None = None
        self._pwm = 0.0
        self._pwm_until: int | None = None
        self._pwm_last_rx = 0
        self._db = 0
        self._seq = int(self.rng.integers(0, 256))  # macDSN starts at a random value (IEEE 802.15.4)
        self._handle = 0
        self._seen: dict[int, tuple[int, int]] = {}
        self._ai = 0 if self.series == 1 else 0xFF
        self._nwk = 0xFFFE
        self._ea = self._ec = 0
        self._events: list[tuple[int, int, str, object]] = []  # (t, order, kind, arg): Series 2's own timers
        self._n_events = 0
        self._tsn = int(self.rng.integers(0, 256))  # transaction numbers of ZDO, remote AT and ND requests
        self._remote_at: dict[int, tuple[int, bytes, int, int]] = {}  # tsn -> (frame id, command, dest64, due)
        self._nd: dict | None = None  # the node discovery (ND or DN) under way
        self._heard: dict[int, tuple[int, int]] = {}  # ieee -> (nwk, last RSSI dBm): Mgmt_Lqi's neighbour table
        self.nwk: Nwk | None = Nwk(self) if self.mesh else None

    def _power_up(self, t: int, status: int) -> None:
        if self.series == 1:
            self._emit(t, bytes((0x8A, status)))
        else:
            if status != MS_HW_RESET:
                self._emit(t, bytes((0x8A, status)))
            self._start_join(t)

    def _start_join(self, t: int) -> None:
        """Series 2: scan SC channels up to the network's; join after the scan time or stay unjoined (AI 0x21/22)."""
        self._ai, self._nwk, self._join_at = 0xFF, 0xFFFE, None
        sc = int(self._set["SC"])
        bit = self.net_channel - 0x0B
        n = bin(sc & ((1 << (bit + 1)) - 1)).count("1")
        per_channel = (1 << 3) * 15_360_000 + 38 * MS  # SD = 3
        if not sc >> bit & 1:
            self._ai = 0x21
            return
        if int(self._set["ID"]) not in (0, self.net_epid):
            self._ai = 0x22
            return
        self._join_at = t + n * per_channel + 20 * MS + int(self.rng.integers(0, 50 * MS))

    def _run_timers(self, upto: int) -> None:
        while True:
            cands = [(tt, k) for k, tt in (("reset", self._reset_at), ("join", self._join_at),
                                          ("retry", self._retry_at), ("pwm", self._pwm_until)) if tt is not None]
            if self._events:
                cands.append((self._events[0][0], "~event"))  # after the module's own timers at the same time
            if not cands:
                return
            tt, kind = min(cands)
            if tt > upto:
                return
            self._t = max(self._t, tt)
            if kind == "~event":
                _, _, what, arg = heapq.heappop(self._events)
                self._on_event(tt, what, arg)
            elif kind == "reset":
                self._do_reset(tt)
            elif kind == "join":
                self._join_at = None
                self._ai = 0
                self._nwk = self._fixed_nwk if self._fixed_nwk is not None else int(self.rng.integers(1, 0xFFF8))
                self._emit(tt, bytes((0x8A, MS_JOINED)))
            elif kind == "retry":
                self._retry_at = None
                if self._inflight is not None:
                    self._send_air(self._inflight, tt)
            else:
                self._pwm_until = None
                self._pwm = 0.0

    def _do_reset(self, t: int) -> None:
        """FR: unsaved settings are lost, queues and buffers cleared, then the reset modem status."""
        self.counters["resets"] += 1
        if self._in_frame:  # a frame being received is lost with the reset
            self.counters["truncated_frames"] += 1
        self._set = dict(self._saved)
        self._queued.clear()
        self._reset_state()
        self._uart_free = t
        self._power_up(t, MS_WDT_RESET)

    # -- UART out --------------------------------------------------------------------------------------------------
    def _byte_ns(self) -> int:
        return round(10_000_000_000 / self.baud)  # 8N1: 10 bit times a byte

    def _do_occupancy(self, t: int) -> int:
        n = 0
        for s, data, bns in self._uart:
            done = 0 if t < s else min(len(data), (t - s) // bns)
            n += len(data) - done
        return n

    def _emit(self, t: int, data: bytes, rf_data: bool = False) -> bool:
        """Queue an API frame for the host; an RF data frame that does not fit the DO buffer is dropped whole."""
        wire = encode_frame(data, self.api_mode)
        if rf_data and self._do_occupancy(t) + len(wire) > self.prof.serial_tx_buffer:
            self.counters["rx_buffer_drops"] += 1
            return False
        bns = self._byte_ns()
        start = max(t, self._uart_free)
        self._uart.append([start, wire, bns])
        self._uart_free = start + len(wire) * bns
        return True

    def _clock_out(self, t: int) -> bytes:
        out = bytearray()
        while self._uart:
            entry = self._uart[0]
            s, data, bns = entry
            k = 0 if t < s else min(len(data), (t - s) // bns)
            out += data[:k]
            if k == len(data):
                self._uart.popleft()
                continue
            entry[0], entry[1] = s + k * bns, data[k:]
            break
        return bytes(out)

    # -- UART in: API frame parser ---------------------------------------------------------------------------------
    def _feed(self, t: int, data: bytes) -> None:
        c = self.counters
        for b in data:
            api = self.api_mode
            if not self._in_frame:
                if b == START:
                    self._begin()
                else:
                    c["discarded_bytes"] += 1
                continue
            if api == 2:
                if b == START:  # an unescaped delimiter inside a frame: the frame was cut short
                    c["escape_errors" if self._esc else "truncated_frames"] += 1
                    self._begin()
                    continue
                if self._esc:
                    self._esc = False
                    b ^= 0x20
                elif b == ESC:
                    self._esc = True
                    continue
            self._rx.append(b)
            if self._need < 0:
                if len(self._rx) == 2:
                    n = int.from_bytes(self._rx, "big")
                    if n == 0:
                        c["zero_length_frames"] += 1
                        self._in_frame = False
                    elif n + 4 > self.prof.serial_rx_buffer:
                        c["oversize_frames"] += 1
                        self._in_frame = False
                    else:
                        self._need = n + 1
                        self._rx.clear()
                continue
            self._need -= 1
            if self._need == 0:
                self._in_frame = False
                frame = bytes(self._rx)
                if sum(frame) & 0xFF != 0xFF:
                    c["checksum_errors"] += 1
                else:
                    c["frames_ok"] += 1
                    self._dispatch(t, frame[:-1])

    def _begin(self) -> None:
        self.counters["frames_started"] += 1
        self._in_frame, self._esc, self._need = True, False, -1
        self._rx.clear()

    def parser_busy(self) -> bool:
        """True while a frame has started but not ended (for accounting in tests)."""
        return self._in_frame

    def _dispatch(self, t: int, data: bytes) -> None:
        ftype = data[0]
        if ftype in (0x08, 0x09):
            self._at_frame(t, data)
        elif (self.series == 1 and ftype in (0x00, 0x01)) or (self.series == 2 and ftype in (0x10, 0x11)):
            self._tx_frame(t, data)
        elif self.series == 2 and ftype == 0x17:
            self._remote_at_frame(t, data)
        else:
            self.counters["unknown_frame_type"] += 1

    # -- AT commands -----------------------------------------------------------------------------------------------
    def _at_frame(self, t: int, data: bytes) -> None:
        c = self.counters
        if len(data) < 4:
            c["malformed_frames"] += 1
            return
        c["frames_handled"] += 1
        c["at_commands"] += 1
        fid, raw_cmd, param = data[1], data[2:4], data[4:]
        cmd = raw_cmd.decode("latin-1").upper()
        if self.series == 2 and cmd in DISCOVERY_COMMANDS:
            self._discover(t, fid, raw_cmd, bytes(param))
            return
        status, value, after = self._at(t, cmd, param, queue=data[0] == 0x09)
        if status:
            c["at_errors"] += 1
        if fid:
            self._emit(t, bytes((0x88, fid)) + raw_cmd + bytes((status,)) + value)
        if after is not None:
            after()

    def _at(self, t: int, cmd: str, param: bytes, queue: bool):
        """-> (status, response value, action to run after the response is queued)."""
        if cmd in self._exec:
            if cmd == "NR":
                if param and (len(param) > 1 or param[0] > 1):
                    return AT_INVALID_PARAMETER, b"", None
                return AT_OK, b"", lambda: self._leave(t)
            if param:
                return AT_INVALID_PARAMETER, b"", None
            if cmd == "AC":
                return AT_OK, b"", lambda: self._apply(t)
            if cmd == "WR":
                self._saved = dict(self._set | self._queued)
                return AT_OK, b"", None
            self._reset_at = t + FR_DELAY_NS  # FR
            return AT_OK, b"", None
        spec = self._spec.get(cmd)
        if spec is None:
            return AT_INVALID_COMMAND, b"", None
        if not param:
            return AT_OK, self._read(cmd, spec), None
        if spec.readonly:
            return AT_INVALID_PARAMETER, b"", None
        if spec.width == 0:
            if not _valid_ni(param):
                return AT_INVALID_PARAMETER, b"", None
            value: int | bytes = bytes(param).rstrip(b"\x00")
        else:
            value = int.from_bytes(param, "big")
            if not spec.lo <= value <= spec.hi or (cmd == "AO" and value not in AO_VALUES):
                return AT_INVALID_PARAMETER, b"", None
        self._queued[cmd] = value
        if queue:
            return AT_OK, b"", None
        return AT_OK, b"", lambda: self._apply(t)

    def _read(self, cmd: str, spec: _Param) -> bytes:
        live = {
            "SH": self.serial64 >> 32, "SL": self.serial64 & 0xFFFFFFFF, "VR": self.prof.vr, "HV": self.prof.hv,
            "AI": self._ai, "DB": self._db, "EA": self._ea, "EC": self._ec, "MY": self.addr16(),
            "OP": self.net_epid if self.joined else 0, "OI": network_pan16(self.net_epid) if self.joined else 0xFFFF,
            "NP": self.prof.max_unicast, "%V": round(SUPPLY_MV * 1024 / 1200), "NC": ROUTER_CHILDREN,
        }
        if self.series == 2:
            live["CH"] = self.net_channel if self.joined else 0
        else:
            live["MY"] = int(self._set["MY"])
        v = live[cmd] if cmd in live else self._set[cmd]
        if isinstance(v, bytes):
            return v
        return int(v).to_bytes(spec.width, "big")

    def _apply(self, t: int) -> None:
        """Apply queued settings (AC, or any 0x08 frame)."""
        changes, self._queued = self._queued, {}
        rejoin = False
        for k, v in changes.items():
            if k in ("EA", "EC"):
                setattr(self, "_" + k.lower(), 0)
                continue
            old = self._set.get(k)
            self._set[k] = v
            if self.series == 2 and k in ("ID", "SC") and v != old:
                rejoin = True
        if "RP" in changes:
            self._pwm_hold_changed(t)
        if rejoin:
            self._leave(t)

    def _leave(self, t: int) -> None:
        """Series 2: leave the network (NR, or ID/SC changed) and scan again."""
        if self._ai == 0:
            self._emit(t, bytes((0x8A, MS_DISASSOCIATED)))
        self._fail_pending(t, 0x22)
        self._start_join(t)

    # -- transmit --------------------------------------------------------------------------------------------------
    def _tx_frame(self, t: int, data: bytes) -> None:
        c = self.counters
        ftype = data[0]
        hdr = {0x00: 11, 0x01: 5, 0x10: 14, 0x11: 20}[ftype]
        if len(data) < hdr:
            c["malformed_frames"] += 1
            return
        size = len(data) + 4
        held = sum(j.size for j in self._txq) + (self._inflight.size if self._inflight else 0)
        if held + size > self.prof.serial_rx_buffer:
            c["serial_rx_overflow"] += 1  # lost in the serial receive buffer: no status
            return
        c["frames_handled"] += 1
        c["tx_requests"] += 1
        fid = data[1]
        if ftype == 0x00:
            dest64, dest16, opts, payload = int.from_bytes(data[2:10], "big"), 0xFFFE, data[10], data[11:]
            bcast = dest64 == BROADCAST64
            dst, addr = ("bcast", 0xFFFF) if bcast else ("64", dest64)
        elif ftype == 0x01:
            dest16, opts, payload = int.from_bytes(data[2:4], "big"), data[4], data[5:]
            dest64 = 0
            bcast = dest16 == 0xFFFF
            dst, addr = ("bcast", 0xFFFF) if bcast else ("16", dest16)
        else:
            dest64, dest16 = int.from_bytes(data[2:10], "big"), int.from_bytes(data[10:12], "big")
            if ftype == 0x10:
                aps, radius, opts, payload = zb.DATA_APS, data[12], data[13], data[14:]
            else:  # 0x11: source and destination endpoints, cluster, profile, then radius and options
                aps = (int.from_bytes(data[16:18], "big"), int.from_bytes(data[14:16], "big"), data[12], data[13])
                radius, opts, payload = data[18], data[19], data[20:]
            bcast = dest64 == BROADCAST64 or dest16 in (0xFFFC, 0xFFFD, 0xFFFF)
            if bcast:
                dst, addr = "bcast", 0xFFFF if dest16 not in (0xFFFC, 0xFFFD) else dest16
            elif dest64 == 0:  # the coordinator: network address 0x0000 (no coordinator in the simulation)
                dst, addr = "16", 0x0000
            else:
                dst, addr = "64", dest64
        job = _TxJob(fid, ftype, dst, addr, dest64, dest16, bytes(payload), opts, size)
        if self.series == 2:
            job.aps, job.radius = aps, radius
        limit = self.prof.max_broadcast if bcast else self.prof.max_unicast
        if len(payload) > limit:
            c["tx_too_large"] += 1
            if self.series == 2:
                self._status(t, job, 0x74)
            return  # Series 1 (10EF) discards an oversized API frame without a status (assumed)
        if self.series == 2:
            if not self.joined:
                self._status(t, job, 0x22)
                return
            if opts & 0x20:
                self._status(t, job, 0x2E)
                return
            if not bcast and self._is_me(dest64, dest16):
                if job.aps[0] == zb.ZDO_PROFILE and job.aps[3] == zb.ZDO_EP:
                    self._local_zdo(t, job)  # a ZDO request to itself: its own ZDO answers
                else:
                    self._status(t, job, 0x23)
                return
        self._txq.append(job)

    def _pump(self) -> None:
        """Start the next queued transmission when the radio is free (one at a time). With mesh routing a host's
        transmission is one at a time (it may wait seconds for a route), the module's own go at once."""
        if self.nwk is not None:
            if self._reset_at is not None:
                return
            for job in [j for j in self._txq if j.kind != "host"]:
                self._txq.remove(job)
                self.nwk.start(self._t, job)
            if self._inflight is None and self._txq:
                self._inflight = job = self._txq.popleft()
                self.nwk.start(self._t, job)
            return
        if self._inflight is None and self._txq and self._reset_at is None:
            job = self._txq.popleft()
            self._seq = (self._seq + 1) & 0xFF
            job.seq = self._seq
            self._inflight = job
            self._send_air(job, self._t)

    def _wants_ack(self, job: _TxJob) -> bool:
        return job.dst != "bcast" and not job.opts & 0x01

    def _send_air(self, job: _TxJob, t: int) -> None:
        self._handle += 1
        job.handle = self._handle
        job.attempts += 1
        job.attempt_t = t
        src16 = self.addr16()
        if self.series == 1:
            dst_len = 8 if job.dst == "64" else 2
            psdu = 2 + 1 + 2 + dst_len + (8 if src16 >= 0xFFFE else 2) + len(job.payload) + 2
            pan = 0xFFFF if job.opts & 0x04 else int(self._set["ID"])
            ch = int(self._set["CH"])
        else:  # MAC 11 + NWK 8 + IEEE src 8 (+ IEEE dst 8 for unicast) + APS 8: 84/92 bytes fill 127
            psdu = 35 + (8 if job.dst != "bcast" else 0) + len(job.payload)
            pan, ch = network_pan16(self.net_epid), self.net_channel
        ack = self._wants_ack(job)
        self._out.air_tx.append({
            "handle": job.handle, "src64": self.serial64, "src16": src16, "dst": job.dst, "dst_addr": job.dst_addr,
            "pan_id": pan, "channel": ch, "ack": ack, "mac_retries": 3 if ack else 0, "psdu_len": psdu,
            "seq": job.seq, "payload": job.payload, "opts": job.opts,
        } | ({"aps": list(job.aps)} if self.series == 2 else {}))
        self.counters["tx_air_frames"] += 1

    def _done(self, t: int, ev: dict) -> None:
        job = self._inflight
        handle, status = ev.get("handle"), ev.get("status")
        if status not in ("ok", "no_ack", "cca_fail") or not isinstance(handle, int):
            self.counters["bad_air_events"] += 1
            return
        if self.nwk is not None:
            if status == "cca_fail":
                self._ec = min(self._ec + 1, 0xFFFF)
            if not self.nwk.mac_done(t, handle, status):
                self.counters["stale_done"] += 1
            return
        if job is None or handle != job.handle:
            self.counters["stale_done"] += 1
            return
        if status == "cca_fail":
            self._ec = min(self._ec + 1, 0xFFFF)
        if self.series == 1:
            if job.dst == "bcast":  # (RR + 2) packets on each broadcast when RR > 0
                job.copies_ok += status != "cca_fail"
                rr = int(self._set["RR"])
                if rr and job.attempts < rr + 2:
                    self._retry_at = t + int(self.rng.integers(0, 48 * MS + 1))
                    return
                self._finish(t, job, 0 if job.copies_ok else 2)
                return
            if status == "ok":
                self._finish(t, job, 0)
            elif status == "no_ack" and self._wants_ack(job) and job.attempts <= int(self._set["RR"]):
                self._retry_at = t + int(self.rng.integers(0, 48 * MS + 1))
            else:
                if status == "no_ack":
                    self._ea = min(self._ea + 1, 0xFFFF)
                self._finish(t, job, 1 if status == "no_ack" else 2)
            return
        if status == "ok":
            self._finish(t, job, 0x00)
        elif status == "cca_fail":
            self._finish(t, job, 0x02)
        elif self._wants_ack(job) and job.attempts < 3:  # APS retries: three attempts, each with its timeout
            self._retry_at = max(t, job.attempt_t + self._unicast_timeout_ns())
        else:
            self._finish(t, job, 0x21)

    def _finish(self, t: int, job: _TxJob, status: int) -> None:
        if self.nwk is not None and job is not self._inflight:  # one of the module's own, beside the host's
            self.counters["tx_ok" if status == 0 else "tx_failed"] += 1
            self._report(t, job, status)
            return
        self._inflight = None
        self._retry_at = None
        self.counters["tx_ok" if status == 0 else "tx_failed"] += 1
        self._report(t, job, status)
        self._pump()

    def _report(self, t: int, job: _TxJob, status: int) -> None:
        """A transmission ended: the host's gets its transmit status; a remote AT request that did not reach its
        node answers its host with status 4; one that did waits for its answer; the module's own say nothing."""
        if job.kind == "host":
            self._status(t, job, status)
        elif job.kind == "remote_at" and job.ctx in self._remote_at:
            if status != 0 and job.dst != "bcast":
                self._remote_at_failed(t, job.ctx)
            else:
                self._at_event(t + self._unicast_timeout_ns(), "remote_at_due", job.ctx)

    def _status(self, t: int, job: _TxJob, status: int) -> None:
        if not job.frame_id:
            return
        if self.series == 1:
            self._emit(t, bytes((0x89, job.frame_id, status)))
            return
        if job.dst == "bcast":
            addr16, disc = 0xFFFE, 0x00
        elif self.nwk is not None and status not in (0x22, 0x23, 0x2E, 0x74):
            addr16 = job.dest16_found if status == 0 and job.dest16_found is not None else 0xFFFD
            disc = job.disc
        elif status in (0x00, 0x23) and self._is_me(job.dest64, job.dest16):
            addr16, disc = self._nwk, 0x00
        elif status == 0:
            heard = self._heard.get(job.dest64)
            known = heard[0] if heard is not None and heard[0] < 0xFFF8 else None
            addr16 = known if known is not None else (job.dest16 if job.dest16 != 0xFFFE else 0xFFFE)
            disc = 0x00 if known is not None or job.dest16 != 0xFFFE else 0x01
        else:
            addr16, disc = 0xFFFD, 0x00
        retries = max(0, job.attempts - 1)
        self._emit(t, bytes((0x8B, job.frame_id)) + addr16.to_bytes(2, "big") + bytes((retries, status, disc)))

    def _fail_pending(self, t: int, status: int) -> None:
        jobs = ([self._inflight] if self._inflight else []) + list(self._txq)
        if self.nwk is not None:
            jobs += [tx.job for tx in self.nwk.txs.values() if tx.job not in jobs]
            self.nwk.reset()
        self._inflight, self._retry_at = None, None
        self._txq.clear()
        for j in jobs:
            self.counters["tx_failed"] += 1
            self._report(t, j, status)

    # -- Series 2: the ZDO server, remote AT commands and node discovery ------------------------------------------
    def mac_send(self, t: int, f: MacFrame) -> int:
        """Put one of the network layer's frames on the air; its handle (the medium's ``done`` names it)."""
        self._handle += 1
        self._seq = (self._seq + 1) & 0xFF
        bcast = f.dst16 is None
        # MAC 11 + NWK 8 + IEEE source 8 (+ IEEE destination 8 for unicast) + APS 8 (not on routing commands)
        psdu = 27 + (0 if bcast else 8) + (8 if f.nwk[0] == 0 else 0) + len(f.payload)
        self._out.air_tx.append({
            "handle": self._handle, "src64": self.serial64, "src16": self._nwk, "dst": "bcast" if bcast else "16",
            "dst_addr": 0xFFFF if bcast else f.dst16, "pan_id": network_pan16(self.net_epid),
            "channel": self.net_channel, "ack": not bcast, "mac_retries": 0 if bcast else 3,
            "psdu_len": min(psdu, 127), "seq": self._seq, "payload": f.payload, "opts": 0, "aps": list(f.aps),
            "nwk": list(f.nwk), "hops": f.hops,  # (hops: the statistics' count, left out of psdu_len: not on air)
        })
        self.counters["tx_air_frames"] += 1
        return self._handle

    def _zdo_nwk_addr_req(self, t: int, ieee: int) -> None:
        """Address discovery: a NWK_addr_req for ``ieee`` to every node whose receiver is on (0xFFFD)."""
        body = bytes((self._next_tsn(),)) + ieee.to_bytes(8, "little") + b"\x00\x00"
        if self.nwk is not None:
            self.nwk.broadcast(t, (zb.ZDO_PROFILE, zb.NWK_ADDR_REQ, zb.ZDO_EP, zb.ZDO_EP), body,
                               self.nwk.radius(0), 0xFFFD)

    def _is_me(self, dest64: int, dest16: int) -> bool:
        return dest64 == self.serial64 or (dest64 == 0xFFFFFFFFFFFFFFFF and dest16 == self._nwk)

    def _me(self) -> zb.NodeInfo:
        return zb.NodeInfo(self.serial64, self._nwk, bytes(self._set["NI"]))

    def _unicast_timeout_ns(self) -> int:
        """[ZB]: a unicast's timeout, (50 x NH + 100) ms an attempt."""
        return (50 * int(self._set["NH"]) + 100) * MS

    def _next_tsn(self) -> int:
        self._tsn = (self._tsn + 1) & 0xFF
        return self._tsn

    def _at_event(self, t: int, what: str, arg: object) -> None:
        self._n_events += 1
        heapq.heappush(self._events, (t, self._n_events, what, arg))

    def _on_event(self, t: int, what: str, arg: object) -> None:
        if what.startswith("nwk_"):
            if self.nwk is None:
                return
            if what == "nwk_send":
                self.nwk._send(t, arg)  # type: ignore[arg-type]
            elif what == "nwk_held_due":
                self.nwk.held_timer(t, arg)  # type: ignore[arg-type]
            elif what == "nwk_rrep":
                self.nwk.rrep_timer(t, arg)  # type: ignore[arg-type]
            elif what == "nwk_rreq":
                self.nwk.rreq_timer(t, arg)  # type: ignore[arg-type]
            elif what == "nwk_bcast":
                self.nwk.bcast_timer(t, arg)  # type: ignore[arg-type]
            else:
                self.nwk.on_timer(t, what, arg)  # type: ignore[arg-type]
        elif what == "remote_at_due":
            if arg in self._remote_at:
                self.counters["remote_at_timeouts"] += 1
                self._remote_at_failed(t, int(arg))  # type: ignore[arg-type]
        elif what == "nd_reply":
            src64, tsn, rsp = arg  # type: ignore[misc]
            if self.joined:
                self.counters["nd_answered"] += 1
                dd = int(self._set["DD"]) if int(self._set["NO"]) & 0x01 else None
                self._internal_job(src64, bytes((tsn,)) + zb.nd_record(self._me(), dd),
                                   (zb.DIN_PROFILE, rsp, zb.DDO_EP, zb.DDO_EP))
        elif what == "nd_end":
            nd = self._nd
            if nd is not None and nd["tsn"] == arg:
                self._nd = None
                if nd["cmd"] == b"DN" or (nd["ni"] and not nd["found"]):  # nobody of that NI answered within NT
                    self._emit(t, bytes((0x88, nd["fid"])) + nd["cmd"] + bytes((AT_ERROR,)))

    def _internal_job(self, dest64: int, payload: bytes, aps: tuple[int, int, int, int], kind: str = "internal",
                      ctx: int = 0, opts: int = 0, radius: int = 0) -> _TxJob:
        """Queue a frame of the module's own (a ZDO or DDO answer, a discovery): it holds no serial buffer space."""
        bcast = dest64 == BROADCAST64
        dst, addr = ("bcast", 0xFFFF) if bcast else ("64", dest64)
        job = _TxJob(0, 0x11, dst, addr, dest64, 0xFFFE, payload, opts, 0, aps=aps, radius=radius, kind=kind,
                     ctx=ctx)
        self._txq.append(job)
        return job

    def _neighbours(self) -> list[tuple[int, int, int]]:
        """The nodes heard, for Mgmt_Lqi: (ieee, nwk, LQI); LQI maps sensitivity..-40 dBm onto 0..255 (assumed)."""
        lo = self.prof.sensitivity_dbm
        return [(ieee, nwk, round(min(max((rssi - lo) / (-40.0 - lo), 0.0), 1.0) * 255))
                for ieee, (nwk, rssi) in sorted(self._heard.items())]

    def _local_zdo(self, t: int, job: _TxJob) -> None:
        """A ZDO request the host addressed to this module: "self-addressed" (0x23), and answered by its own ZDO,
        whose answer reaches the host as 0x91 when AO asks for explicit output (what digi-xbee's role read needs)."""
        self.counters["zdo_requests"] += 1
        self._status(t, job, 0x23)
        ans = zb.zdo_answer(job.aps[1], job.payload, self._me(), self._neighbours())
        if ans is not None:
            self.counters["zdo_answered"] += 1
            if int(self._set["AO"]) & 1:
                self._deliver(t, self.serial64, self._nwk, (zb.ZDO_PROFILE, ans[0], zb.ZDO_EP, zb.ZDO_EP), ans[1],
                              0x01)

    def _zdo_rx(self, t: int, src64: int, src16: int, aps: tuple, payload: bytes, opts: int) -> None:
        """A ZDO frame from the air: a request is answered (unless AO 3 hands the ones the stack does not serve to the
        host); a response goes to the host when AO asks for explicit output, else nowhere."""
        cluster = aps[1]
        if cluster >= 0x8000:
            if (self.nwk is not None and cluster == (zb.NWK_ADDR_REQ | 0x8000) and len(payload) >= 12
                    and payload[1] == zb.ZDP_SUCCESS):
                self.nwk.learned_address(t, int.from_bytes(payload[2:10], "little"),
                                         int.from_bytes(payload[10:12], "little"))
            if int(self._set["AO"]) & 1:
                self._deliver(t, src64, src16, aps, payload, opts)
            return
        self.counters["zdo_requests"] += 1
        ans = zb.zdo_answer(cluster, payload, self._me(), self._neighbours())
        if ans is None:
            return
        if int(self._set["AO"]) == 3 and (cluster in zb.APPLICATION_ZDO or ans[1][1:2] == bytes((
                zb.ZDP_NOT_SUPPORTED,))):
            self._deliver(t, src64, src16, aps, payload, opts)  # pass-through: the host answers it, if it will
            return
        self.counters["zdo_answered"] += 1
        self._internal_job(src64, ans[1], (zb.ZDO_PROFILE, ans[0], zb.ZDO_EP, zb.ZDO_EP))

    def _ddo_rx(self, t: int, src64: int, src16: int, cluster: int, payload: bytes, rssi: int) -> None:
        """A frame to the Digi device endpoint: a remote AT command or its answer, a node discovery or its answer."""
        ddo = (zb.DIN_PROFILE, 0, zb.DDO_EP, zb.DDO_EP)
        if cluster == zb.DDO_REMOTE_AT_REQ and (req := zb.parse_remote_at_req(payload)) is not None:
            tsn, opts, raw_cmd, param = req
            cmd = raw_cmd.decode("latin-1").upper()
            if cmd in DISCOVERY_COMMANDS:
                status, value, after = AT_INVALID_COMMAND, b"", None
            else:
                status, value, after = self._at(t, cmd, param, queue=not opts & 0x02)
            self.counters["remote_at_served"] += 1
            self._internal_job(src64, zb.ddo_remote_at_rsp(tsn, raw_cmd, status, value),
                               (ddo[0], zb.DDO_REMOTE_AT_RSP, ddo[2], ddo[3]))
            if after is not None:
                after()
        elif cluster == zb.DDO_REMOTE_AT_RSP and (rsp := zb.parse_remote_at_rsp(payload)) is not None:
            tsn, raw_cmd, status, value = rsp
            pending = self._remote_at.get(tsn)
            if pending is None or pending[1] != bytes(raw_cmd).upper():
                return  # late, or not ours
            fid, _, dest64, _ = pending
            if dest64 != BROADCAST64:  # a broadcast request collects every answer until its time is up
                del self._remote_at[tsn]
            if fid:
                self._emit(t, bytes((0x97, fid)) + src64.to_bytes(8, "big") + src16.to_bytes(2, "big") + raw_cmd
                           + bytes((status,)) + value)
        elif cluster in (zb.DDO_ND_REQ, zb.DDO_DN_REQ) and (req := zb.parse_nd_req(payload)) is not None:
            tsn, nt, ni = req
            if not ni or ni == bytes(self._set["NI"]):  # each waits a random time within NT (uniform: assumed)
                window = max(int(nt), 1) * 100 * MS
                rsp = zb.DDO_ND_RSP if cluster == zb.DDO_ND_REQ else zb.DDO_DN_RSP
                self._at_event(t + int(self.rng.integers(0, window)), "nd_reply", (src64, tsn, rsp))
        elif cluster in (zb.DDO_ND_RSP, zb.DDO_DN_RSP) and len(payload) > 11:
            nd = self._nd
            if nd is None or payload[0] != nd["tsn"]:
                return
            record = payload[1:]
            nd["found"] = True
            if nd["cmd"] == b"DN":
                self._nd = None
                self._emit(t, bytes((0x88, nd["fid"])) + b"DN" + bytes((AT_OK,)) + record[:10])
            else:
                self._emit(t, bytes((0x88, nd["fid"])) + b"ND" + bytes((AT_OK,)) + record)
        else:
            self.counters["ddo_malformed"] += 1

    def _remote_at_frame(self, t: int, data: bytes) -> None:
        """0x17 Remote AT Command Request: sent on the Digi device endpoint; 0x97 answers with the remote's reply,
        or with status 4 when the request was not delivered or not answered in time."""
        c = self.counters
        if len(data) < 15:
            c["malformed_frames"] += 1
            return
        c["frames_handled"] += 1
        fid, dest64, dest16, opts = data[1], int.from_bytes(data[2:10], "big"), int.from_bytes(data[10:12], "big"), \
            data[12]
        raw_cmd, param = bytes(data[13:15]).upper(), bytes(data[15:])
        tsn = self._next_tsn()
        self._remote_at[tsn] = (fid, raw_cmd, dest64, 0)
        if not self.joined or self._is_me(dest64, dest16):
            self._remote_at_failed(t, tsn)
            return
        if dest64 == 0xFFFFFFFFFFFFFFFF and dest16 < 0xFFF8:
            dest64 = next((a for a, (n16, _) in self._heard.items() if n16 == dest16), dest64)
        self._internal_job(dest64, zb.ddo_remote_at_req(tsn, opts, raw_cmd, param),
                           (zb.DIN_PROFILE, zb.DDO_REMOTE_AT_REQ, zb.DDO_EP, zb.DDO_EP), kind="remote_at", ctx=tsn,
                           opts=opts & 0x01)

    def _remote_at_failed(self, t: int, tsn: int) -> None:
        fid, raw_cmd, dest64, _ = self._remote_at.pop(tsn)
        if fid and dest64 != BROADCAST64:
            self._emit(t, bytes((0x97, fid)) + dest64.to_bytes(8, "big") + b"\xff\xfe" + raw_cmd
                       + bytes((REMOTE_AT_FAILED,)))

    def _discover(self, t: int, fid: int, raw_cmd: bytes, param: bytes) -> None:
        """ND (every node, or the one of NI ``param``) and DN (the one of NI ``param``, its addresses): a broadcast to
        the Digi device endpoints; each node answers after a random wait within NT, and each answer that comes in
        time reaches the host as an AT response. DN with no NI, or ND/DN when not joined, fail at once."""
        cmd = raw_cmd.upper()
        self.counters["at_commands"] += 1
        self.counters["frames_handled"] += 1
        ni = param.rstrip(b"\x00")
        if not self.joined or (cmd == b"DN" and not ni) or not _valid_ni(ni):
            self.counters["at_errors"] += 1
            if fid:
                self._emit(t, bytes((0x88, fid)) + raw_cmd + bytes((AT_ERROR,)))
            return
        tsn = self._next_tsn()
        nt = int(self._set["NT"])
        self._nd = {"tsn": tsn, "fid": fid, "cmd": cmd, "ni": ni, "found": False}
        if cmd == b"ND" and int(self._set["NO"]) & 0x02 and (not ni or ni == bytes(self._set["NI"])):
            dd = int(self._set["DD"]) if int(self._set["NO"]) & 0x01 else None
            self._emit(t, bytes((0x88, fid)) + b"ND" + bytes((AT_OK,)) + zb.nd_record(self._me(), dd))
            self._nd["found"] = True
        req = zb.DDO_ND_REQ if cmd == b"ND" else zb.DDO_DN_REQ
        self._internal_job(BROADCAST64, zb.ddo_nd_req(tsn, nt, ni), (zb.DIN_PROFILE, req, zb.DDO_EP, zb.DDO_EP),
                           radius=int(self._set["BH"]))
        self._at_event(t + nt * 100 * MS, "nd_end", tsn)

    # -- receive ---------------------------------------------------------------------------------------------------
    def _air_event(self, t: int, ev: object) -> None:
        if not isinstance(ev, dict) or ev.get("ev") not in ("rx", "done"):
            self.counters["bad_air_events"] += 1
            return
        if ev["ev"] == "done":
            self._done(t, ev)
            return
        fr, rssi = ev.get("frame"), ev.get("rssi_dbm")
        if not isinstance(fr, dict) or not isinstance(rssi, int | float) or not valid_air_frame(fr):
            self.counters["rx_malformed"] += 1
            return
        self.counters["rx_frames"] += 1
        if self._reset_at is not None or not self._accepts(fr):
            self.counters["rx_filtered"] += 1
            return
        rssi = round(rssi)
        self._db = min(max(-rssi, self.prof.db_min), 0xFF)
        self._pwm_rx(t, rssi)
        src64, src16 = fr["src64"], fr["src16"]
        prev = self._seen.get(src64)
        if prev is not None and prev[0] == fr["seq"] and t - prev[1] < DUP_WINDOW_NS:
            self.counters["rx_duplicates"] += 1
            return
        self._seen[src64] = (fr["seq"], t)
        payload = fr["payload"]
        bcast = fr["dst"] == "bcast"
        if self.series == 1:
            opts = (0x02 if bcast else 0) | (0x04 if fr["pan_id"] == 0xFFFF else 0)
            if src16 < 0xFFFE:
                data = bytes((0x81,)) + src16.to_bytes(2, "big") + bytes((self._db, opts)) + payload
            else:
                data = bytes((0x80,)) + src64.to_bytes(8, "big") + bytes((self._db, opts)) + payload
        else:
            self._heard[src64] = (src16, rssi)
            opts = 0x02 if bcast else (0x01 if fr["ack"] else 0x00)
            if self.nwk is not None:
                up = self.nwk.on_rx(t, fr, rssi)
                if up is None:
                    return
                src64, src16, bcast = up
                opts = 0x02 if bcast else 0x01
            aps = tuple(fr.get("aps", zb.DATA_APS))
            if aps[0] == zb.ZDO_PROFILE and aps[3] == zb.ZDO_EP:
                self._zdo_rx(t, src64, src16, aps, payload, opts)
                return
            if aps[0] == zb.DIN_PROFILE and aps[3] == zb.DDO_EP:
                self._ddo_rx(t, src64, src16, aps[1], payload, rssi)
                return
            if self.nwk is not None and not bcast:  # a unicast for the host: how many hops it took
                self.nwk.stats["data_delivered"] += 1
                self.nwk.stats["data_hops"] += air_hops(fr)
            self._deliver(t, src64, src16, aps, payload, opts)
            return
        if self._emit(t, data, rf_data=True):
            self.counters["rx_delivered"] += 1

    def _deliver(self, t: int, src64: int, src16: int, aps: tuple, payload: bytes, opts: int) -> None:
        """Series 2: received data to the host, as 0x91 Explicit RX Indicator when AO asks for it, else 0x90."""
        head = src64.to_bytes(8, "big") + src16.to_bytes(2, "big")
        if int(self._set["AO"]) & 1:
            data = bytes((0x91,)) + head + bytes((aps[2], aps[3])) + aps[1].to_bytes(2, "big") \
                + aps[0].to_bytes(2, "big") + bytes((opts,)) + payload
        else:
            data = bytes((0x90,)) + head + bytes((opts,)) + payload
        if self._emit(t, data, rf_data=True):
            self.counters["rx_delivered"] += 1

    def _accepts(self, fr: dict) -> bool:
        n = self.node()
        if fr["channel"] != n["channel"] or fr["src64"] == self.serial64 or not self.joined:
            return False
        if len(fr["payload"]) > self.prof.max_broadcast:
            return False
        if fr["pan_id"] != n["pan_id"] and not (self.series == 1 and fr["pan_id"] == 0xFFFF):
            return False
        if fr["dst"] == "bcast":
            return True
        if fr["dst"] == "64":
            return fr["dst_addr"] == self.serial64
        a16 = self.addr16()
        return a16 < 0xFFFE and fr["dst_addr"] == a16

    # -- RSSI PWM --------------------------------------------------------------------------------------------------
    def _pwm_rx(self, t: int, rssi_dbm: int) -> None:
        rp = int(self._set["RP"])
        if rp == 0:
            return
        self._pwm = rssi_pwm_formula(rssi_dbm, self.prof.sensitivity_dbm)
        self._pwm_last_rx = t
        self._pwm_until = None if rp == 0xFF else t + rp * 100 * MS

    def _pwm_hold_changed(self, t: int) -> None:
        rp = int(self._set["RP"])
        if rp == 0:
            self._pwm, self._pwm_until = 0.0, None
        elif self._pwm > 0:
            self._pwm_until = None if rp == 0xFF else max(t, self._pwm_last_rx + rp * 100 * MS)


def _valid_ni(b: bytes) -> bool:
    b = bytes(b).rstrip(b"\x00")
    return len(b) <= 20 and all(0x20 <= x < 0x7F for x in b)



def valid_air_frame(fr: object) -> bool:
    """The shape of an air frame as modules submit and receive it (anything else is dropped and counted)."""
    if not isinstance(fr, dict):
        return False
    ints = ("handle", "src64", "src16", "dst_addr", "pan_id", "channel", "seq", "psdu_len", "mac_retries")
    return (
        all(type(fr.get(k)) is int for k in ints)
        and fr.get("dst") in ("bcast", "64", "16")
        and isinstance(fr.get("payload"), bytes)
        and isinstance(fr.get("ack"), bool)
        and 0 <= fr["src64"] < 1 << 64
        and 0 <= fr["src16"] <= 0xFFFF
        and 0 <= fr["dst_addr"] < 1 << 64
        and 0 <= fr["handle"] < 1 << 62
        and 11 <= fr["channel"] <= 26
        and 1 <= fr["psdu_len"] <= 127
        and 0 <= fr["mac_retries"] <= 7
        and ("aps" not in fr or zb.valid_aps(fr["aps"]))
        and ("nwk" not in fr or valid_nwk(fr["nwk"]))
    )
