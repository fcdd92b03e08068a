"""A 2.4 GHz IEEE 802.15.4 radio medium for the robots' XBee modules: propagation, PHY errors, CSMA-CA, ACKs.

The medium lives in the world process. Each robot's XBee module (``firmware_sim.modules.xbee``) submits air frames;
the medium runs an event-driven simulation of the shared channel in integer nanoseconds and answers with
``rx`` events (to every module that decoded a frame) and one ``done`` event per submitted frame (to its
sender). Everything is deterministic per seed: the same seed and the same call sequence give the same
events, bit for bit.

Propagation (see ``docs/radio.md`` for the calibration against Couceiro (2013), §3.2.3 and Table 5.2)::

    P_rx = P_tx - PL(d0) - 10 n log10(d / d0) - walls * L_wall + S_ij(x_i, x_j, t) + F     [dBm]

- log-distance path loss, optionally dual-slope (a second exponent beyond a breakpoint);
- ``walls``: obstacles the straight line crosses (from the world's geometry), ``L_wall`` dB each
  (COST 231 multi-wall model);
- ``S_ij``: log-normal shadowing, a Gaussian random field over both end positions and time, with an
  exponential correlation in distance (Gudmundson 1991) and in time, reciprocal (``S_ij = S_ji``), drawn as a
  sum of sinusoids (spectral method), so it is a pure function of the positions, the time and the seed;
- ``F``: fast fading (Rician or Rayleigh power gain, unit mean) per packet, reciprocal, correlated per link
  in time and in the distance its ends travel (a Gauss-Markov complex gain), so that MAC retries a few
  milliseconds apart see nearly the same fade, as on a real slowly moving robot.

Reception: a receiver locks onto the first frame that arrives at or above its sensitivity while it is
neither transmitting nor receiving (no capture of a later frame); nothing below the sensitivity is ever
decoded. The frame is then decoded with the probability given by the IEEE 802.15.4 2.4 GHz O-QPSK
BER(SINR) curve (IEEE Std 802.15.4-2006, Annex E.4.1.8), piecewise over the overlaps with other
transmissions on the channel (collisions and capture follow from the SINR).

MAC (IEEE Std 802.15.4-2006, §7.5.1.4 and Tables 22 and 86): unslotted CSMA-CA (macMinBE 3, macMaxBE 5,
macMaxCSMABackoffs 4, aUnitBackoffPeriod 20 symbols = 320 us, CCA over 8 symbols = 128 us), aTurnaroundTime
12 symbols = 192 us, acknowledged unicast with a 5-byte ACK PSDU and macAckWaitDuration 54 symbols = 864 us,
``mac_retries`` (macMaxFrameRetries, 3) retransmissions, SIFS/LIFS after each frame. Air time is
(6 PHY bytes + psdu_len) x 32 us at 250 kbit/s.
"""

from __future__ import annotations

import heapq
import itertools
import math
import statistics
from collections import deque
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from bridge.core import foxglove as fx
from bridge.core.entities import entity
from bridge.core.medium import Medium
from bridge.core.rng import stream
from bridge.media.impairments import AIR_FAULTS, Impairments
from firmware_sim.modules.xbee import valid_air_frame
from swarm_logic.graph import components

if TYPE_CHECKING:
    from bridge.core.hub import Hub

US = 1_000  # ns per microsecond
BIT_NS = 4_000  # 250 kbit/s
RSSI_HIST_LO_DBM = -100
RSSI_HIST_BIN_DB = 2
RSSI_HIST_BINS = 40  # -100 .. -20 dBm; the first and last bins also hold what falls outside
LOSS_CAUSES = ("below_sensitivity", "collision", "corrupt")


class Geometry(Protocol):
    """What the medium needs from the world (implemented over pybullet in the world process)."""

    def positions(self) -> np.ndarray:
        """(n, 2) robot positions (m), now."""
        ...

    def walls(self, src: int, dsts: np.ndarray) -> np.ndarray:
        """Number of obstacles the straight line from robot ``src`` to each robot in ``dsts`` crosses."""
        ...

    def alive(self) -> np.ndarray:
        """(n,) bool: robots whose radios still work."""
        ...


