"""Faults the UWB media carry: faults of the air on the UWB radios' frames, and a robot's UWB module as a faulty
range sensor. One place for both UWB media: the eSwarBot's ranging modules (``bridge.media.uwb``, two-way ranging
exchanges) and the DeciZebro's DWM1001 radio with data (``bridge.media.uwb_radio``, beacons and data frames).

- **Air** (``[[faults]]`` ``partition`` or ``burst_loss`` with ``medium = "uwb"``): ``bridge.media.impairments``'s
  partitions and Gilbert-Elliott loss, with streams of their own per medium. A two-way exchange is four frames (poll,
  response, final, report; Decawave APS013): the first one lost ends it, so the responder has a range only if the
  first three got through and the initiator only if all four did. A DeciZebro's beacon or data frame is one frame.
- **Sensor** (``kind = "sensor"``, ``sensor = "uwb"``, ``robot = R``), for ``duration_s`` (None: to the end):
  ``stuck``: R's module reports, for each peer, the range it last reported before the fault (for a peer it had none
  of, the first it measures); ``noisy``: R's reports get N(0, ``sigma``) added (clipped at 0), drawn from the fault's
  own stream; ``bias``: every range involving R's module, whoever measures it, is off by ``bias`` (an antenna-delay
  error biases both directions of a time of flight); ``dead``: R's module measures no range, as a module whose
  receiver is dead: a two-way exchange it takes part in fails (as initiator it never hears the response, as responder
  never the poll), a DeciZebro's hears no beacon (its data frames still arrive: the fault is the ranging sensor's;
  ``unplugged`` takes the whole module). stuck, noisy and bias are the world sensors' ``SensorFault``.

A fault takes only what would have got through without it (a frame already lost to the channel is not counted
again), and it also strikes a robot in the DeciZebro's faithful mode: it is injected on purpose. Each is an event at
its start and end (``/session/events``: ``partition``, ``burst_loss``, ``sensor`` and their ``_end``) and counted in
``summary.json``'s ``radio`` section (``uwb_faults``, ``uwb_radio.faults``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from bridge.core.faults import SensorFault
from bridge.core.rng import stream
from bridge.media.impairments import AIR_FAULTS, BurstLoss, Impairments, Partition

if TYPE_CHECKING:
    from bridge.core.hub import Hub


class UwbSensorFault:
    """Robot ``robot``'s UWB module as a faulty range sensor from ``t0`` to ``t1`` (ns; None: to the end)."""

    def __init__(self, robot: int, mode: str, t0: int, t1: int | None, sigma: float = 0.0, bias: float = 0.0,
                 rng: np.random.Generator | None = None) -> None:
        self.robot, self.mode = robot, mode
        self.generic = SensorFault("uwb", mode, t0, t1, sigma=sigma, bias=bias, rng=rng)
        self.held: dict[int, SensorFault] = {}  # stuck: the range it holds for each peer
        self.failed = 0  # dead: exchanges (a DeciZebro's beacons) it took

    @property
    def t0(self) -> int:
        return self.generic.t0

    @property
    def t1(self) -> int | None:
        return self.generic.t1

    @t1.setter
    def t1(self, t: int | None) -> None:
        self.generic.t1 = t
        for sf in self.held.values():
            sf.t1 = t

    def active(self, t: int) -> bool:
        return self.generic.active(t)

    @property
    def ranges(self) -> int:
        """The ranges it changed (stuck, noisy, bias)."""
        return self.generic.reads + sum(sf.reads for sf in self.held.values())

    def own(self, peer: int, value: float, last: float | None, t: int) -> float:
        """What R's module reports for ``peer`` when it measured ``value`` at ``t`` (``last``: its last report)."""
        if not self.active(t):  # (a stuck module holds what it reported last before, not what it had earlier)
            return value
        if self.mode == "stuck":
            sf = self.held.get(peer)
            if sf is None:
                sf = self.held[peer] = SensorFault("uwb", "stuck", self.t0, self.t1,
                                                   held=None if last is None else np.asarray(last))
            return float(sf.apply(value, t))
        if self.mode == "noisy":
            return float(self.generic.apply(value, t))
        return value

    def biased(self, value: float, t: int) -> float:
        """A range involving R's module, off by the bias while it lasts."""
        return float(self.generic.apply(value, t)) if self.mode == "bias" and self.active(t) else value


