"""Faults a robot lives through, scheduled in simulated time: what the world does for each, and what it counts.

One place for the kinds of ``[[faults]]`` that neither kill a robot outright nor belong to a medium:

- ``freeze``: the robot's logic, or its boards, stop for a while (as a process after SIGSTOP): nothing of theirs runs,
  what reaches them queues, and they go on with it when the freeze ends; or the world declares the robot hung once it
  has been frozen ``hung_after_s`` (the policy a watchdog on the robot would have).
- ``firmware_reboot``: a board restarts (held in reset ``boot_s``, RAM lost, ``setup()`` again); the firmware host
  does it (``bridge.hosts.firmware``), told here when.
- ``brown_out``: the battery sags (the world's battery model); below ``reset_v`` every board of the robot resets and
  reboots once the voltage is back.
- ``sensor``: a stuck, noisy, dead or biased sensor, applied where the world model makes the reading
  (``SensorFaults``, held by the world), so every board that reads it sees the same fault.
- ``wheel_slip``, ``motor_stall``: the drive's wheels (a world model with ``WorldModel.faults``).
- ``clock_drift``: a board's ``millis()`` runs fast or slow; the firmware host maps its clock.

Each is an event at its start and end (``/session/events``) and a row of ``summary.json``'s ``faults``. Random draws
(a noisy sensor's) come from the fault's own stream, so the same seed gives the same faulty run.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from bridge.core.entities import entity
from bridge.core.rng import stream

if TYPE_CHECKING:
    from bridge.core.config import FaultCfg
    from bridge.core.hub import Hub

#: the kinds this module carries out (the others: the hub's deaths, the media's faults)
ROBOT_FAULTS = ("freeze", "firmware_reboot", "brown_out", "sensor", "wheel_slip", "motor_stall", "clock_drift")
#: the readings a sensor fault takes, as the world models that make them name them (``WorldModel.sensors``)
SENSORS = ("sonar", "encoder", "light")
#: what a dead sensor reads: an analog sonar's 0 V (0 m), a dark light sensor; a dead encoder sends no pulses
DEAD_READING = {"sonar": 0.0, "light": 0.0}


@dataclass
class SensorFault:
    """One sensor's fault from ``t0`` to ``t1`` (ns; None: to the end). A counter (an encoder) keeps, after the fault,
    what it missed during it (``offset``): its pulses lost while stuck or dead stay lost."""

    sensor: str
    mode: str
    t0: int
    t1: int | None
    sigma: float = 0.0
    bias: float = 0.0
    rng: np.random.Generator | None = None
    held: Any = None
    offset: Any = None
    reads: int = 0

    def active(self, t: int) -> bool:
        return self.t0 <= t and (self.t1 is None or t < self.t1)

    def apply(self, value: Any, t: int) -> Any:
        """The reading the sensor gives for the true ``value`` (a float, or an array: several sonars, two encoders)
        at ``t``."""
        counter = self.sensor == "encoder"
        if not self.active(t):
            if counter and self.offset is None and self.held is not None:
                self.offset = np.asarray(self.held) - np.asarray(value)  # the pulses it missed
            if self.offset is not None:
                return _like(value, np.asarray(value) + self.offset)
            return value
        self.reads += 1
        v = np.asarray(value, dtype=float)
        if self.mode == "stuck" or (self.mode == "dead" and counter):
            if self.held is None:
                self.held = np.asarray(value)
            return _like(value, self.held)
        if self.mode == "dead":
            return _like(value, np.full_like(v, DEAD_READING[self.sensor]))
        if self.mode == "noisy":
            assert self.rng is not None
            noise = self.rng.standard_normal(v.shape) * self.sigma
            return _like(value, np.round(v + noise) if counter else np.maximum(v + noise, 0.0))
        return _like(value, np.round(v + self.bias) if counter else np.maximum(v + self.bias, 0.0))


def _like(template: Any, v: Any) -> Any:
    """``v`` in ``template``'s form: a float, a tuple of ints (counts), or an array."""
    if isinstance(template, float | int) and not isinstance(template, bool):
        return type(template)(np.asarray(v).item())
    if isinstance(template, tuple):
        return tuple(int(x) for x in np.asarray(v).tolist())
    return np.asarray(v, dtype=np.asarray(template).dtype)


class SensorFaults:
    """The world's faulty sensors: a world model passes each fresh reading of robot ``r``'s ``sensor`` through
    ``apply``; with no fault it costs one dictionary lookup."""

    def __init__(self) -> None:
        self.faults: dict[tuple[int, str], list[SensorFault]] = {}

    def add(self, r: int, f: SensorFault) -> None:
        self.faults.setdefault((r, f.sensor), []).append(f)

    def apply(self, r: int, sensor: str, value: Any, t: int) -> Any:
        for f in self.faults.get((r, sensor), ()):
            value = f.apply(value, t)
        return value


