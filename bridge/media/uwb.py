"""The UWB ranging medium: what one DS-TWR exchange between two DW1000 modules measures, and when.

``UwbMedium.exchange(t_ns, i, j)`` is called by the world for every ``{"op": "range"}`` request module ``i``
makes in its TDMA turn (sort requests by ``t_ns`` then robot before calling; TDMA keeps exchanges apart, so
there are no collisions to model). It returns the result events for the initiator (after the report, the
``frames_per_exchange``-th frame) and, when the exchange succeeded, for the responder (after the final, the
third frame: in DS-TWR the responder computes the range). Event dicts::

    {"ev": "range", "peer": int, "ok": bool, "range_m": float, "rx_dbm": float, "fp_dbm": float, "t_ns": int,
     "responder": bool, "true_m": float, "nlos": bool, "walls": int, "cause": "ok"|"dropout"|"out_of_range"|
     "no_response"|"partitioned"|"burst_loss"|"sensor_dead"}

(``range_m``, ``rx_dbm`` and ``fp_dbm`` are 0.0 when ``ok`` is false; ``true_m``, ``nlos``, ``walls`` and
``cause`` are ground truth for statistics and recording, not for the module.) The last three causes are injected
faults' (``faults``, ``bridge.media.uwb_faults``): a partition or burst loss took one of the exchange's frames, or a
module's ranging is dead; a fault takes only an exchange that would otherwise have got through, and a stuck, noisy
or biased module changes the ranges reported (``range_m``; ``true_m`` stays the truth).

Noise model (defaults and sources in ``UwbCfg``; docs/uwb.md has the derivations):

- measured = true distance + link bias + LOS noise N(0, ``sigma_los_m``) when no wall is crossed; with ``w``
  walls, + ``w * nlos_bias_m`` + Exp(``nlos_exp_scale_m``) + N(0, ``nlos_sigma_m``) instead of the LOS noise:
  the Gaussian-plus-exponential NLOS error of TOA ranging (positive bias, heavy tail).
- link bias: Ornstein-Uhlenbeck, stationary std ``bias_sigma_m``, correlation time ``bias_tau_s``,
  reciprocal (one per unordered pair): residual antenna-delay and temperature drift (Decawave APS011/APS014).
- received power: ``rx_1m_dbm - 10 n log10(d) - w * wall_loss_db`` + N(0, ``rx_sigma_db``); first-path power
  below it by ``fp_gap_los_db + w * fp_gap_per_wall_db`` + N(0, ``fp_gap_sigma_db``), so the APS006 rule
  (RX - FP > 10 dB: NLOS) works most of the time but not always.
- dropouts: probability ``1 - (1 - dropout_los) (1 - dropout_per_wall)^w (1 - (d / max_range_m)^k)``; nothing
  at all beyond ``max_range_m`` or to a dead robot.

Each link draws from its own stream ``rng.stream(seed, "uwb", min(i, j), max(i, j))``, a fixed number of
draws per exchange, so nothing else shifts another link's noise. filterpy's noise helpers
(``Q_discrete_white_noise`` and co.) build filter covariances, not noise sequences, so the exact OU
discretisation is written out here; the filter that consumes these ranges (swarm_logic.drivers.ranging) uses them.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bridge.core.entities import entity, uwb_addr16
from bridge.core.medium import Medium
from bridge.core.rng import stream
from bridge.core.stats import LogHistogram, Moments
from bridge.media.radio import Geometry
from bridge.media.uwb_faults import UwbFaultCarrier, UwbFaults
from firmware_sim.modules.uwb import tdma_budget

if TYPE_CHECKING:
    from bridge.core.hub import Hub


class UwbCfg(BaseModel):
    """UWB ranging: TDMA budget, host UART and the DW1000 error model (mounted as ``[uwb]``)."""

    model_config = ConfigDict(extra="forbid", frozen=False)

    # TDMA budget and module
    frames_per_s: int = Field(512, ge=1, le=100_000, description=(
        "UWB frames per second shared by the whole swarm (one collision domain); Agrawal, Zebro swarm, App. B.2: "
        "16 robots x 32/s or 32 x 16/s"))
    frames_per_exchange: int = Field(4, ge=4, le=16, description=(
        "frames one ranging exchange costs: DS-TWR poll, response, final plus the report (Decawave APS013)"))
    update_rate_hz: float = Field(1.0, gt=0, le=100, description=(
        "target ranging rate per pair (Agrawal, Zebro swarm, App. B.2: 1 Hz update); the budget may give less"))
    max_range_m: float = Field(60.0, gt=0, le=1000, description=(
        "no exchange succeeds beyond this distance (Agrawal, Zebro swarm, App. B.2: 1-60 m)"))
    uart_baud: int = Field(115200, ge=1200, description="module host UART (DWM1001 Firmware API Guide: 115200 8N1)")
    uart_gap_ns: int = Field(762_940, ge=1, description=(
        "quiet time that ends a TLV request: 25 ticks of 32768 Hz (DWM1001 Firmware API Guide, UART TLV mode)"))
    los_fp_gap_db: float = Field(6.0, description=(
        "RX - first-path power below which the channel is likely LOS (Decawave APS006 Part 2)"))
    nlos_fp_gap_db: float = Field(10.0, description=(
        "RX - first-path power above which the channel is likely NLOS (Decawave APS006 Part 2)"))
    # range errors
    sigma_los_m: float = Field(0.10, ge=0, description=(
        "LOS range noise std (DW1000 datasheet: 10 cm location precision; Agrawal, Zebro swarm, 5.1)"))
    bias_sigma_m: float = Field(0.05, ge=0, description=(
        "stationary std of the per-link bias after antenna-delay calibration (Decawave APS014/APS011; "
        "uncalibrated modules show 10-50 cm)"))
    bias_tau_s: float = Field(60.0, gt=0, description="correlation time of the per-link bias drift (assumption)")
    nlos_bias_m: float = Field(0.25, ge=0, description="mean positive NLOS bias per wall crossed (assumption, "
                               "TOA NLOS error model: Gaussian plus exponential)")
    nlos_exp_scale_m: float = Field(0.35, ge=0, description=(
        "scale of the exponential NLOS tail (0.2-0.5 m in the TOA ranging-error literature)"))
    nlos_sigma_m: float = Field(0.20, ge=0, description="Gaussian part of the NLOS error (assumption)")
    # dropouts
    dropout_los: float = Field(0.01, ge=0, le=1, description="exchange failure probability in LOS (assumption)")
    dropout_per_wall: float = Field(0.15, ge=0, le=1, description="extra failure probability per wall (assumption)")
    dropout_range_exp: float = Field(6.0, gt=0, description=(
        "k in the (d / max_range)^k failure term: failures grow near the maximum range"))
    # signal levels reported by the DW1000 diagnostics
    rx_1m_dbm: float = Field(-63.0, description=(
        "RX level at 1 m: DW1000 TX -41.3 dBm/MHz x 499.2 MHz = -14.3 dBm, minus 48.7 dB free-space loss at "
        "6.5 GHz (channel 5)"))
    path_loss_exp: float = Field(2.0, gt=0, description="path-loss exponent (free space, LOS)")
    wall_loss_db: float = Field(6.0, ge=0, description="total-power loss per wall (assumption)")
    rx_sigma_db: float = Field(2.0, ge=0, description="RX level estimate scatter")
    fp_gap_los_db: float = Field(3.0, ge=0, description="mean RX - first-path power in LOS (APS006 Part 2: < 6 dB)")
    fp_gap_per_wall_db: float = Field(9.0, ge=0, description=(
        "extra first-path attenuation per wall (APS006 Part 2: NLOS gives > 10 dB)"))
    fp_gap_sigma_db: float = Field(2.0, ge=0, description="scatter of RX - first-path power")

    # the data radio's angle of arrival (bridge.media.uwb_radio)
    pdoa_fov_deg: float = Field(60.0, gt=0, le=90, description=(
        "data radio: bearings within this angle of the antenna axis are flagged valid (two-antenna PDoA; Dotlic et "
        "al. 2017; assumption for the field of view)"))
    pdoa_sigma_deg: float = Field(5.0, ge=0, le=45, description=(
        "data radio: angle-of-arrival noise at boresight, growing as 1 / cos towards broadside (assumption, of the "
        "order of the DW1000 PDoA demonstrations in Dotlic et al. 2017)"))
    pdoa_nlos_sigma_deg: float = Field(15.0, ge=0, le=45, description=(
        "data radio: extra angle-of-arrival noise through walls (assumption)"))
    radio_queue_frames: int = Field(16, ge=1, le=255, description="data radio: transmit queue of the module, frames")

    def budget(self, n_robots: int) -> dict[str, float]:
        """Ranging rates for ``n_robots`` sharing this budget (see ``firmware_sim.modules.uwb.tdma_budget``)."""
        return tdma_budget(self.frames_per_s, self.frames_per_exchange, n_robots, self.update_rate_hz)


class _Link:
    __slots__ = ("bias", "rng", "t_ns")

    def __init__(self, rng: np.random.Generator, bias: float, t_ns: int) -> None:
        self.rng = rng
        self.bias = bias
        self.t_ns = t_ns


def _err_acc() -> dict[str, float]:
    return {"n": 0, "sum": 0.0, "sumsq": 0.0}


def _summary(acc: dict[str, float]) -> dict[str, float | int]:
    n = int(acc["n"])
    if n == 0:
        return {"n": 0, "mean_m": 0.0, "std_m": 0.0, "rms_m": 0.0}
    mean = acc["sum"] / n
    ms = acc["sumsq"] / n
    return {"n": n, "mean_m": mean, "std_m": math.sqrt(max(0.0, ms - mean * mean)), "rms_m": math.sqrt(ms)}


class UwbMedium:
    """Range exchanges between the swarm's UWB modules, with ground truth from ``geometry``."""

    def __init__(self, cfg: UwbCfg, n: int, seed: int, geometry: Geometry) -> None:
        self.cfg = cfg
        self.n = n
        self.seed = seed
        self.geometry = geometry
        self.frame_ns = 1_000_000_000 // cfg.frames_per_s  # nominal; slot edges use exact integer division
        self._links: dict[tuple[int, int], _Link] = {}
        keys = ("exchanges", "ok", "dropout", "out_of_range", "no_response", "nlos", "responded", "partitioned",
                "burst_loss", "sensor_dead")
        self._count = [dict.fromkeys(keys, 0) for _ in range(n)]
        self._err = [{"los": _err_acc(), "nlos": _err_acc()} for _ in range(n)]
        self.off: set[int] = set()  # robots whose module was pulled out: they neither range nor answer
        self.faults = UwbFaults(seed, "uwb")  # injected faults: the air's, and modules as faulty sensors

    def _frames_ns(self, k: int) -> int:
        return (k * 1_000_000_000) // self.cfg.frames_per_s

    def _link(self, i: int, j: int, t_ns: int) -> _Link:
        key = (min(i, j), max(i, j))
        link = self._links.get(key)
        if link is None:
            rng = stream(self.seed, "uwb", *key)
            link = _Link(rng, float(rng.normal(0.0, self.cfg.bias_sigma_m)), t_ns)
            self._links[key] = link
        return link

    def p_ok(self, d: float, walls: int) -> float:
        """Probability that an exchange (or a frame) over ``d`` metres and ``walls`` walls gets through."""
        cfg = self.cfg
        return (1 - cfg.dropout_los) * (1 - cfg.dropout_per_wall) ** walls * (
            1 - min(1.0, d / cfg.max_range_m) ** cfg.dropout_range_exp)

    def measure(self, t_ns: int, i: int, j: int, d: float, walls: int) -> tuple[float, float, float, float]:
        """One exchange's draws on the link between ``i`` and ``j`` (a fixed number, whatever comes of them):
        ``(u, measured range, RX level, first-path level)``; it got through if ``u < p_ok(d, walls)``."""
        cfg = self.cfg
        link = self._link(i, j, t_ns)
        # fixed draws per exchange: bias step, noise, exponential tail, dropout, rx level, fp gap
        z_b, z_n, z_rx, z_fp = link.rng.standard_normal(4)
        e_tail = float(link.rng.exponential(1.0))
        u_drop = float(link.rng.random())
        dt = max(0, t_ns - link.t_ns) / 1e9
        a = math.exp(-dt / cfg.bias_tau_s)
        link.bias = a * link.bias + cfg.bias_sigma_m * math.sqrt(max(0.0, 1.0 - a * a)) * float(z_b)
        link.t_ns = max(link.t_ns, t_ns)
        if walls > 0:
            err = walls * cfg.nlos_bias_m + cfg.nlos_exp_scale_m * e_tail + cfg.nlos_sigma_m * float(z_n)
        else:
            err = cfg.sigma_los_m * float(z_n)
        rx = (cfg.rx_1m_dbm - 10 * cfg.path_loss_exp * math.log10(max(d, 0.1)) - walls * cfg.wall_loss_db
              + cfg.rx_sigma_db * float(z_rx))
        gap = max(0.0, cfg.fp_gap_los_db + walls * cfg.fp_gap_per_wall_db + cfg.fp_gap_sigma_db * float(z_fp))
        return u_drop, d + link.bias + err, rx, rx - gap

    def exchange(self, t_ns: int, i: int, j: int) -> list[tuple[int, int, dict[str, Any]]]:
        """Module ``i`` ranges module ``j`` starting at ``t_ns``: result events (t_done_ns, robot, event)."""
        cfg = self.cfg
        t_ns = int(t_ns)
        alive = np.asarray(self.geometry.alive())
        if not (0 <= i < self.n and 0 <= j < self.n) or i == j or not alive[i] or i in self.off:
            return []
        pos = np.asarray(self.geometry.positions(), dtype=float)
        d = float(math.hypot(*(pos[i] - pos[j])))
        walls = int(np.asarray(self.geometry.walls(i, np.array([j])))[0])
        u_drop, meas, rx, fp = self.measure(t_ns, i, j, d, walls)
        nlos = walls > 0
        c = self._count[i]
        c["exchanges"] += 1
        c["nlos"] += int(nlos)
        t_resp = t_ns + self._frames_ns(3)
        t_init = t_ns + self._frames_ns(cfg.frames_per_exchange)
        base = {"ev": "range", "true_m": d, "nlos": nlos, "walls": walls}
        if not alive[j] or j in self.off:
            cause = "no_response"
        elif d > cfg.max_range_m:
            cause = "out_of_range"
        else:
            cause = "ok" if u_drop < self.p_ok(d, walls) else "dropout"
        arrived = 4 if cause == "ok" else 0  # of its frames: poll, response, final, report
        if arrived and self.faults.any:
            cause, arrived = self._faulted(t_ns, i, j)
        fail = {**base, "peer": j, "ok": False, "range_m": 0.0, "rx_dbm": 0.0, "fp_dbm": 0.0, "t_ns": t_init,
                "responder": False, "cause": cause}
        if arrived < 3:  # the responder never got the final: nobody has a range
            c[cause] += 1
            return [(t_init, i, fail)]

        self._count[j]["responded"] += 1
        common = {**base, "ok": True, "range_m": meas, "rx_dbm": rx, "fp_dbm": fp, "cause": "ok"}
        out = [(t_resp, j, {**common, "range_m": self.faults.reading(j, i, meas, t_ns), "peer": i, "t_ns": t_resp,
                            "responder": True})]
        if arrived < 4:  # the report was lost: the responder has its range, the initiator none
            c[cause] += 1
            return [*out, (t_init, i, fail)]
        c["ok"] += 1
        got = self.faults.reading(i, j, meas, t_ns)
        acc = self._err[i]["nlos" if nlos else "los"]
        acc["n"] += 1
        acc["sum"] += got - d
        acc["sumsq"] += (got - d) ** 2
        return [*out, (t_init, i, {**common, "range_m": got, "peer": j, "t_ns": t_init, "responder": False})]

    def _faulted(self, t_ns: int, i: int, j: int) -> tuple[str, int]:
        """An injected fault's say on an exchange that would get through: its cause and how many of its four frames
        arrived (a dead module's exchanges fail from the first; a frame lost to the air ends the exchange)."""
        for r in (i, j):
            if (sf := self.faults.dead(r, t_ns)) is not None:
                sf.failed += 1
                return "sensor_dead", 0
        for k, (src, dst) in enumerate(((i, j), (j, i), (i, j), (j, i))):
            if (lost := self.faults.air(t_ns + self._frames_ns(k), src, dst)) is not None:
                return lost, k
        return "ok", 4

    def stats(self) -> dict[str, Any]:
        """Per robot (as initiator) counts and raw range errors (LOS and NLOS), plus the swarm totals."""
        robots = []
        tot_c: dict[str, int] = {}
        tot_e = {"los": _err_acc(), "nlos": _err_acc()}
        for r in range(self.n):
            c, e = self._count[r], self._err[r]
            for k, v in c.items():
                tot_c[k] = tot_c.get(k, 0) + v
            for kind in ("los", "nlos"):
                for k in ("n", "sum", "sumsq"):
                    tot_e[kind][k] += e[kind][k]
            robots.append({**c, "err_los": _summary(e["los"]), "err_nlos": _summary(e["nlos"])})
        return {"robots": robots,
                "all": {**tot_c, "err_los": _summary(tot_e["los"]), "err_nlos": _summary(tot_e["nlos"])}}