class RadioCfg(BaseModel):
    """The ``[radio]`` section: propagation, PHY and MAC of the 2.4 GHz 802.15.4 channel."""

    model_config = ConfigDict(extra="forbid")

    tx_power_dbm: float = Field(
        3.0, ge=-40, le=30,
        description="transmit power (dBm) of a node that did not announce one: XBee ZB (Series 2) at PL=4, "
                    "+3 dBm (Digi XBee/XBee-PRO ZB RF module manual, PL table)")
    sensitivity_dbm: float = Field(
        -94.0, ge=-120, le=-40,
        description="receiver sensitivity (dBm) of a node that did not announce one; nothing weaker is decoded: "
                    "-94 dBm, the XBee S2 figure used by Couceiro (2013), §3.2.3")
    d0_m: float = Field(1.0, gt=0, description="reference distance (m) of the path loss PL(d0)")
    path_loss_d0_db: float = Field(
        66.0, ge=0, le=150,
        description="path loss (dB) at d0. Calibrated: the eSwarBots' near-floor antennas lose ~26 dB over free "
                    "space (40 dB at 1 m, 2.44 GHz) so that the median RSSI is -75 dBm at 2-4 m (Couceiro 2013, "
                    "§3.2.3); see docs/radio.md")
    path_loss_exponent: float = Field(
        2.3, gt=0, le=10,
        description="path loss exponent n (up to the breakpoint when one is set). Calibrated so that 55-80 % "
                    "of unicast frames arrive beyond 10 m in the thesis pavilion and some at 30 m in an open "
                    "corridor (Couceiro 2013, §3.2.3); see docs/radio.md")
    breakpoint_m: float | None = Field(
        None, gt=0, description="dual-slope model: distance (m) beyond which path_loss_exponent_far applies")
    path_loss_exponent_far: float | None = Field(
        None, gt=0, le=10, description="exponent beyond breakpoint_m (default: path_loss_exponent)")
    min_distance_m: float = Field(0.1, gt=0, description="distances are clamped to at least this (m)")
    wall_loss_db: float = Field(
        3.0, ge=0, le=60,
        description="loss (dB) per obstacle crossed by the straight line: light internal wall of the COST 231 "
                    "multi-wall model (3.4 dB); pillars and crates are narrow, diffraction fills in behind them")
    shadowing_sigma_db: float = Field(
        4.0, ge=0, le=20,
        description="log-normal shadowing standard deviation (dB): Couceiro (2013) Table 5.2 one-hop RSSI "
                    "spreads 2.9-5.1 dB; TinyOS/Zuniga indoor model 3.2 dB")
    shadowing_decorrelation_m: float = Field(
        2.0, gt=0,
        description="distance (m) over which shadowing correlation falls to 1/e when an end moves "
                    "(exponential model after Gudmundson 1991; indoor values are 1-3 m)")
    shadowing_decorrelation_s: float | None = Field(
        10.0, gt=0,
        description="time (s) over which shadowing of a static link decorrelates to 1/e (people and doors "
                    "moving); None freezes it")
    shadowing_components: int = Field(
        24, ge=4, le=256, description="sinusoids in the spectral shadowing field (more: closer to Gaussian)")
    fading: Literal["none", "rayleigh", "rician"] = Field(
        "rician", description="per-packet fast fading of the received power (unit mean power gain)")
    rician_k_db: float = Field(
        6.0, ge=-20, le=40,
        description="Rician K factor (dB): a dominant direct path among floor and body reflections over a few "
                    "metres indoors")
    fading_coherence_s: float | None = Field(
        0.2, gt=0,
        description="time (s) over which the fading of a static link decorrelates to 1/e (people moving; Doppler "
                    "of a few Hz); MAC retries milliseconds apart see nearly the same fade. None: only motion")
    fading_decorrelation_m: float = Field(
        0.05, gt=0,
        description="travel (m, both ends summed) over which fading decorrelates to 1/e: ~0.4 wavelength at "
                    "2.44 GHz (Clarke/Jakes: first zero of J0 at 0.38 wavelength)")
    noise_floor_dbm: float | None = Field(
        None, le=-60,
        description="receiver noise (dBm); None derives it per receiver from its sensitivity so that a 20-byte "
                    "PSDU has 1 % PER at the sensitivity (the standard's definition, IEEE 802.15.4-2006 §6.1.7)")
    cca_threshold_dbm: float = Field(
        -75.0, ge=-110, le=0,
        description="CCA energy-detection threshold (dBm): at most 10 dB above the -85 dBm reference "
                    "sensitivity (IEEE 802.15.4-2006 §6.9.9)")
    cca_carrier_sense: bool = Field(
        True, description="CCA also reports busy while the radio is receiving a frame (CCA mode 3)")
    byte_us: int = Field(32, ge=1, description="air time per byte (us): 250 kbit/s O-QPSK")
    phy_header_bytes: int = Field(6, ge=0, description="preamble 4 + SFD 1 + PHR 1 bytes before the PSDU")
    unit_backoff_us: int = Field(320, ge=1, description="aUnitBackoffPeriod, 20 symbols")
    cca_us: int = Field(128, ge=1, description="CCA detection time, 8 symbols")
    turnaround_us: int = Field(192, ge=0, description="aTurnaroundTime RX<->TX, 12 symbols")
    ack_wait_us: int = Field(864, ge=1, description="macAckWaitDuration, 54 symbols at 2.4 GHz")
    ack_psdu_len: int = Field(5, ge=1, description="ACK frame PSDU bytes (FCF 2, DSN 1, FCS 2)")
    sifs_us: int = Field(192, ge=0, description="macSIFSPeriod, 12 symbols, after frames up to 18 bytes")
    lifs_us: int = Field(640, ge=0, description="macLIFSPeriod, 40 symbols, after longer frames")
    max_sifs_frame_bytes: int = Field(18, ge=1, description="aMaxSIFSFrameSize")
    min_be: int = Field(3, ge=0, le=8, description="macMinBE")
    max_be: int = Field(5, ge=3, le=8, description="macMaxBE")
    max_csma_backoffs: int = Field(4, ge=0, le=5, description="macMaxCSMABackoffs")

    @model_validator(mode="after")
    def _consistent(self) -> RadioCfg:
        if self.min_be > self.max_be:
            raise ValueError(f"min_be = {self.min_be} is larger than max_be = {self.max_be}")
        if self.path_loss_exponent_far is not None and self.breakpoint_m is None:
            raise ValueError("path_loss_exponent_far needs breakpoint_m")
        if self.breakpoint_m is not None and self.breakpoint_m <= self.min_distance_m:
            raise ValueError(f"breakpoint_m = {self.breakpoint_m} must exceed min_distance_m = {self.min_distance_m}")
        return self


# ---------------------------------------------------------------------------------------------- PHY curves

_K = np.arange(2, 17)
_BINOM = np.array([math.comb(16, int(k)) for k in _K], dtype=float)
_SIGN = (-1.0) ** _K


def ber_oqpsk(sinr: np.ndarray | float) -> np.ndarray:
    """Bit error rate of the 2.4 GHz O-QPSK DSSS PHY at a linear SINR (IEEE Std 802.15.4-2006, Annex E.4.1.8):
    BER = 8/15 * 1/16 * sum_{k=2..16} (-1)^k C(16, k) exp(20 SINR (1/k - 1)), clipped to [0, 0.5]."""
    s = np.asarray(sinr, dtype=float)[..., None]
    b = (8.0 / 15.0 / 16.0) * np.sum(_SIGN * _BINOM * np.exp(20.0 * s * (1.0 / _K - 1.0)), axis=-1)
    return np.clip(b, 0.0, 0.5)


def per_oqpsk(sinr: np.ndarray | float, n_bytes: int) -> np.ndarray:
    """Packet error rate of ``n_bytes`` at a constant SINR: 1 - (1 - BER)^(8 n)."""
    return -np.expm1(8 * n_bytes * np.log1p(-ber_oqpsk(sinr)))


def _snr_at_sensitivity_db(n_bytes: int, per: float = 0.01) -> float:
    """SNR (dB) at which a PPDU of ``n_bytes`` has the given PER (bisection; the curve is monotone)."""
    lo, hi = -10.0, 10.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if float(per_oqpsk(10 ** (mid / 10), n_bytes)) > per:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# The standard's sensitivity: PER < 1 % for a 20-octet PSDU; errors count over the whole PPDU here.
SNR_AT_SENSITIVITY_DB = _snr_at_sensitivity_db(6 + 20)


def airtime_ns(cfg: RadioCfg, psdu_len: int) -> int:
    """Time on air (ns) of a PPDU carrying ``psdu_len`` bytes."""
    return (cfg.phy_header_bytes + psdu_len) * cfg.byte_us * US


# ------------------------------------------------------------------------------------------ propagation