@dataclass
class _Row:
    """One fault of the run, as ``summary.json``'s ``faults`` lists it."""

    kind: str
    robot: int
    at_s: float
    until_s: float | None
    detail: str
    effect: dict[str, Any] = field(default_factory=dict)
    ended: bool = False


class RobotFaults:
    """The hub's side of the robot faults: it schedules each one's start and end, freezes and thaws entities, tells
    the firmware host of reboots and drifting clocks, sags batteries, and reports them."""

    def __init__(self, hub: Hub) -> None:
        self.hub = hub
        self.frozen: dict[str, int | None] = {}  # entity -> when its freeze ends
        self.to_firmware: dict[str, list[dict[str, Any]]] = {}  # entity -> fault items for its next run
        self.rows: list[_Row] = []
        self.sensor_faults: list[tuple[_Row, SensorFault]] = []
        self.count = 0
        self._live: dict[int, tuple[_Row, SensorFault | None]] = {}  # id(fault entry) -> what ends it early

    # -- what a robot can carry ----------------------------------------------------------------------
    def problem(self, f: FaultCfg) -> str | None:
        """Why robot ``f.robot`` cannot carry fault ``f`` of this module's kinds (None if it can)."""
        rp = self.hub.plan.robots[f.robot]
        return robot_fault_problem(rp, f)

    # -- injection -------------------------------------------------------------------------------------
    def inject(self, f: FaultCfg, t: int) -> None:
        """Fault ``f`` from ``f.at_s`` on (``t``: now). ValueError if robot ``f.robot`` cannot carry it."""
        if why := self.problem(f):
            raise ValueError(why)
        hub, r = self.hub, f.robot
        q = hub.q_ns
        t0 = round(f.at_s * 1e9)
        t1 = None if f.duration_s is None else t0 + round(f.duration_s * 1e9)
        k0 = -(-t0 // q) * q  # the quantum it takes effect at
        self.count += 1
        if f.kind == "freeze":
            ents = self._process_entities(r, f.process)
            row = self._row(f, t0, t1, f"its {f.process} stops" + (
                f", declared hung after {f.hung_after_s:g} s" if f.hung_after_s else " and comes back"))
            hub.deliver_at(k0, self._freeze, row, ents, -(-t1 // q) * q)
            if f.hung_after_s is not None:
                hub.deliver_at(-(-(t0 + round(f.hung_after_s * 1e9)) // q) * q, self._hung, row, ents, f.hung_after_s)
        elif f.kind == "firmware_reboot":
            row = self._row(f, t0, t0 + round(f.boot_s * 1e9), f"its {f.board} reboots ({f.boot_s:g} s to setup())")
            self._reboot(r, [f.board], t0, t0 + round(f.boot_s * 1e9), row)
        elif f.kind == "clock_drift":
            row = self._row(f, t0, t1, f"its {f.board}'s clock runs {f.ppm:+g} ppm")
            self._tell(entity(r, f.board), {"kind": "drift", "at": t0, "until": t1, "ppm": float(f.ppm)}, None)
            hub.deliver_at(k0, self._event, row, "")
        elif f.kind == "brown_out":
            row = self._row(f, t0, t1, f"its battery sags {f.sag_v:g} V")
            hub.deliver_at(k0, self._brown_out, row, f)
        elif f.kind == "sensor":
            row = self._row(f, t0, t1, f"its {f.sensor} goes {f.mode}" + (
                f" (sigma {f.sigma:g})" if f.mode == "noisy" else f" (bias {f.bias:+g})" if f.mode == "bias" else ""))
            sf = SensorFault(f.sensor, f.mode, t0, t1, sigma=f.sigma or 0.0, bias=f.bias or 0.0,
                             rng=stream(hub.cfg.session.seed, "fault", self.count, r, f.sensor))
            hub.world.sensor_faults.add(r, sf)
            self.sensor_faults.append((row, sf))
            self._live[id(f)] = (row, sf)
            hub.deliver_at(k0, self._event, row, "")
        else:  # wheel_slip, motor_stall
            row = self._row(f, t0, t1, f"its {f.wheel} wheel" + (
                f" slips ({f.slip:g} of its rim speed lost)" if f.kind == "wheel_slip" else "'s motor stalls"))
            hub.deliver_at(k0, self._wheel, row, f, True)
            self._live[id(f)] = (row, None)
        if t1 is not None and f.kind in ("sensor", "clock_drift"):
            hub.deliver_at(-(-t1 // q) * q, self._event_end, row)
        if t1 is not None and f.kind in ("wheel_slip", "motor_stall"):
            hub.deliver_at(-(-t1 // q) * q, self._wheel, row, f, False)

    def end(self, f: FaultCfg, t: int) -> None:
        """End fault ``f`` (the entry given to ``inject``) at ``t`` (ns) if it would last longer: a sensor's or a
        wheel's (a ground station's FAILURE_TYPE_OK). ValueError for a fault that cannot end early."""
        live = self._live.get(id(f))
        if live is None:
            raise ValueError(f"a {f.kind} fault cannot be ended early")
        row, sf = live
        q = self.hub.q_ns
        k = -(-t // q) * q
        if row.ended or (row.until_s is not None and row.until_s * 1e9 <= t):
            return
        row.until_s = t / 1e9
        if sf is not None:
            sf.t1 = t
            self.hub.deliver_at(k, self._event_end, row)
        else:
            self.hub.deliver_at(k, self._wheel, row, f, False)

    def _row(self, f: FaultCfg, t0: int, t1: int | None, detail: str) -> _Row:
        row = _Row(f.kind, int(f.robot), t0 / 1e9, None if t1 is None else t1 / 1e9, detail)
        self.rows.append(row)
        return row

    def _process_entities(self, r: int, process: str) -> list[str]:
        rp = self.hub.plan.robots[r]
        if process == "logic":
            return [entity(r, "logic")]
        return [entity(r, role) for role in board_roles(rp)]

    def _tell(self, e: str, item: dict[str, Any], wake_at: int | None) -> None:
        """An item for the firmware host's next run of board ``e`` (and a run at ``wake_at`` at the latest)."""
        hub = self.hub
        self.to_firmware.setdefault(e, []).append(item)
        if wake_at is not None and e in hub.next_wake and not hub.is_dead(e):
            w = hub.next_wake[e]
            q = hub.q_ns
            k = -(-wake_at // q) * q
            hub.next_wake[e] = k if w is None else min(w, k)

    def take_for(self, e: str) -> list[dict[str, Any]] | None:
        """The fault items waiting for board ``e``'s run (None: none)."""
        return self.to_firmware.pop(e, None) if self.to_firmware else None

    # -- deliveries (at the quantum each takes effect) --------------------------------------------------
    def _event(self, t: int, row: _Row, extra: str) -> None:
        self.hub.event(t, {"kind": row.kind, "robot": row.robot, "detail": row.detail + extra})

    def _event_end(self, t: int, row: _Row) -> None:
        if row.ended:  # (ended early)
            return
        row.ended = True
        self.hub.event(t, {"kind": f"{row.kind}_end", "robot": row.robot, "detail": f"{row.kind} over"})

    def _freeze(self, t: int, row: _Row, ents: list[str], t_end: int | None) -> None:
        hub = self.hub
        if hub.is_dead(ents[0]):
            return
        for e in ents:
            self.frozen[e] = t_end
        self._event(t, row, "")
        if t_end is not None:
            hub.deliver_at(t_end, self._thaw, row, ents)

    def _thaw(self, t: int, row: _Row, ents: list[str]) -> None:
        """The freeze is over: the entities run now, with everything that queued for them meanwhile."""
        hub = self.hub
        queued = 0
        for e in ents:
            if self.frozen.pop(e, "gone") == "gone" or hub.is_dead(e):
                continue
            queued += len(hub.inbox[e])
            hub.next_wake[e] = t
        if not hub.is_dead(ents[0]):
            row.effect["queued_on_resume"] = row.effect.get("queued_on_resume", 0) + queued
            self.hub.event(t, {"kind": "freeze_end", "robot": row.robot,
                               "detail": f"it runs again, with {queued} inputs that queued meanwhile"})

    def _hung(self, t: int, row: _Row, ents: list[str], after_s: float) -> None:
        if not all(e in self.frozen for e in ents) or self.hub.is_dead(ents[0]):
            return
        for e in ents:
            self.frozen.pop(e, None)
        row.effect["declared_hung"] = True
        self.hub.robot_failed(row.robot, t, "hung", f"frozen for {after_s:g} s (a freeze fault): declared hung")

    def due_filter(self, t: int, due: dict[str, list[str]]) -> dict[str, list[str]]:
        """``due`` without the frozen entities (they run when the freeze ends)."""
        if not self.frozen:
            return due
        out: dict[str, list[str]] = {}
        for p, ents in due.items():
            keep = [e for e in ents if e not in self.frozen]
            if keep:
                out[p] = keep
        return out

    def _reboot(self, r: int, roles: list[str], t0: int, up: int, row: _Row) -> None:
        for role in roles:
            self._tell(entity(r, role), {"kind": "reboot", "at": t0, "up": up}, t0)
        q = self.hub.q_ns
        self.hub.deliver_at(-(-t0 // q) * q, self._event, row, "")
        self.hub.deliver_at(-(-up // q) * q, self._rebooted, row, roles)

    def _rebooted(self, t: int, row: _Row, roles: list[str]) -> None:
        if not self.hub.is_dead(entity(row.robot, "logic")):
            self.hub.event(t, {"kind": "firmware_reboot_end", "robot": row.robot,
                               "detail": f"{', '.join(roles)} running setup() again"})

    def _brown_out(self, t: int, row: _Row, f: FaultCfg) -> None:
        """The sag starts: the world's battery drops ``sag_v``; below ``reset_v`` the boards reset until it is over
        and then boot."""
        hub, r = self.hub, row.robot
        if r in hub.dead:
            return
        v = float(hub.world.battery_v[r]) - f.sag_v
        hub.world.sag_v[r] += f.sag_v
        resets = v < f.reset_v
        row.effect.update({"battery_v": round(v, 3), "reset": resets})
        t1 = round((f.at_s + f.duration_s) * 1e9)
        q = hub.q_ns
        hub.deliver_at(-(-t1 // q) * q, self._sag_over, row, f.sag_v)
        extra = (f": {v:.2f} V, below the {f.reset_v:g} V its boards need: they reset" if resets
                 else f": {v:.2f} V, above the {f.reset_v:g} V its boards need")
        self._event(t, row, extra)
        if resets:
            roles = board_roles(hub.plan.robots[r])
            for role in roles:
                self._tell(entity(r, role), {"kind": "reboot", "at": t, "up": t1 + round(f.boot_s * 1e9)}, t)
            hub.deliver_at(-(-(t1 + round(f.boot_s * 1e9)) // q) * q, self._rebooted, row, list(roles))

    def _sag_over(self, t: int, row: _Row, sag_v: float) -> None:
        self.hub.world.sag_v[row.robot] -= sag_v
        self._event_end(t, row)

    def _wheel(self, t: int, row: _Row, f: FaultCfg, on: bool) -> None:
        hub = self.hub
        if row.robot in hub.dead or (not on and row.ended):
            return
        wheels = {"left": (0,), "right": (1,), "both": (0, 1)}[f.wheel]
        drive = next(m for m in hub.world.models.values() if f.kind in m.faults)
        drive.wheel_fault(row.robot, wheels, f.kind, f.slip if on else 0.0, on)
        if on:
            self._event(t, row, "")
        else:
            self._event_end(t, row)

    def report(self) -> dict[str, Any]:
        """``summary.json``'s ``faults``: each fault with its time span and effect, and how many of each kind."""
        for row, sf in self.sensor_faults:
            row.effect["faulty_readings"] = sf.reads
        return {"count": dict(Counter(r.kind for r in self.rows)),
                "list": [{"kind": r.kind, "robot": r.robot, "at_s": r.at_s, "until_s": r.until_s,
                          "detail": r.detail, **r.effect} for r in self.rows]}


def board_roles(rp: Any) -> tuple[str, ...]:
    """A robot's boards (its simulated LLC, its robot model's own boards): what reboots, hangs or drifts; its radio
    modules and USB adapters are hardware of their own."""
    return tuple(role for role in rp.modules() if role not in ("xbee", "uwb", "slcan", "can_bridge"))


def robot_fault_problem(rp: Any, f: FaultCfg) -> str | None:
    """Why robot ``rp`` cannot carry fault ``f`` of the kinds this module carries (None if it can)."""
    from bridge.core.registry import robot_spec

    if f.kind == "freeze":
        if f.process == "logic" and not rp.has_logic:
            return f"process: robot {rp.id}'s logic is not the session's to freeze"
        if f.process == "firmware" and not board_roles(rp):
            return f"process: robot {rp.id} has no simulated board to freeze"
    elif f.kind in ("firmware_reboot", "clock_drift"):
        if f.board not in board_roles(rp):
            return (f"board: robot {rp.id} has no {f.board} board (its boards: "
                    f"{', '.join(board_roles(rp)) or 'none simulated'})")
    elif f.kind == "brown_out":
        if not board_roles(rp):
            return f"robot: robot {rp.id} has no simulated board to brown out"
    elif f.kind in ("sensor", "wheel_slip", "motor_stall"):
        if f.kind == "sensor" and f.sensor == "uwb":
            from bridge.media.impairments import UWB_RADIO_ROLE

            return None if rp.uwb or UWB_RADIO_ROLE in rp.modules() else f"sensor: robot {rp.id} has no UWB module"
        parts = robot_spec(rp.profile).profile_with(rp.options).parts
        if f.kind == "sensor":
            if not any(f.sensor in type(p).world_model.sensors for p in parts):
                return f"sensor: robot {rp.id} ({rp.profile}) has no {f.sensor}"
        elif not any(f.kind in type(p).world_model.faults for p in parts):
            return f"kind: robot {rp.id} ({rp.profile}) has no wheels that can {f.kind.replace('_', ' ')}"
    return None
