"""A session a test drives in simulated time: ``SwarmSession``.

The session runs as ``swarm-sitl run`` runs it (the world, firmware and logic processes, the recording), with one more
participant: the probe (``bridge.testing.probe``), served in the test's own process. Between two calls of the test the
world waits for the probe, so simulated time stands still while the test looks, asserts or acts; ``run_for`` and
``run_until`` let it go on. What a test sees is fixed by the seed, whatever the machine's load: the same seed, the same
outcome.

    with SwarmSession("hil_configs/demo.toml", {"robots.count": 4}, out_dir=tmp_path) as s:
        s.run_until(lambda s: s.distance_m(0) > 0.5, timeout_s=30)
        assert s.alive(0)
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.core.config import Config, read_toml
from bridge.core.services import service_proc
from bridge.testing.probe import PROBE_NAME, Ended, Go, ProbeChannel, ProbeHost, Seen

LONGEST_S = 30 * 24 * 3600.0  # a driven session runs until the test stops it: its duration is the longest allowed


class SessionEnded(Exception):
    """The session is over (it reached its duration, a robot's failure stopped it, or it failed) and cannot go on."""


class SimTimeout(AssertionError):
    """``run_until``'s condition did not hold within its simulated time."""


@dataclass(frozen=True)
class LogLine:
    """One record a robot's logic (``robot.log``) or a service logged, or a session event."""

    t_s: float
    source: str  # "r003", "svc/camera" or "session"
    topic: str  # the log's topic ("rdpso"), "events" for a session event
    values: Any

    @property
    def robot(self) -> int | None:
        return int(self.source[1:]) if self.source.startswith("r") and self.source[1:].isdigit() else None

    def __str__(self) -> str:
        return f"t={self.t_s:.3f} s {self.source} {self.topic}: {self.values}"


class SwarmSession:
    """One session from ``config`` (a TOML path) with ``overrides`` (``{"session.seed": 3, "robots.count": 5}``, as
    ``load_config`` takes them), recorded into ``out_dir``. ``start()`` (or ``with``) runs it to simulated time 0 and
    holds it there; ``stop()`` ends it cleanly and returns its summary."""

    def __init__(self, config: str | Path, overrides: dict[str, Any] | None = None, out_dir: str | Path = "runs/test",
                 mavlink: bool = False) -> None:
        self.config = str(config)
        self.overrides = dict(overrides or {})
        if mavlink and "mavlink.endpoint" not in self.overrides:  # every robot gets its MAVLink face
            self.overrides["mavlink.endpoint"] = "udpin:127.0.0.1:0"
        self.out_dir = Path(out_dir)
        self.recording = self.out_dir / "session.mcap"
        self.summary: dict[str, Any] | None = None
        self.code: int | None = None
        self.touched: set[int] = set()  # the robots the test looked at or acted on (for a failure's report)
        self._channel = ProbeChannel()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._seen: Seen | None = None
        self._ended = False
        self._ids: list[int] = []
        self._log: list[LogLine] = []
        self._plan: Any = None
        self._q_ns = 0
        self._pending: list[list[Any]] = []  # what the probe sends with its next answer (faults, MAVLink)
        self._pins: dict[tuple[int, str], tuple[float, dict[str, Any]]] = {}  # (robot, board) -> newest pins record
        self._mavlink: MavlinkHandle | None = None
        self._running = False  # the world runs on (a run_for or run_until has not returned)
        self._stop_asked = False  # the launcher's stop hook: end the session even while the world runs

    # -- lifecycle -------------------------------------------------------------------------------------------
    def start(self) -> SwarmSession:
        """Start the session's processes and run it to simulated time 0, where it waits for the test."""
        from bridge.core.launcher import run_session

        if self._thread is not None:
            raise RuntimeError("this session was started already")
        overrides = self.session_overrides()
        channel = self._channel
        plan = self._plan = _plan(self.config, overrides)  # a wrong config or override is refused here, in the test
        self._ids = [r.id for r in plan.robots if r.gateway is None]
        self._q_ns = Config.from_plan(plan.config).session.quantum_ns
        hosted = {service_proc(PROBE_NAME): ProbeHost(plan, channel)}

        def launch() -> None:
            try:
                res = run_session(self.config, overrides, str(self.out_dir), progress=None, plot=False, hosted=hosted,
                                  stop=lambda: self._stop_asked)
                self.code, self.summary = res.code, res.summary
            except BaseException as e:  # a config error, or the launcher failed: told to the test's thread
                self._error = e
            finally:
                channel.seen.put(Ended())

        self._thread = threading.Thread(target=launch, name="swarm-sitl-launcher", daemon=True)
        self._thread.start()
        self._wait()
        return self

    def session_overrides(self) -> dict[str, Any]:
        """The overrides the session runs with: the test's, the longest duration unless they give one, and the probe
        among the services. The probe joins the config's services (or a whole list the overrides give) before the
        overrides that reach into them (``services.0.options.fps``) apply, so none is lost."""
        raw = read_toml(Path(self.config))
        services = self.overrides.get("services", raw.get("services", []))
        return {"session.duration_s": LONGEST_S, "services": [*services, {"kind": "probe", "name": PROBE_NAME}],
                **{k: v for k, v in self.overrides.items() if k != "services"}}

    def stop(self, reason: str = "the test stopped it") -> dict[str, Any]:
        """End the session now (the processes stop, the recording is finished) and return its summary."""
        if self._thread is None:
            raise RuntimeError("this session was never started")
        if not self._ended:
            self._channel.commands.put(Go(None, [["stop", reason]]))
            if self._running:  # interrupted while the world runs (Ctrl-C): it stops at the end of its quantum
                self._stop_asked = True
            while not self._ended:
                self._take(self._channel.seen.get())
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self.summary or {}

    def __enter__(self) -> SwarmSession:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- simulated time ---------------------------------------------------------------------------------------
    @property
    def t_ns(self) -> int:
        """Simulated time now (ns): the world stands at the start of this quantum."""
        return self._now().t_ns

    @property
    def t(self) -> float:
        """Simulated time now (s)."""
        return self.t_ns / 1e9

    def run_for(self, seconds: float) -> float:
        """Let the session run ``seconds`` of simulated time (to the first quantum at or after); returns the time."""
        if not 0 <= seconds <= LONGEST_S:
            raise ValueError(f"run_for: seconds must lie in [0, {LONGEST_S:g}], not {seconds}")
        if seconds > 0:
            self._go(self.t_ns + round(seconds * 1e9))
        return self.t

    def run_until(self, condition: Callable[[SwarmSession], bool], timeout_s: float,
                  every_s: float | None = None) -> float:
        """Let the session run until ``condition(session)`` holds, checked now and then every ``every_s`` simulated
        seconds (default: every quantum); returns the time. ``SimTimeout`` (an AssertionError) if it still does
        not hold ``timeout_s`` simulated seconds from now."""
        if not 0 <= timeout_s <= LONGEST_S:
            raise ValueError(f"run_until: timeout_s must lie in [0, {LONGEST_S:g}], not {timeout_s}")
        end = self.t_ns + round(timeout_s * 1e9)
        step = round(every_s * 1e9) if every_s else 1
        while not condition(self):
            if self.t_ns >= end:
                raise SimTimeout(f"not within {timeout_s:g} s of simulated time (now t={self.t:.3f} s)")
            self._go(min(end, self.t_ns + step))
        return self.t

    # -- a ground station ---------------------------------------------------------------------------------------
    @property
    def mavlink(self) -> MavlinkHandle:
        """The test as a ground station of the whole swarm (the session needs ``mavlink=True`` or a
        ``mavlink.endpoint``): what it sends reaches the robots' faces at the next quantum, routed by
        ``target_system`` as the swarm's MAVLink endpoint routes a ground station's packets; what the faces send
        arrives as they send it. Deterministic: it goes through the lock-step, not a socket."""
        if self._mavlink is None:
            cfg = Config.from_plan(self._plan.config) if self._plan is not None else None
            if cfg is None or not cfg.mavlink.endpoint:
                raise RuntimeError("this session's robots have no MAVLink face: SwarmSession(..., mavlink=True), or "
                                   "swarm_session(..., mavlink=True)")
            self._mavlink = MavlinkHandle(self, cfg.mavlink.system_id_base)
        return self._mavlink

    # -- faults -------------------------------------------------------------------------------------------------
    def fault(self, kind: str, robot: int | None = None, **fields: Any) -> None:
        """Inject a fault of any kind a config's ``[[faults]]`` knows, from the next quantum on (the world applies what
        the test does at simulated time t from t + one quantum, as any entity's output): ``firmware_crash``,
        ``battery_depleted``, ``can_bus_off`` (``node``, ``duration_s``), ``can_noise`` (``probability``,
        ``duration_s``), ``unplugged`` (``device``: its ``xbee`` or ``uwb`` module pulled out); and, with no robot,
        the air's: ``partition`` (``groups``, ``duration_s``), ``burst_loss`` (``p_gb``, ``p_bg``, ``loss_good``,
        ``loss_bad``, ``robots``, ``duration_s``, ``medium``: ``radio`` or ``uwb``); and the faults a robot lives
        through: ``freeze``, ``firmware_reboot``, ``brown_out``, ``sensor``, ``wheel_slip``, ``motor_stall``,
        ``clock_drift`` (README, Faults). A fault this session cannot carry is refused here (ConfigError naming the
        field)."""
        from pydantic import ValidationError

        from bridge.core.config import ConfigError, FaultCfg
        from bridge.media.impairments import UWB_RADIO_ROLE

        at_s = (self.t_ns + self._q_ns) / 1e9
        on = "" if robot is None else f" on robot {robot}"
        try:
            f = FaultCfg.model_validate({"kind": kind, "robot": robot, "at_s": at_s, **fields})
        except ValidationError as e:
            raise ConfigError(f"fault {kind}{on}: {e.errors()[0]['loc']}: {e.errors()[0]['msg']}") from None
        if missing := [r for r in f.robot_ids() if r not in self._ids]:
            raise ConfigError(f"fault {kind}: no robot {missing[0]} in this session (robots {self._ids})")
        if robot is not None and (why := self._plan.robots[robot].fault_problem(f)):
            raise ConfigError(f"fault {kind}: {why}")
        if robot is None and f.medium == "radio" and not any(rp.sim_xbee for rp in self._plan.robots):
            raise ConfigError(f"fault {kind}: no robot has a simulated XBee, so nothing carries it")
        if robot is None and f.medium == "uwb" and not any(rp.uwb or UWB_RADIO_ROLE in rp.modules()
                                                           for rp in self._plan.robots):
            raise ConfigError(f"fault {kind}: no robot has a UWB module, so nothing carries it")
        self.touched.update(f.robot_ids())
        self._pending.append(["fault", {**f.model_dump(exclude_defaults=True), "kind": f.kind}])

    # -- the robots ---------------------------------------------------------------------------------------------
    @property
    def robots(self) -> list[int]:
        """The session's robots' ids (XBee gateways, which are no robots, left out)."""
        return list(self._ids)

    def pose(self, robot: int) -> tuple[float, float, float]:
        """Robot ``robot``'s true pose now: x, y (m, arena frame) and yaw (rad)."""
        i = self._row(robot)
        p = self._now().sensed["poses"]
        return float(p["x"][i]), float(p["y"][i]), float(p["yaw"][i])

    def alive(self, robot: int) -> bool:
        """Whether robot ``robot`` still runs (not failed, not out of battery)."""
        return bool(self._now().sensed["poses"]["alive"][self._row(robot)])

    def led(self, robot: int) -> tuple[int, int, int]:
        """Robot ``robot``'s LED colour now (RGB, 0-255)."""
        r, g, b = self._now().sensed["robot_state"]["led"][self._row(robot)]
        return int(r), int(g), int(b)

    def battery_v(self, robot: int) -> float:
        """Robot ``robot``'s battery voltage now (V)."""
        return float(self._now().sensed["robot_state"]["battery_v"][self._row(robot)])

    def distance_m(self, robot: int) -> float:
        """How far robot ``robot`` has travelled since the start (m)."""
        return float(self._now().sensed["robot_state"]["distance_m"][self._row(robot)])

    def radio(self) -> dict[str, Any]:
        """The session's radio and UWB figures so far, as ``summary.json``'s ``radio`` section will give them at the end
        (``connectivity``: the share of samples the swarm's graph was connected, λ2; ``totals``; ``per_robot``: each
        robot's frames sent, received and lost, its UWB exchanges), without the modules' own counters, which come at
        the end. Empty for a session without radios."""
        return self._now().sensed.get("radio") or {}

    def pins(self, robot: int, board: str = "llc") -> dict[str, Any]:
        """Robot ``robot``'s board ``board`` as its pins stood at its last loop: what it read (encoders, sonar, light,
        battery) and what it wrote (PWM, LED), as the recording's ``/rNNN/<board>/pins`` has it. Empty before its
        first loop, or for a board the robot does not have."""
        self._row(robot)
        return dict(self._pins.get((robot, board), (0.0, {}))[1])

    def llc(self, robot: int) -> dict[str, Any]:
        """Robot ``robot``'s low-level controller's state: its pins at its last loop (``pins(robot, "llc")``)."""
        return self.pins(robot, "llc")

    def logs(self, robot: int | None = None, topic: str | None = None) -> list[LogLine]:
        """The log records so far (the robots' ``robot.log``, the services' logs, the session's events as topic
        ``events``), in recording order; only robot ``robot``'s, or only topic ``topic``'s, when given."""
        self._now()
        if robot is not None:
            self.touched.add(robot)
        return [ln for ln in self._log if (robot is None or ln.robot == robot) and (topic is None or ln.topic == topic)]

    def events(self) -> list[LogLine]:
        """The session's events so far (failures, a stop)."""
        return [ln for ln in self._log if ln.source == "session"]

    def describe(self, lines: int = 5) -> str:
        """Where the session stands, for a failing test's report: the simulated time, the recording, and the last log
        lines of the robots the test touched (of every robot if it touched none)."""
        where = f"t={self._seen.t_ns / 1e9:.3f} s" if self._seen is not None else "not started"
        out = [f"swarm-sitl session {self.config} at simulated {where}" + (" (ended)" if self._ended else ""),
               f"recording: {self.recording}"]
        robots = sorted(self.touched) or sorted({ln.robot for ln in self._log if ln.robot is not None})
        for r in robots:
            mine = [ln for ln in self._log if ln.robot == r][-lines:]
            out.append(f"robot {r}, last {len(mine)} log lines:" if mine else f"robot {r}: no log line")
            out += [f"  {ln}" for ln in mine]
        if events := self.events():
            out.append("session events:")
            out += [f"  {ln}" for ln in events[-lines:]]
        return "\n".join(out)

    # -- internals ----------------------------------------------------------------------------------------------
    def _row(self, robot: int) -> int:
        try:
            i = self._ids.index(robot)
        except ValueError:
            raise KeyError(f"no robot {robot} in this session (robots {self._ids})") from None
        self.touched.add(robot)
        return i

    def _now(self) -> Seen:
        if self._seen is None:
            raise RuntimeError("the session is not started: call start() or use it in a with block")
        return self._seen

    def _go(self, wake_ns: int) -> None:
        if self._ended:
            raise SessionEnded(self._why_ended())
        out, self._pending = self._pending, []
        self._running = True
        self._channel.commands.put(Go(wake_ns, out))
        self._wait()
        self._running = False

    def _wait(self) -> None:
        """Wait for the probe's next run (the world then holds), or the session's end."""
        self._take(self._channel.seen.get())
        if self._ended:
            self._thread.join() if self._thread is not None else None
            if self._error is not None:
                raise self._error
            raise SessionEnded(self._why_ended())

    def _take(self, item: Seen | Ended) -> None:
        if isinstance(item, Ended):
            self._ended = True
            return
        self._seen = item
        for t, topic, values in item.records:
            parts = topic.strip("/").split("/")
            if parts[-1] == "pins" and len(parts) == 3 and parts[0][1:].isdigit():  # /rNNN/<board>/pins
                self._pins[(int(parts[0][1:]), parts[1])] = (t / 1e9, values)
            elif topic == "/mavlink/to_gcs":
                if self._mavlink is not None:
                    self._mavlink.heard(t, int(values["robot"]), bytes.fromhex(values["data"]))
            elif topic == "/session/events":
                self._log.append(LogLine(t / 1e9, "session", "events", values))
            elif parts[0] == "svc":
                self._log.append(LogLine(t / 1e9, f"svc/{parts[1]}", parts[-1], values))
            else:
                self._log.append(LogLine(t / 1e9, parts[0], parts[-1], values))

    def _why_ended(self) -> str:
        s = self.summary or {}
        why = s.get("stop_reason") or ("it reached its duration" if s else "it is over")
        return f"the session ended ({why}); its recording: {self.recording}"


def _plan(config: str, overrides: dict[str, Any]) -> Any:
    from bridge.core.config import load_config
    from bridge.core.plan import make_plan

    return make_plan(load_config(config, overrides), config)



class MavlinkHandle:
    """A test's ground station: ``mav`` encodes and sends (``handle.mav.command_long_send(...)``, pymavlink's MAVLink 2
    encoder, system 255), ``messages``/``last`` read what the robots' faces sent, decoded, with their robot and
    simulated time. ``system_id(robot)`` is the robot's MAVLink system id."""

    def __init__(self, session: SwarmSession, system_id_base: int) -> None:
        import os

        os.environ.setdefault("MAVLINK20", "1")
        from pymavlink.dialects.v20 import common as mavlink2

        self.session = session
        self.base = system_id_base
        self.mav = mavlink2.MAVLink(self, srcSystem=255, srcComponent=190)
        self._mavlink2 = mavlink2
        self._parsers: dict[int, Any] = {}
        self.received: list[tuple[float, int, Any]] = []  # (t s, robot, message), in the order the faces sent them

    def system_id(self, robot: int) -> int:
        return self.base + robot

    def write(self, buf: bytes) -> None:
        """pymavlink's file interface: the encoded packet goes with the probe's next answer."""
        self.session._pending.append(["mavlink", bytes(buf)])

    def heard(self, t_ns: int, robot: int, data: bytes) -> None:
        parser = self._parsers.get(robot)
        if parser is None:
            parser = self._parsers[robot] = self._mavlink2.MAVLink(None)
            parser.robust_parsing = True
        for msg in parser.parse_buffer(data) or ():
            if msg.get_type() != "BAD_DATA":
                self.received.append((t_ns / 1e9, robot, msg))

    def messages(self, type: str | None = None, robot: int | None = None) -> list[Any]:
        """The decoded messages the faces sent so far, of ``type`` (``"HEARTBEAT"``) and from ``robot`` if given."""
        if robot is not None:
            self.session.touched.add(robot)
        return [m for _, r, m in self.received if (type is None or m.get_type() == type) and
                (robot is None or r == robot)]

    def last(self, type: str, robot: int) -> Any | None:
        """The newest ``type`` message robot ``robot``'s face sent, or None."""
        found = self.messages(type, robot)
        return found[-1] if found else None