class UwbRanging(Medium):
    """The UWB modules' two-way ranging in a session: each request resolved by the ``UwbMedium`` and its results
    delivered to the modules; the ranges the logic logs (``uwb_ranges``: peers, raw, filtered) scored against the
    ground truth, LOS and NLOS apart."""

    name = "uwb"
    order = 40
    routes = {("uwb", "uwb"): "exchange"}  # noqa: RUF012

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        return any(rp.uwb for rp in hub.plan.robots)

    def __init__(self, hub: Hub) -> None:
        super().__init__(hub)
        self.medium = UwbMedium(hub.cfg.uwb, hub.n, hub.cfg.session.seed, hub.geometry)
        self.robot_of = {uwb_addr16(r): r for r, rp in enumerate(hub.plan.robots) if rp.uwb}
        self.log_err: dict[int, dict[str, ErrorStats]] = defaultdict(lambda: defaultdict(ErrorStats))
        # the config's UWB faults (partition, burst_loss with medium = "uwb"; sensor = "uwb"), and injected ones
        self.carrier = UwbFaultCarrier(hub, self.medium.faults, self.robot_of.values(), "UWB ranging")

    def inject_fault(self, f: Any, t: int) -> bool:
        """A fault of the UWB air, or a module's sensor fault, injected while the session runs."""
        return self.carrier.take(f)

    def end_fault(self, f: Any, t: int) -> bool:
        """End fault ``f`` (as injected) at ``t``, if this medium carries it."""
        return self.carrier.end(f, t)

    def unplug(self, r: int, device: str) -> None:
        """Robot ``r``'s UWB module was pulled out: it answers nobody from now on."""
        if device == "uwb":
            self.medium.off.add(r)

    def exchange(self, e: str, r: int, t: int, item: list) -> None:
        """``["uwb", {op: "range", peer, t_ns}]``: resolved at once, at its slot start (kept within t+q..t+2q); the
        results go to the modules at the first quantum boundary after their times."""
        hub = self.hub
        q = hub.q_ns
        req = item[1]
        if not isinstance(req, dict):
            raise ValueError
        peer, t_req = req.get("peer"), req.get("t_ns", 0)
        if type(peer) is not int or type(t_req) is not int or not (0 <= peer < hub.n) or peer == r:
            raise ValueError
        start = max(t + q, min(t_req, t + 2 * q))
        for t_ev, rr, ev in self.medium.exchange(start, r, peer):
            if "uwb" in hub.roles[rr]:
                hub.deliver_at(max(t + q, -(-t_ev // q) * q), hub.to_inbox, entity(rr, "uwb"), ["uwb", ev])

    def on_log(self, robot: int, topic: str, values: dict[str, Any], t: int) -> None:
        """The logic's own ranges (raw and filtered) against the ground truth now: the error it lives with."""
        if topic != "uwb_ranges":
            return
        hub = self.hub
        peers, raw, filt = values.get("peers"), values.get("raw"), values.get("filtered")
        if not (isinstance(peers, list) and isinstance(raw, list) and isinstance(filt, list)
                and len(peers) == len(raw) == len(filt)):
            raise ValueError
        acc = self.log_err[robot]
        pairs = [(self.robot_of.get(a), x, f) for a, x, f in zip(peers, raw, filt, strict=True)]
        pairs = [(p, x, f) for p, x, f in pairs if p is not None and p not in hub.dead and p != robot]
        if not pairs:
            return
        pos = hub.world.pos
        walls = hub.world.walls(robot, np.array([p for p, _, _ in pairs]))
        for (p, x, f), w in zip(pairs, walls.tolist(), strict=True):
            true_m = float(np.hypot(*(pos[robot] - pos[p])))
            sight = "nlos" if w else "los"
            if isinstance(x, int | float) and isinstance(f, int | float):  # compared on the same samples
                acc[f"raw_{sight}"].add(float(x) - true_m)
                acc[f"filtered_{sight}"].add(float(f) - true_m)

    def radio_report(self, out: dict[str, Any]) -> None:
        hub = self.hub
        ustats = self.medium.stats()
        out["uwb_medium"] = ustats.get("all", {})
        if (faults := self.carrier.report()) is not None:
            out["uwb_faults"] = faults
        for r in range(hub.n):
            if "uwb" not in hub.roles[r]:
                continue
            d = out["per_robot"].setdefault(r, {})
            d["uwb_raw"] = ustats["robots"][r]
            d["uwb_module"] = hub.module_stats.get(entity(r, "uwb"))
            logged = self.log_err.get(r)
            if logged:
                d["uwb_logic_error"] = {k: v.summary() for k, v in logged.items()}
        allerr: dict[str, ErrorStats] = defaultdict(ErrorStats)
        for acc in self.log_err.values():
            for k, v in acc.items():
                allerr[k].merge(v)
        out["uwb_logic_error"] = {k: v.summary() for k, v in sorted(allerr.items())}


class ErrorStats:
    """A series of range errors (m) in fixed memory, for the summary: RMS, mean and the 95th percentile of |error|
    (to 1.2 %, from 0.1 mm to 1 km). A soak keeps counters, not a float per range."""

    def __init__(self) -> None:
        self.moments = Moments()
        self.abs = LogHistogram(lo=1e-4, decades=7)

    def add(self, e: float) -> None:
        self.moments.add(e)
        self.abs.add(abs(e))

    def merge(self, other: ErrorStats) -> None:
        self.moments.merge(other.moments)
        self.abs.merge(other.abs)

    def summary(self) -> dict[str, Any]:
        m = self.moments
        if not m.n:
            return {"n": 0}
        return {"n": m.n, "rms_m": round(m.rms, 4), "mean_m": round(m.mean, 4),
                "p95_abs_m": round(float(self.abs.quantile(0.95) or 0.0), 4)}
