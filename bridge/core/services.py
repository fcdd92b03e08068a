"""Services: a session's centralised programs (a localisation service behind an overhead camera, a global
controller on a PC), each in a process of its own, lock-stepped like a robot's firmware.

A config declares them as ``[[services]]`` (``kind``, ``name``, ``options``); a kind comes from a plugin (entry point
group ``swarm_sitl.services``: a ``ServiceSpec``). The launcher starts one process per service (``svc-<name>``,
``bridge.hosts.service``), whose one entity is ``svc/<name>``. Its inputs are the datagrams the session's Wi-Fi
network (``bridge.media.wifi``) delivers to it (address: its name) and the ground truth its kind is entitled to
(``ServiceSpec.senses``, from ``SENSES``: a camera sees every robot's true pose); its outputs are datagrams and log
records (``Service.log``, recorded under ``/svc/<name>/log/<topic>``). At the end its ``summary()`` becomes its entry
in ``summary.json``'s ``services``.

The core knows no service kind: this module gives the contract, the hub and the service host carry it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict

from bridge.core.rng import stream

if TYPE_CHECKING:
    import numpy as np

    from bridge.core.config import Config

SERVICE_ROLE = "service"


def service_entity(name: str) -> str:
    """The entity id of service ``name`` (``svc/camera``)."""
    return f"svc/{name}"


def service_proc(name: str) -> str:
    """The process name of service ``name`` (``svc-camera``)."""
    return f"svc-{name}"


class ServiceOptions(BaseModel):
    """Base of a service kind's options (``[[services]].options``): unknown fields are refused."""

    model_config = ConfigDict(extra="forbid")


def _poses(world: Any, robots: list[int]) -> dict[str, Any]:
    """Every robot's true pose in the world frame and whether it is alive (a tracking system's ground truth)."""
    return {
        "x": [float(world.pos[r, 0]) for r in robots],
        "y": [float(world.pos[r, 1]) for r in robots],
        "yaw": [float(world.yaw[r]) for r in robots],
        "alive": [bool(world.alive[r]) for r in robots],
    }


def _robot_state(world: Any, robots: list[int]) -> dict[str, Any]:
    """What an observer of the arena sees of each robot besides its pose: its LED colour (RGB), its battery voltage
    and how far it has travelled (its odometer, m)."""
    return {
        "led": [world.led[r].tolist() for r in robots],
        "battery_v": [float(world.battery_v[r]) for r in robots],
        "distance_m": [float(world.odometer[r]) for r in robots],
    }


# what a service kind may be entitled to sense of the world, by name: (world, robot ids) -> the values
SENSES: dict[str, Callable[[Any, list[int]], dict[str, Any]]] = {"poses": _poses, "robot_state": _robot_state}
# and of the session as the world process keeps it: "radio", the radio and UWB figures so far (``summary.json``'s
# ``radio`` section as it stands: the media's counters and the connectivity; the modules' own counters come at the end)
SESSION_SENSES = ("radio",)


@dataclass(frozen=True)
class RobotInfo:
    """What a service knows of a robot from the session's plan: its id, Wi-Fi address, model and body."""

    id: int
    address: str
    profile: str
    radius_m: float
    height_m: float
    length_m: float | None  # a box body: along the heading (None: a cylinder)
    width_m: float | None
    marker_radius_m: float | None = None  # the marker on its top for an overhead camera, if its profile has one


@dataclass
class ServiceContext:
    """What a service is built with: its name and validated options, the session's config and robots, the quantum,
    and its own seeded random streams."""

    name: str
    options: Any
    config: Config
    robots: list[RobotInfo]
    q_ns: int
    seed: int

    def rng(self, *keys: object) -> np.random.Generator:
        """A random stream of this service's own (``rng.stream(seed, "service", name, *keys)``)."""
        return stream(self.seed, "service", self.name, *keys)