class UwbFaults:
    """The faults on one UWB medium: the air's (``impairments``) and its modules' as sensors (``sensors``)."""

    def __init__(self, seed: int, medium: str) -> None:
        self.seed, self.medium = seed, medium
        self.impairments = Impairments(seed, medium)
        self.sensors: list[UwbSensorFault] = []
        self._of: dict[int, list[UwbSensorFault]] = {}  # robot -> its module's faults
        self.last: dict[tuple[int, int], float] = {}  # (module, peer) -> the last range it reported

    @property
    def any(self) -> bool:
        """Whether any fault was ever put on this medium (none: the hot paths skip all of this)."""
        return bool(self.sensors or self.impairments.partitions or self.impairments.bursts)

    def sensor(self, robot: int, mode: str, t0: int, t1: int | None, sigma: float | None = None,
               bias: float | None = None) -> UwbSensorFault:
        """Robot ``robot``'s module goes ``mode`` from ``t0`` to ``t1`` (ns); noise from the fault's own stream."""
        if mode not in ("stuck", "noisy", "dead", "bias"):
            raise ValueError(f"mode: a UWB module goes stuck, noisy, dead or bias, not {mode!r}")
        rng = stream(self.seed, "fault", self.medium, len(self.sensors), robot, "uwb")
        sf = UwbSensorFault(robot, mode, t0, t1, sigma or 0.0, bias or 0.0, rng)
        self.sensors.append(sf)
        self._of.setdefault(robot, []).append(sf)
        return sf

    def air(self, t: int, src: int, dst: int) -> str | None:
        """Whether a frame ``src`` sends ``dst`` at ``t`` is lost to a fault of the air: ``partitioned``,
        ``burst_loss``, or None (it gets through)."""
        imp = self.impairments
        if not (imp.partitions or imp.bursts):
            return None
        before = imp.partitioned
        if imp.lost(t, src, np.array([dst]))[0]:
            return "partitioned" if imp.partitioned > before else "burst_loss"
        return None

    def dead(self, r: int, t: int) -> UwbSensorFault | None:
        """Robot ``r``'s module's dead-sensor fault at ``t``, if it has one."""
        return next((sf for sf in self._of.get(r, ()) if sf.mode == "dead" and sf.active(t)), None)

    def reading(self, r: int, peer: int, value: float, t: int) -> float:
        """The range module ``r`` reports to ``peer`` when it measured ``value`` at ``t``: its own stuck and noisy
        faults, then the bias of either module."""
        for sf in self._of.get(r, ()):
            value = sf.own(peer, value, self.last.get((r, peer)), t)
        for x in (r, peer):
            for sf in self._of.get(x, ()):
                value = sf.biased(value, t)
        self.last[(r, peer)] = value
        return value