def path_loss_db(cfg: RadioCfg, d: np.ndarray) -> np.ndarray:
    """Mean path loss (dB) at distances ``d`` (m), single- or dual-slope log-distance model."""
    d = np.maximum(np.asarray(d, dtype=float), cfg.min_distance_m)
    n1 = cfg.path_loss_exponent
    pl = cfg.path_loss_d0_db + 10.0 * n1 * np.log10(d / cfg.d0_m)
    if cfg.breakpoint_m is not None:
        n2 = cfg.path_loss_exponent_far if cfg.path_loss_exponent_far is not None else n1
        far = d > cfg.breakpoint_m
        pl = np.where(far, pl + 10.0 * (n2 - n1) * np.log10(np.where(far, d, 1.0) / cfg.breakpoint_m), pl)
    return pl


def _exp_corr_wavenumbers(rng: np.random.Generator, m: int, corr_len: float) -> np.ndarray:
    """(m, 2) wave vectors whose spectral density gives a 2-D exponential correlation exp(-r / corr_len):
    radial CDF 1 - (1 + (k L)^2)^(-1/2), uniform direction."""
    u = rng.random(m)
    k = np.sqrt(1.0 / (1.0 - u) ** 2 - 1.0) / corr_len
    a = rng.uniform(0.0, 2.0 * np.pi, m)
    return np.stack([k * np.cos(a), k * np.sin(a)], axis=1)