class Service:
    """Base of a service: override ``step`` (and ``summary``, ``close``); send with ``send``, record with ``log``.

    ``step(t_ns, datagrams, sensed)`` runs when the service is due: at the wake time it returned last (None: never
    again by itself), or, with ``wake_on_datagram``, when a datagram arrives (otherwise datagrams wait in its inbox
    until it runs anyway). ``datagrams`` are ``(src, data)`` in arrival order; ``sensed`` holds what its kind's
    ``senses`` name. Whatever it sends leaves at the end of the quantum."""

    wake_on_datagram = False

    def __init__(self, ctx: ServiceContext) -> None:
        self.ctx = ctx
        self._out: list[list[Any]] = []

    def send(self, data: bytes, dest: str | None = None) -> None:
        """A datagram to ``dest`` (a robot's ``rNNN``, another service's name) or, with None, to every node."""
        self._out.append(["wifi", dest, bytes(data)])

    def log(self, topic: str, values: dict[str, Any], schema: str | None = None) -> None:
        """A record under ``/svc/<name>/log/<topic>`` (plain JSON values), recorded with ``schema`` when given: a
        schema the world knows (``recorder.register_schema`` in a module its kind imports, as a scene a viewer
        draws), else the generic log schema."""
        self._out.append(["log", topic, values] if schema is None else ["log", topic, values, schema])

    def stop_session(self, reason: str) -> None:
        """End the session after this quantum, as at its duration's end (recorded as a ``stopped`` event)."""
        self._out.append(["stop", str(reason)])

    def on_record(self, t_ns: int, topic: str, values: Any) -> None:
        """A record its kind hears (``ServiceSpec.hears``), before the ``step`` of its next run, in recording order."""

    def step(self, t_ns: int, datagrams: list[tuple[str, bytes]], sensed: dict[str, Any]) -> int | None:
        """Run at ``t_ns``; returns the next wake time (ns) or None."""
        return None

    def summary(self) -> dict[str, Any]:
        """Its entry in ``summary.json``'s ``services`` (its own figures)."""
        return {}

    def close(self) -> None:
        """Release what it holds (a rendering client)."""

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        """One tick, as the service host calls it: the inputs unpacked for ``step``, the outputs packed."""
        datagrams = []
        for item in inputs.get("in", ()):
            if item[0] == "wifi":
                datagrams.append((item[1][0], item[1][1]))
            elif item[0] == "rec":
                self.on_record(item[1], item[2], item[3])
        wake = self.step(t_ns, datagrams, inputs.get("sens") or {})
        out, self._out = self._out, []
        return {"out": out, "wake": wake, "wom": ["wifi"] if self.wake_on_datagram else False}  # records never wake it


@dataclass(frozen=True)
class ServiceSpec:
    """A service kind: its options (a ``ServiceOptions`` model), what it builds (``make(ctx) -> Service``) and what
    of the world it senses each time it runs (names in ``SENSES``)."""

    name: str
    make: Callable[[ServiceContext], Service]
    options: type[BaseModel] = ServiceOptions
    senses: tuple[str, ...] = ()
    title: str = ""
    # the records it hears as they are written (``Service.on_record``): topic patterns (fnmatch), e.g. the robots'
    # logs ``/r*/log/*`` and the session's events ``/session/events``
    hears: tuple[str, ...] = ()
    # topics of which it hears only the newest record at each run (a board's pins, written at its loop rate)
    hears_latest: tuple[str, ...] = ()
    # checks against the whole config once it is valid (an option naming a robot the session lacks): (options,
    # config) -> None, raising ValueError naming the option
    check: Callable[[Any, Any], None] | None = field(default=None)

    def __post_init__(self) -> None:
        known = {*SENSES, *SESSION_SENSES}
        unknown = sorted(set(self.senses) - known)
        if unknown:
            from swarm_logic.plugins import PluginError

            raise PluginError(f"service {self.name!r}: cannot sense {unknown}; a service senses {sorted(known)}")