class UwbFaultCarrier:
    """A UWB medium's side of the faults: those it carries (the config's, read at construction, and those injected
    while the session runs), their start and end events, an early end, and what they took for the summary."""

    def __init__(self, hub: Hub, faults: UwbFaults, modules: Iterable[int], where: str) -> None:
        self.hub, self.faults, self.where = hub, faults, where
        self.modules = frozenset(modules)  # the robots with a module on this medium
        self.carried: list[tuple[Any, Partition | BurstLoss | UwbSensorFault]] = []
        for f in hub.cfg.faults:  # the config's (the hub injects none of these at start)
            self.take(f)

    def carries(self, f: Any) -> bool:
        """Whether fault ``f`` (``FaultCfg``) is this medium's: a fault of the UWB air, or a sensor fault of one of
        its modules."""
        if f.kind in AIR_FAULTS:
            return f.medium == "uwb"
        return f.kind == "sensor" and f.sensor == "uwb" and f.robot in self.modules

    def take(self, f: Any) -> bool:
        """Put fault ``f`` on the medium from ``f.at_s`` for ``f.duration_s`` (False: not this medium's)."""
        if not self.carries(f):
            return False
        t0 = round(f.at_s * 1e9)
        t1 = None if f.duration_s is None else t0 + round(f.duration_s * 1e9)
        imp = self.faults.impairments
        obj: Partition | BurstLoss | UwbSensorFault
        if f.kind == "partition":
            imp.partition(t0, t1, f.groups)
            obj = imp.partitions[-1]
            start = {"kind": "partition", "detail": f"the robots split into {f.groups} on the {self.where}"}
        elif f.kind == "burst_loss":
            imp.burst_loss(t0, t1, f.p_gb, f.p_bg, f.loss_good, f.loss_bad, f.robots)
            obj = imp.bursts[-1]
            links = "every link" if f.robots is None else f"the links of robots {f.robots}"
            start = {"kind": "burst_loss", "detail": f"Gilbert-Elliott loss on {links} (p_gb {f.p_gb}, p_bg {f.p_bg}, "
                                                     f"loss {f.loss_good}/{f.loss_bad}) on the {self.where}"}
        else:
            obj = self.faults.sensor(f.robot, f.mode, t0, t1, f.sigma, f.bias)
            extra = f" (sigma {f.sigma:g})" if f.mode == "noisy" else f" (bias {f.bias:+g})" if f.mode == "bias" else ""
            start = {"kind": "sensor", "robot": f.robot, "detail": f"its uwb goes {f.mode}{extra}"}
        self.carried.append((f, obj))
        self.hub.deliver_at(self._quantum(t0), self._start, start)
        if t1 is not None:
            self.hub.deliver_at(self._quantum(t1), self._end, obj, t1)
        return True

    def end(self, f: Any, t: int) -> bool:
        """End fault ``f`` (the entry it was given) at ``t`` (ns) if it lasts longer; False if it is not this
        medium's."""
        for g, obj in self.carried:
            if g is f:
                if obj.t1 is None or obj.t1 > t:
                    obj.t1 = t
                    self.hub.deliver_at(self._quantum(t), self._end, obj, t)
                return True
        return False

    def _quantum(self, t: int) -> int:
        q = self.hub.q_ns
        return -(-t // q) * q

    def _start(self, t: int, payload: dict[str, Any]) -> None:
        self.hub.event(t, payload)

    def _end(self, t: int, obj: Partition | BurstLoss | UwbSensorFault, t1: int) -> None:
        if obj.t1 != t1:  # ended earlier (or later) than this end was scheduled for
            return
        if isinstance(obj, UwbSensorFault):
            self.hub.event(t, {"kind": "sensor_end", "robot": obj.robot, "detail": "sensor over"})
        else:
            kind = "partition" if isinstance(obj, Partition) else "burst_loss"
            self.hub.event(t, {"kind": f"{kind}_end", "detail": f"{kind} over"})

    def report(self) -> dict[str, Any] | None:
        """The summary's figures: what the air's faults took, and each sensor fault's changed ranges and failed
        exchanges (None when the medium carried no fault)."""
        if not self.carried:
            return None
        out: dict[str, Any] = {}
        if any(not isinstance(obj, UwbSensorFault) for _, obj in self.carried):
            out["impairments"] = self.faults.impairments.report()
        sensors = [(f, obj) for f, obj in self.carried if isinstance(obj, UwbSensorFault)]
        if sensors:
            out["sensors"] = [{"robot": obj.robot, "mode": obj.mode, "at_s": obj.t0 / 1e9,
                               "until_s": None if obj.t1 is None else obj.t1 / 1e9, "faulty_ranges": obj.ranges,
                               "failed": obj.failed} for _, obj in sensors]
        return out