class _Shadowing:
    """Per-link Gaussian shadowing field S_ij(x_lo, x_hi, t) = sigma sqrt(2/M) sum_m cos(k_m.x_lo + k'_m.x_hi
    + w_m t + phi_ijm): separable exponential correlation in each end's displacement and in time, zero mean,
    variance sigma^2, reciprocal because the lower robot index always takes the first argument."""

    def __init__(self, cfg: RadioCfg, n: int, seed: int) -> None:
        self.sigma = cfg.shadowing_sigma_db
        self.n = n
        m = cfg.shadowing_components
        rb = stream(seed, "radio", "shadowing", "basis")
        self.k_lo = _exp_corr_wavenumbers(rb, m, cfg.shadowing_decorrelation_m)
        self.k_hi = _exp_corr_wavenumbers(rb, m, cfg.shadowing_decorrelation_m)
        tau = cfg.shadowing_decorrelation_s
        self.omega = np.zeros(m) if tau is None else rb.standard_cauchy(m) / tau  # exp(-|dt|/tau) correlation
        n_pairs = n * (n - 1) // 2
        rp = stream(seed, "radio", "shadowing", "phase")
        self.phase = (rp.random((n_pairs, m)) * (2.0 * np.pi)).astype(np.float32)
        self.scale = self.sigma * math.sqrt(2.0 / m)

    def pair_index(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        lo, hi = np.minimum(i, j), np.maximum(i, j)
        return lo * self.n - lo * (lo + 1) // 2 + (hi - lo - 1)

    def links(self, pos: np.ndarray, i: np.ndarray, j: np.ndarray, t_s: float) -> np.ndarray:
        """Shadowing (dB) of links i[k]-j[k] (i != j) at time ``t_s``."""
        if self.sigma == 0.0 or len(i) == 0:
            return np.zeros(len(i))
        lo, hi = np.minimum(i, j), np.maximum(i, j)
        arg = pos[lo] @ self.k_lo.T + pos[hi] @ self.k_hi.T + self.omega * t_s
        arg += self.phase[self.pair_index(lo, hi)]
        return self.scale * np.cos(arg).sum(axis=1)


def fading_gain_db(cfg: RadioCfg, h: np.ndarray) -> np.ndarray:
    """Fast-fading power gains (dB, unit mean in linear power) from unit-power complex Gaussian diffuse
    components ``h``: Rician |mu + s h|^2 with mu^2 = K/(K+1), s^2 = 1/(K+1); Rayleigh |h|^2; none 0 dB."""
    if cfg.fading == "none":
        return np.zeros(h.shape)
    if cfg.fading == "rayleigh":
        g = np.abs(h) ** 2
    else:
        k = 10.0 ** (cfg.rician_k_db / 10.0)
        g = np.abs(math.sqrt(k / (k + 1.0)) + math.sqrt(1.0 / (k + 1.0)) * h) ** 2
    return 10.0 * np.log10(np.maximum(g, 1e-30))


def complex_normal(rng: np.random.Generator, size: int) -> np.ndarray:
    """Unit-power circular complex Gaussian samples."""
    z = rng.standard_normal((2, size))
    return (z[0] + 1j * z[1]) * math.sqrt(0.5)


# ----------------------------------------------------------------------------------------- the medium

_START, _CCA_END, _TX_START, _TX_END, _ACK_START, _ACK_END, _ACK_TIMEOUT = range(7)
_REQUIRED = ("handle", "dst", "psdu_len", "channel")


class _Job:
    """The frame a node's MAC is working on."""

    __slots__ = ("acked", "attempts", "be", "counted", "delivered", "frame", "nb", "retries", "src", "token",
                 "unicast_ack")

    def __init__(self, src: int, frame: dict) -> None:
        self.src = src
        self.frame = frame
        self.attempts = 0
        self.nb = 0
        self.be = 0
        self.token = 0
        self.acked = False
        self.counted = False
        self.delivered: set[int] = set()
        self.unicast_ack = bool(frame.get("ack", False)) and frame["dst"] != "bcast"
        self.retries = int(frame.get("mac_retries", 3))


class _Tx:
    """One PPDU on the air."""

    __slots__ = ("channel", "intended", "is_ack", "job", "lockers", "p_mw", "rssi", "src", "t0", "t1")

    def __init__(self, src: int, job: _Job, is_ack: bool, t0: int, t1: int, channel: int) -> None:
        self.src = src
        self.job = job
        self.is_ack = is_ack
        self.t0 = t0
        self.t1 = t1
        self.channel = channel
        self.p_mw = np.zeros(0)
        self.rssi = np.zeros(0)
        self.lockers: list[int] = []
        self.intended = np.zeros(0, dtype=np.int64)


def _new_robot_stats() -> dict[str, Any]:
    return {"tx": {"frames": 0, "attempts": 0, "ok": 0, "cca_fail": 0, "retries_exhausted": 0, "acks_sent": 0},
            "rx": {"decoded": 0, "intended": 0, "delivered": 0, **dict.fromkeys(LOSS_CAUSES, 0)},
            "rssi_hist": [0] * RSSI_HIST_BINS}


class RadioMedium:
    """The shared 2.4 GHz channel(s) of ``n_robots`` XBee modules."""

    def __init__(self, cfg: RadioCfg, n_robots: int, seed: int, geometry: Geometry) -> None:
        self.cfg = cfg
        self.n = n = n_robots
        self.seed = seed
        self.geometry = geometry
        self._shadow = _Shadowing(cfg, n, seed)
        self._rng_fading = stream(seed, "radio", "fading")
        n_pairs = n * (n - 1) // 2
        self._fad_h = complex_normal(self._rng_fading, n_pairs)  # diffuse gain per link (reciprocal)
        self._fad_t = np.zeros(n_pairs, dtype=np.int64)  # when each link's gain was last advanced
        self._fad_s = np.zeros(n_pairs)  # both ends' travel then
        self._travel = np.zeros(n)  # distance each robot moved, as seen by the medium
        self._last_pos: np.ndarray | None = None
        self._rng_decode = stream(seed, "radio", "decode")
        self.impairments = Impairments(seed, "radio")  # partitions and burst loss a fault puts on the channel
        self._rng_csma = [stream(seed, "radio", "csma", r) for r in range(n)]
        # node settings (channel -1: radio off)
        self._chan = np.full(n, -1, dtype=np.int64)
        self._pan = np.zeros(n, dtype=np.int64)
        self._a64 = np.zeros(n, dtype=np.uint64)
        self._a16 = np.zeros(n, dtype=np.int64)
        self._ptx = np.full(n, cfg.tx_power_dbm)
        self._sens = np.full(n, cfg.sensitivity_dbm)
        self._noise_mw = np.zeros(n)
        self._set_noise(np.arange(n))
        # MAC and radio state
        self._queue: list[deque[dict]] = [deque() for _ in range(n)]
        self._job: list[_Job | None] = [None] * n
        self._ifs_until = np.zeros(n, dtype=np.int64)
        self._tx_until = np.zeros(n, dtype=np.int64)
        self._lock: list[_Tx | None] = [None] * n
        self._air: list[_Tx] = []  # transmissions that may still overlap with something being decided
        self._heap: list[tuple[int, int, int, Any]] = []
        self._seq = 0
        self._now = 0  # everything before this has been processed
        self._out: list[tuple[int, int, dict]] = []
        self._pos: np.ndarray | None = None
        self._alive: np.ndarray | None = None
        self._walls: dict[int, np.ndarray] = {}
        self._stats = [_new_robot_stats() for _ in range(n)]

    # ------------------------------------------------------------------------------------ public API

    def set_node(self, r: int, node: dict | None) -> None:
        """Apply robot ``r``'s module settings (see the XBee module's ``node`` dict); None switches its radio
        off, which drops its queued frames without answers and aborts what it was receiving."""
        if node is None:
            self._chan[r] = -1
            self._queue[r].clear()
            if (job := self._job[r]) is not None:
                job.token += 1
                self._job[r] = None
            self._lock[r] = None
            return
        self._chan[r] = int(node["channel"])
        self._pan[r] = int(node.get("pan_id", 0))
        self._a64[r] = np.uint64(int(node.get("addr64", 0)) & 0xFFFF_FFFF_FFFF_FFFF)
        self._a16[r] = int(node.get("addr16", 0xFFFE))
        self._ptx[r] = float(node.get("tx_power_dbm", self.cfg.tx_power_dbm))
        self._sens[r] = float(node.get("sensitivity_dbm", self.cfg.sensitivity_dbm))
        self._set_noise(np.array([r]))

    def submit(self, r: int, t_ns: int, frame: dict) -> None:
        """Queue ``frame`` from robot ``r``'s module; its MAC may start on it at ``t_ns`` (or when the frames
        queued before it are done). Frames from a robot whose radio is off are ignored."""
        missing = [k for k in _REQUIRED if k not in frame]
        if missing:
            raise ValueError(f"air frame from robot {r} lacks {', '.join(missing)}")
        if not 1 <= int(frame["psdu_len"]) <= 127:
            raise ValueError(f"air frame from robot {r}: psdu_len {frame['psdu_len']} outside 1..127 "
                             "(aMaxPHYPacketSize)")
        if frame["dst"] not in ("bcast", "64", "16"):
            raise ValueError(f"air frame from robot {r}: dst {frame['dst']!r} is not 'bcast', '64' or '16'")
        if self._chan[r] < 0:
            return
        self._stats[r]["tx"]["frames"] += 1
        self._queue[r].append(frame)
        if self._job[r] is None and len(self._queue[r]) == 1:
            self._push(max(int(t_ns), self._now, int(self._ifs_until[r])), _START, r)

    def advance(self, horizon_ns: int) -> list[tuple[int, int, dict]]:
        """Run the channel up to ``horizon_ns`` (exclusive); return the events (t_ns, robot, event) in time order."""
        heap = self._heap
        if not heap or heap[0][0] >= horizon_ns:
            self._now = max(self._now, horizon_ns)
            return []
        self._pos = self._alive = None
        self._walls = {}
        self._out = []
        while heap and heap[0][0] < horizon_ns:
            t, _, kind, arg = heapq.heappop(heap)
            self._now = t
            self._dispatch(t, kind, arg)
        self._now = max(self._now, horizon_ns)
        out, self._out = self._out, []
        return out

    def next_event_ns(self) -> int | None:
        """Time of the next internal event, or None when nothing is queued or on the air."""
        return self._heap[0][0] if self._heap else None

    def mean_rssi(self) -> np.ndarray:
        """(n, n) mean received power (dBm) from row robot to column robot now: path loss, walls and shadowing,
        no fast fading; NaN on the diagonal. Changes nothing: draws no random numbers, moves no state."""
        pos = np.asarray(self.geometry.positions(), dtype=float)[:, :2]
        every = np.arange(self.n)
        out = np.full((self.n, self.n), np.nan)
        for i in range(self.n):
            walls = np.asarray(self.geometry.walls(i, every), dtype=float)
            row = self._mean_dbm_from(i, self._now, pos, walls)
            row[i] = np.nan
            out[i] = row
        return out

    def stats(self) -> dict[str, Any]:
        """Counters per robot and in total (see docs/radio.md); msgpack-friendly."""
        robots = [{"tx": dict(s["tx"]), "rx": dict(s["rx"]), "rssi_hist": list(s["rssi_hist"])} for s in self._stats]
        totals: dict[str, Any] = {
            "tx": {k: sum(s["tx"][k] for s in robots) for k in robots[0]["tx"]} if robots else {},
            "rx": {k: sum(s["rx"][k] for s in robots) for k in robots[0]["rx"]} if robots else {},
            "rssi_hist": [sum(s["rssi_hist"][b] for s in robots) for b in range(RSSI_HIST_BINS)],
        }
        return {"robots": robots, "totals": totals, "rssi_hist_lo_dbm": RSSI_HIST_LO_DBM,
                "rssi_hist_bin_db": RSSI_HIST_BIN_DB}

    # ------------------------------------------------------------------------------------ internals

    def _set_noise(self, rs: np.ndarray) -> None:
        if self.cfg.noise_floor_dbm is not None:
            self._noise_mw[rs] = 10.0 ** (self.cfg.noise_floor_dbm / 10.0)
        else:
            self._noise_mw[rs] = 10.0 ** ((self._sens[rs] - SNR_AT_SENSITIVITY_DB) / 10.0)

    def _push(self, t: int, kind: int, arg: Any) -> None:
        self._seq += 1
        heapq.heappush(self._heap, (t, self._seq, kind, arg))

    def _positions(self) -> np.ndarray:
        if self._pos is None:
            self._pos = np.asarray(self.geometry.positions(), dtype=float)[:, :2].copy()
            if self._last_pos is not None:
                self._travel += np.hypot(*(self._pos - self._last_pos).T)
            self._last_pos = self._pos
        return self._pos

    def _fading_db_from(self, src: int, t: int) -> np.ndarray:
        """Fast-fading gains (dB) of the links from ``src`` to every robot at ``t``: each link's complex gain is
        a Gauss-Markov process, correlation exp(-dt / T_c - travel / L) since the link was last used."""
        others = np.arange(self.n)
        others = others[others != src]
        w = complex_normal(self._rng_fading, self.n)[: len(others)]  # fixed draw count per transmission
        out = np.zeros(self.n)
        if self.cfg.fading == "none" or len(others) == 0:
            return out
        p = self._shadow.pair_index(np.full(len(others), src), others)
        travel = self._travel[src] + self._travel[others]
        decay = (travel - self._fad_s[p]) / self.cfg.fading_decorrelation_m
        if self.cfg.fading_coherence_s is not None:
            decay += (t - self._fad_t[p]) * 1e-9 / self.cfg.fading_coherence_s
        rho = np.exp(-decay)
        h = rho * self._fad_h[p] + np.sqrt(1.0 - rho * rho) * w
        self._fad_h[p] = h
        self._fad_t[p] = t
        self._fad_s[p] = travel
        out[others] = fading_gain_db(self.cfg, h)
        return out

    def _alive_mask(self) -> np.ndarray:
        if self._alive is None:
            self._alive = np.asarray(self.geometry.alive(), dtype=bool)
        return self._alive

    def _walls_from(self, src: int) -> np.ndarray:
        w = self._walls.get(src)
        if w is None:
            w = np.asarray(self.geometry.walls(src, np.arange(self.n)), dtype=float)
            self._walls[src] = w
        return w

    def _mean_dbm_from(self, src: int, t: int, pos: np.ndarray, walls: np.ndarray) -> np.ndarray:
        """Mean power (dBm) at every robot from ``src`` (its own entry is meaningless)."""
        d = np.hypot(*(pos - pos[src]).T)
        dbm = self._ptx[src] - path_loss_db(self.cfg, d) - self.cfg.wall_loss_db * walls
        others = np.arange(self.n)
        others = others[others != src]
        dbm[others] += self._shadow.links(pos, np.full(len(others), src), others, t * 1e-9)
        return dbm

    def _intended(self, src: int, frame: dict) -> np.ndarray:
        """Robots the frame is addressed to (on its channel and PAN)."""
        on = (self._chan == int(frame["channel"])) & (self._pan == int(frame.get("pan_id", 0)))
        on[src] = False
        dst = frame["dst"]
        if dst == "64":
            on &= self._a64 == np.uint64(int(frame.get("dst_addr", 0)) & 0xFFFF_FFFF_FFFF_FFFF)
        elif dst == "16":
            on &= self._a16 == int(frame.get("dst_addr", 0))
        return np.flatnonzero(on)

    def _emit(self, t: int, r: int, ev: dict) -> None:
        self._out.append((t, r, ev))

    def _done(self, t: int, job: _Job, status: str) -> None:
        r = job.src
        self._emit(t, r, {"ev": "done", "t_ns": t, "handle": job.frame["handle"], "status": status,
                          "attempts": job.attempts})
        st = self._stats[r]["tx"]
        st[{"ok": "ok", "no_ack": "retries_exhausted", "cca_fail": "cca_fail"}[status]] += 1
        self._finish(t, job)

    def _finish(self, t: int, job: _Job) -> None:
        r = job.src
        job.token += 1
        if self._job[r] is job:
            self._job[r] = None
            big = int(job.frame["psdu_len"]) > self.cfg.max_sifs_frame_bytes
            self._ifs_until[r] = t + (self.cfg.lifs_us if big else self.cfg.sifs_us) * US
            if self._queue[r]:
                self._push(int(self._ifs_until[r]), _START, r)

    def _dispatch(self, t: int, kind: int, arg: Any) -> None:
        if kind == _START:
            self._start(t, arg)
        elif kind == _CCA_END:
            self._cca_end(t, *arg)
        elif kind == _TX_START:
            self._tx_start(t, *arg)
        elif kind in (_TX_END, _ACK_END):
            self._tx_end(t, arg)
        elif kind == _ACK_START:
            self._ack_start(t, *arg)
        elif kind == _ACK_TIMEOUT:
            self._ack_timeout(t, *arg)

    def _start(self, t: int, r: int) -> None:
        if self._job[r] is not None or not self._queue[r] or self._chan[r] < 0:
            return
        job = _Job(r, self._queue[r].popleft())
        self._job[r] = job
        self._csma_begin(t, job)

    def _csma_begin(self, t: int, job: _Job) -> None:
        job.nb = 0
        job.be = self.cfg.min_be
        self._backoff(t, job)

    def _backoff(self, t: int, job: _Job) -> None:
        periods = int(self._rng_csma[job.src].integers(0, 1 << job.be))
        t_cca_end = t + periods * self.cfg.unit_backoff_us * US + self.cfg.cca_us * US
        job.token += 1
        self._push(t_cca_end, _CCA_END, (job, job.token))

    def _cca_end(self, t: int, job: _Job, token: int) -> None:
        if token != job.token or self._job[job.src] is not job:
            return
        r = job.src
        busy = self.cfg.cca_carrier_sense and self._lock[r] is not None
        if not busy:
            t_from = t - self.cfg.cca_us * US
            e = self._noise_mw[r]
            ch = int(job.frame["channel"])
            for tx in self._air:
                if tx.channel == ch and tx.src != r and tx.t0 < t and tx.t1 > t_from:
                    e += tx.p_mw[r]
            busy = 10.0 * math.log10(e) >= self.cfg.cca_threshold_dbm or self._tx_until[r] > t
        if not busy:
            job.token += 1
            self._push(t + self.cfg.turnaround_us * US, _TX_START, (job, job.token))
            return
        job.nb += 1
        job.be = min(job.be + 1, self.cfg.max_be)
        if job.nb > self.cfg.max_csma_backoffs:
            self._done(t, job, "cca_fail")
        else:
            self._backoff(t, job)

    def _radio_ok(self, r: int) -> bool:
        return self._chan[r] >= 0 and bool(self._alive_mask()[r])

    def _transmit(self, t: int, src: int, job: _Job, is_ack: bool) -> _Tx:
        """Put a PPDU on the air from ``src`` at ``t``; receivers lock onto it."""
        cfg = self.cfg
        psdu = cfg.ack_psdu_len if is_ack else int(job.frame["psdu_len"])
        ch = int(job.frame["channel"])
        tx = _Tx(src, job, is_ack, t, t + airtime_ns(cfg, psdu), ch)
        rssi = self._mean_dbm_from(src, t, self._positions(), self._walls_from(src)) + self._fading_db_from(src, t)
        rssi[src] = -np.inf
        tx.rssi = rssi
        tx.p_mw = 10.0 ** (rssi / 10.0)
        if (lk := self._lock[src]) is not None:  # half duplex: transmitting aborts a reception
            self._lock[src] = None
            if src in lk.lockers:
                lk.lockers.remove(src)
                if not lk.is_ack and src in lk.intended:
                    self._stats[src]["rx"]["collision"] += 1
        self._tx_until[src] = tx.t1
        alive = self._alive_mask()
        can = (self._chan == ch) & alive & (self._tx_until <= t)
        can[src] = False
        free = np.fromiter((lk is None for lk in self._lock), dtype=bool, count=self.n)
        audible = rssi >= self._sens
        lockers = np.flatnonzero(can & free & audible)
        for r in lockers:
            self._lock[int(r)] = tx
        tx.lockers = [int(r) for r in lockers]
        if not is_ack:
            tx.intended = self._intended(src, job.frame)
            first = not job.counted
            job.counted = True
            for r in tx.intended:
                r = int(r)
                st = self._stats[r]["rx"]
                if first:
                    st["intended"] += 1
                if not (alive[r] and self._chan[r] == ch):
                    continue
                if not audible[r]:
                    st["below_sensitivity"] += 1
                elif not can[r] or not free[r]:
                    st["collision"] += 1
        self._air.append(tx)
        self._push(tx.t1, _ACK_END if is_ack else _TX_END, tx)
        return tx

    def _tx_start(self, t: int, job: _Job, token: int) -> None:
        if token != job.token or self._job[job.src] is not job:
            return
        r = job.src
        if not self._radio_ok(r):
            self._finish(t, job)  # the module is off or its robot dead: nobody waits for an answer
            return
        if self._tx_until[r] > t:  # still sending an ACK: start right after it
            self._push(int(self._tx_until[r]), _TX_START, (job, token))
            return
        job.attempts += 1
        self._stats[r]["tx"]["attempts"] += 1
        self._transmit(t, r, job, is_ack=False)

    def _decode(self, tx: _Tx) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For the receivers locked onto ``tx`` (still locked): (receivers, decoded, interfered)."""
        rs = np.array([r for r in tx.lockers if self._lock[r] is tx], dtype=np.int64)
        if len(rs) == 0:
            return rs, np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
        others = [o for o in self._air if o is not tx and o.channel == tx.channel and o.t0 < tx.t1 and o.t1 > tx.t0]
        cuts = sorted({tx.t0, tx.t1, *(max(o.t0, tx.t0) for o in others), *(min(o.t1, tx.t1) for o in others)})
        sig = tx.p_mw[rs]
        noise = self._noise_mw[rs]
        log_ok = np.zeros(len(rs))
        interfered = np.zeros(len(rs), dtype=bool)
        for a, b in itertools.pairwise(cuts):
            if b <= a:
                continue
            interf = np.zeros(len(rs))
            for o in others:
                if o.t0 < b and o.t1 > a:
                    interf += o.p_mw[rs]
            interfered |= interf > 0.1 * noise
            bits = (b - a) / BIT_NS
            log_ok += bits * np.log1p(-ber_oqpsk(sig / (noise + interf)))
        u = self._rng_decode.random(len(rs))
        return rs, u < np.exp(log_ok), interfered

    def _tx_end(self, t: int, tx: _Tx) -> None:
        rs, ok, interfered = self._decode(tx)
        if len(rs) and (self.impairments.partitions or self.impairments.bursts):  # a fault's: lost, as corrupt
            ok = ok & ~self.impairments.lost(tx.t0, tx.src, rs)
        for r in rs:
            if self._lock[int(r)] is tx:
                self._lock[int(r)] = None
        job = tx.job
        if tx.is_ack:
            sender = job.src
            hit = rs == sender
            if (hit & ok).any() and self._job[sender] is job and not job.acked:
                job.acked = True
                self._done(t, job, "ok")
        else:
            intended = set(tx.intended.tolist())
            for r, good, itf in zip(rs.tolist(), ok.tolist(), interfered.tolist(), strict=True):
                st = self._stats[r]
                if good:
                    st["rx"]["decoded"] += 1
                    rssi = round(float(tx.rssi[r]))
                    b = min(max((rssi - RSSI_HIST_LO_DBM) // RSSI_HIST_BIN_DB, 0), RSSI_HIST_BINS - 1)
                    st["rssi_hist"][b] += 1
                    self._emit(t, r, {"ev": "rx", "t_ns": t, "frame": job.frame, "rssi_dbm": rssi})
                    if r in intended:
                        if r not in job.delivered:
                            job.delivered.add(r)
                            st["rx"]["delivered"] += 1
                        if job.unicast_ack:
                            self._push(t + self.cfg.turnaround_us * US, _ACK_START, (r, job))
                elif r in intended:
                    st["rx"]["collision" if itf else "corrupt"] += 1
            if self._job[job.src] is job:
                if job.unicast_ack:
                    job.token += 1
                    self._push(t + self.cfg.ack_wait_us * US, _ACK_TIMEOUT, (job, job.token))
                else:
                    self._done(t, job, "ok")
        self._prune(t)

    def _ack_start(self, t: int, r: int, job: _Job) -> None:
        if not self._radio_ok(r) or self._tx_until[r] > t:
            return
        self._stats[r]["tx"]["acks_sent"] += 1
        self._transmit(t, r, job, is_ack=True)

    def _ack_timeout(self, t: int, job: _Job, token: int) -> None:
        if token != job.token or self._job[job.src] is not job or job.acked:
            return
        if job.attempts <= job.retries:
            self._csma_begin(t, job)
        else:
            self._done(t, job, "no_ack")

    def _prune(self, t: int) -> None:
        """Forget transmissions that can no longer overlap with a reception or CCA still to be decided."""
        horizon = t - self.cfg.cca_us * US
        for tx in self._air:
            if tx.t1 > t:
                horizon = min(horizon, tx.t0)
        self._air = [tx for tx in self._air if tx.t1 > horizon]


CONNECTIVITY_EVERY_NS = 1_000_000_000  # how often the radio graph's algebraic connectivity is sampled


class RadioChannel(Medium):
    """The XBees' 2.4 GHz channel in a session: the modules' air frames and settings to the ``RadioMedium``, its
    receptions and transmit results to the modules and the recording, and the radio graph's connectivity."""

    name = "radio"
    order = 30
    routes = {("air", "xbee"): "air", ("node", "xbee"): "node", ("rssi_pwm", "xbee"): "rssi_pwm"}  # noqa: RUF012

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        return any(rp.sim_xbee for rp in hub.plan.robots)

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        robots = hub.plan.robots
        self.medium = RadioMedium(hub.cfg.radio, hub.n, hub.cfg.session.seed, hub.geometry)
        # the swarm's radio network, whose connectivity is sampled: the robots' XBees (not a gateway's)
        self.swarm_radios = [r for r, rp in enumerate(robots) if rp.sim_xbee and rp.gateway is None]
        self.addr_robot: dict[tuple[str, int], int] = {}  # ("64" | "16", address) -> robot, from the modules
        self.tx_dst: dict[tuple[int, int], tuple] = {}  # (robot, frame handle) -> (addressed robot, MAC seq)
        self.node_sens: dict[int, float] = {}  # each module's receiver sensitivity, as it reported it
        self.node_net: dict[int, tuple[int, int] | None] = {}  # each module's (channel, PAN id); None: unplugged
        self.connectivity: list[tuple[float, float]] = []  # (t s, lambda2)
        self.links: dict[tuple[int, int], tuple[int, float]] = {}  # (robot, robot) -> last frame decoded: t, RSSI
        self.pieces: list[int] = []  # how many pieces the live swarm's radio graph is in, by sample
        for r in range(hub.n):  # the LLC samples its XBee's RSSI PWM output on a pin
            if "xbee" in hub.roles[r]:
                hub.pin_inputs[r]["rssi_pwm"] = 0.0
        for f in hub.cfg.faults:  # the config's faults of the air
            if f.kind in AIR_FAULTS and f.medium == "radio":
                self._air_fault(f)

    def air(self, e: str, r: int, t: int, item: list) -> None:
        if not valid_air_frame(item[1]):
            raise ValueError
        f = item[1]
        self.medium.submit(r, t + self.hub.q_ns, f)
        self.hub.counts["air_frames"] += 1
        dst = f.get("dst")
        self.tx_dst[(r, f["handle"])] = (self.addr_robot.get((dst, f["dst_addr"])) if dst != "bcast" else None,
                                         f["seq"])

    def node(self, e: str, r: int, t: int, item: list) -> None:
        node = item[1]
        if not _valid_node(node):
            raise ValueError
        self.medium.set_node(r, node)
        self.addr_robot[("64", int(node["addr64"]))] = r
        self.addr_robot[("16", int(node["addr16"]))] = r
        self.node_sens[r] = float(node["sensitivity_dbm"])
        self.node_net[r] = (node["channel"], node["pan_id"])

    def inject_fault(self, f: Any, t: int) -> bool:
        """A fault of the air on the 2.4 GHz channel (a partition, burst loss), injected while the session runs."""
        if f.kind not in AIR_FAULTS or f.medium != "radio":
            return False
        self._air_fault(f)
        return True

    def _air_fault(self, f: Any) -> None:
        """Put fault ``f`` on the channel from ``f.at_s`` for ``f.duration_s``; its start and end become events."""
        t0 = round(f.at_s * 1e9)
        t1 = None if f.duration_s is None else t0 + round(f.duration_s * 1e9)
        imp = self.medium.impairments
        if f.kind == "partition":
            imp.partition(t0, t1, f.groups)
            what = f"the robots split into {f.groups}"
        else:
            imp.burst_loss(t0, t1, f.p_gb, f.p_bg, f.loss_good, f.loss_bad, f.robots)
            what = (f"Gilbert-Elliott loss on {'every link' if f.robots is None else f'the links of robots {f.robots}'}"
                    f" (p_gb {f.p_gb}, p_bg {f.p_bg}, loss {f.loss_good}/{f.loss_bad})")
        q = self.hub.q_ns
        self.hub.deliver_at(-(-t0 // q) * q, self._fault_event, f.kind, f"{what} on the radio channel")
        if t1 is not None:
            self.hub.deliver_at(-(-t1 // q) * q, self._fault_event, f"{f.kind}_end", f"{f.kind} over")

    def _fault_event(self, t: int, kind: str, detail: str) -> None:
        self.hub.event(t, {"kind": kind, "detail": detail})

    def unplug(self, r: int, device: str) -> None:
        """Robot ``r``'s XBee was pulled out: its radio is off (its queued frames dropped, what it was receiving
        aborted), it hears and acknowledges nothing, and it has no link in the radio graph."""
        if device == "xbee":
            self.medium.set_node(r, None)
            self.node_net[r] = None

    def rssi_pwm(self, e: str, r: int, t: int, item: list) -> None:
        self.hub.pin_inputs[r]["rssi_pwm"] = min(1.0, max(0.0, float(item[1])))

    def advance(self, t: int) -> None:
        """Resolve the air up to the earliest time a new frame could start (t+2q: this quantum's submissions start
        at t+q or later), and sample the radio graph's connectivity."""
        hub = self.hub
        q = hub.q_ns
        for t_ev, r, ev in self.medium.advance(t + 2 * q):
            self._event(t_ev, r, ev)
        if t % CONNECTIVITY_EVERY_NS < q and all(r in self.node_net for r in self.swarm_radios if r not in hub.dead):
            lam = self.algebraic_connectivity(t)
            self.connectivity.append((t / 1e9, lam))
            live, adj = self.radio_graph(t)
            self.pieces.append(components(adj))
            for lf in hub.loop_functions:
                lf.on_radio_sample(t, live, adj)
            hub.rec.write(t, "/radio/connectivity", "swarm_sitl.Connectivity", {"lambda2": round(lam, 6)})

    def radio_graph(self, t: int) -> tuple[list[int], np.ndarray]:
        """The live robots' radio graph at ``t``: a link where the mean link budget (no fast fading) clears the
        receiver's sensitivity both ways, on the same channel and PAN, and no partition fault cuts it."""
        live = [r for r in self.swarm_radios if r not in self.hub.dead]
        rssi = self.medium.mean_rssi()[np.ix_(live, live)]  # row: sender, column: receiver
        sens = np.array([self.node_sens.get(r, -94.0) for r in live])
        net = [self.node_net.get(r) for r in live]  # modules hear only their own channel and PAN
        same = np.array([[a is not None and a == b for b in net] for a in net]).reshape(len(live), len(live))
        up = rssi >= sens[None, :]
        adj = (up & up.T & same).astype(float)
        np.fill_diagonal(adj, 0.0)
        for p in self.medium.impairments.partitions:  # a partition fault cuts the links across its groups
            if p.active(t):
                grp = np.array([p.group_of(r) for r in live])
                adj[(grp[:, None] >= 0) & (grp[None, :] >= 0) & (grp[:, None] != grp[None, :])] = 0.0
        return live, adj

    def algebraic_connectivity(self, t: int) -> float:
        """lambda2 of the radio graph at ``t``: above zero exactly when the radio network is connected."""
        live, adj = self.radio_graph(t)
        if len(live) < 2:
            return 0.0
        lap = np.diag(adj.sum(axis=1)) - adj
        return float(max(0.0, np.sort(np.linalg.eigvalsh(lap))[1]))

    def _event(self, t_ev: int, r: int, ev: dict) -> None:
        """A reception or a transmit result from the medium: to the module at the next quantum boundary, and
        to the recording (with the ground-truth distance, for surveys)."""
        hub = self.hub
        pos = hub.world.pos
        t_del = -(-t_ev // hub.q_ns) * hub.q_ns
        if "xbee" in hub.roles[r]:
            hub.deliver_at(t_del, hub.to_inbox, entity(r, "xbee"), ["air", ev])
        if ev.get("ev") == "rx":
            f = ev["frame"]
            src = self.addr_robot.get(("64", f.get("src64")), -1)
            d = float(np.hypot(*(pos[r] - pos[src]))) if 0 <= src < hub.n else None
            if d is not None and ev.get("rssi_dbm") is not None:
                self.links[(min(r, src), max(r, src))] = (t_ev, float(ev["rssi_dbm"]))
            hub.deliver_at(t_del, hub.record, "/radio/rx", "swarm_sitl.RadioRx", {
                "t_ns": t_ev, "dst": r, "src": src, "handle": f.get("handle"), "rssi_dbm": ev.get("rssi_dbm"),
                "len": len(f.get("payload", b"")), "distance_m": None if d is None else round(d, 3)})
        elif ev.get("ev") == "done":
            dst, seq = self.tx_dst.pop((r, ev.get("handle")), (None, None))
            d = walls = None
            if dst is not None and dst != r:
                d = round(float(np.hypot(*(pos[r] - pos[dst]))), 3)
                walls = int(hub.world.walls(r, np.array([dst]))[0])
            hub.deliver_at(t_del, hub.record, "/radio/tx", "swarm_sitl.RadioTx", {
                "t_ns": t_ev, "src": r, "handle": ev.get("handle"), "status": ev.get("status"),
                "attempts": ev.get("attempts"), "dst": dst, "seq": seq, "distance_m": d, "walls": walls})

    LINK_FRESH_NS = 2_000_000_000  # a link is drawn while a frame crossed it in the last 2 s

    def scene(self, t: int) -> list[dict[str, Any]]:
        """The radio links as one line list: every pair of live robots a frame crossed in the last ``LINK_FRESH_NS``,
        coloured by the RSSI of the last one (red weak, green strong)."""
        w = self.hub.world
        points: list[tuple[float, float, float]] = []
        colours: list[dict[str, float]] = []
        for (a, b), (t_rx, rssi) in sorted(self.links.items()):
            if t - t_rx > self.LINK_FRESH_NS or not (w.alive[a] and w.alive[b]):
                continue
            c = fx.rssi_colour(rssi)
            points += [(float(w.pos[a, 0]), float(w.pos[a, 1]), 0.15), (float(w.pos[b, 0]), float(w.pos[b, 1]), 0.15)]
            colours += [c, c]
        if not points:
            return []
        return [fx.entity(t, "radio/links", lines=[fx.line(points, fx.color(0.5, 0.5, 0.5), fx.LINE_LIST, 0.015,
                                                           colours)])]

    def radio_report(self, out: dict[str, Any]) -> None:
        """The session's radio figures: per robot from the medium and the modules, and the network's connectivity
        over time."""
        hub = self.hub
        stats = self.medium.stats()
        lam = [v for _, v in self.connectivity]
        share = round(sum(v > 1e-9 for v in lam) / len(lam), 4) if lam else None
        out["connectivity"] = {
            "samples": len(lam), "connected_share": share,
            "lambda2_min": round(min(lam), 4) if lam else None,
            "lambda2_median": round(statistics.median(lam), 4) if lam else None,
            # a partition event: the graph falls into more pieces than at the previous sample
            "partition_events": splits(self.pieces), "pieces_max": max(self.pieces, default=0)}
        for lf in hub.loop_functions:
            lf.radio_report(out["connectivity"])
        out["totals"] = stats.get("totals", {})
        if self.medium.impairments.partitions or self.medium.impairments.bursts:
            out["impairments"] = self.medium.impairments.report()
        out["rssi_hist_bins_dbm"] = [stats.get("rssi_hist_lo_dbm"), stats.get("rssi_hist_bin_db")]
        for r in range(hub.n):
            if "xbee" in hub.roles[r]:
                out["per_robot"].setdefault(r, {})["radio"] = stats["robots"][r]
                out["per_robot"][r]["xbee_module"] = hub.module_stats.get(entity(r, "xbee"))


def splits(pieces: list[int]) -> int:
    """Partition events in a series of component counts: the times it rose (a piece broke off)."""
    return sum(max(0, b - a) for a, b in itertools.pairwise(pieces) if a > 0)


def _valid_node(node: Any) -> bool:
    """A module's radio settings, as the medium uses them."""
    if not isinstance(node, dict):
        return False
    ints = {"channel": (11, 26), "pan_id": (0, (1 << 64) - 1), "addr64": (0, (1 << 64) - 1), "addr16": (0, 0xFFFF),
            "series": (1, 2)}
    nums = {"tx_power_dbm": (-40.0, 30.0), "sensitivity_dbm": (-130.0, -40.0)}
    return (all(type(node.get(k)) is int and lo <= node[k] <= hi for k, (lo, hi) in ints.items())
            and all(isinstance(node.get(k), int | float) and lo <= node[k] <= hi for k, (lo, hi) in nums.items()))
