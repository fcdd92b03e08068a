"""What a session can be made of, found by name: robots, media, services and studies (swarm behaviours are found the
same way on the robot's side, ``swarm_logic.behaviours``).

Every plugin, swarm-sitl's own included, comes from an entry point of an installed package (``pyproject.toml``:
``[project.entry-points."swarm_sitl.robots"]`` and so on) or from a ``register_*`` call in the process; ``swarm-sitl
list`` shows what was found. The core imports none of them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel

from swarm_logic.plugins import PluginError, Registry, load_ref

if TYPE_CHECKING:
    from bridge.core.loop_functions import LoopFunctions
    from bridge.core.medium import Medium
    from bridge.core.profile import RobotProfile
    from bridge.core.services import ServiceSpec

__all__ = [
    "MEDIA",
    "PREFLIGHT",
    "ROBOTS",
    "SERVICES",
    "STUDIES",
    "PluginError",
    "RobotSpec",
    "Study",
    "default_robot",
    "register_medium",
    "register_robot",
    "register_study",
    "robot_profile",
    "robot_spec",
]


@dataclass(frozen=True)
class RobotSpec:
    """A robot model: its body, battery and firmware figures and its parts (``profile``), the interface its boards
    speak on the robot's CAN bus (``can_db``: a function returning its cantools database, for names in the
    recording), its LLC's firmware (``board``), that board's wiring in the world (``pins``), and the options a
    robot group of this model may set in a session config (``options``: a pydantic model of the extra group
    fields; ``configure(profile, options)`` returns the profile they make)."""

    name: str
    profile: RobotProfile
    can_db: Callable[[], Any] | None = None
    title: str = ""
    # its LLC's firmware: (profile, the robot's plan entry) -> an object whose ``run(t_ns, inputs)`` answers a tick
    board: Callable[[RobotProfile, Any], Any] | None = None
    # what that board's pins meet in the world: ``sense(world, r, media, ideal_pose)``, ``valid(pins)``,
    # ``actuate(world, r, pins)`` (the hub asks it each tick)
    pins: Any = None
    options: type[BaseModel] | None = None
    configure: Callable[[RobotProfile, Any], RobotProfile] | None = None
    default: bool = False  # the model a robot group without ``profile`` gets (one installed robot says so)
    # its own firmware entities beyond the LLC and the shared modules (XBee, UWB, slcan adapter): ``roles(rp)``
    # names them for robot ``rp`` (a hexapod's six leg modules), ``modules(rp, cfg)`` builds them in the firmware host
    # (role -> an object whose ``run(t_ns, inputs)`` answers a tick as a board's does; ``counters`` and ``close()``
    # when it has them)
    roles: Callable[[Any], tuple[str, ...]] | None = None
    modules: Callable[[Any, Any], dict[str, Any]] | None = None
    # what its own modules' pins meet in the world: role -> a wiring as ``pins`` is (``sense``, ``valid``,
    # ``actuate``, ``schema``), None for a module without pins (a radio)
    wiring: Callable[[str], Any] | None = None
    # robot-group fields that do not apply to this model, with why (a legged robot given an LLC's or a wheeled
    # robot's options): field -> reason; a config that sets one is refused naming it
    refuses: dict[str, str] = field(default_factory=dict)
    # the HAL tables its robot program gets in a session beyond the shared ones: (rp, cfg) -> {table: settings}
    hal: Callable[[Any, Any], dict[str, Any]] | None = None
    # its own modules that the robot's computer reaches over a serial line (the program opens ``sitl://ROLE``, paced
    # by the ``uart`` medium as the XBee's line is): role -> the module's UART rate (bit/s)
    ports: dict[str, int] = field(default_factory=dict)
    # what a program outside the session needs to be the robot's logic (``logic = "external"``): the group fields that
    # put the robot's devices on ports it can open (dotted as a config names them: ``can.slcan_pty``, a model option
    # ``i2c_pty``) -> why and how to set it; a group with an external logic that leaves one unset is refused naming it
    external_ports: dict[str, str] = field(default_factory=dict)
    # its own firmware entities that are nodes on the robot's CAN bus beside the LLC (a range-and-bearing board that
    # reports on the bus the base board shares): they offer and receive ``can0`` items as the LLC does
    can_roles: tuple[str, ...] = ()
    # the HAL table under which its robot program opens the robot's CAN bus in a session (given python-can's
    # arguments for the simulated bus): ``llc_can``, the LLC client of ``swarm_logic.devices``, or a device of the
    # model's own that speaks its boards' protocol (a foot-bot's ``footbot_can``)
    can_hal: str = "llc_can"

    def __post_init__(self) -> None:
        if (self.board is None) != (self.pins is None):
            raise PluginError(f"robot {self.name!r}: an LLC firmware (board) and its wiring (pins) go together")
        if (self.options is None) != (self.configure is None):
            raise PluginError(f"robot {self.name!r}: config options and what they configure go together")
        if (self.roles is None) != (self.modules is None):
            raise PluginError(f"robot {self.name!r}: its firmware entities' roles and their modules go together")
        if self.ports and self.roles is None:
            raise PluginError(f"robot {self.name!r}: serial ports belong to its own firmware entities (roles)")
        if self.can_roles and self.roles is None:
            raise PluginError(f"robot {self.name!r}: CAN nodes of its own are its own firmware entities (roles)")

    @property
    def has_can(self) -> bool:
        """Its boards talk on a CAN bus (an LLC, a CAN interface): the companion computer is a node of it."""
        return self.board is not None or self.can_db is not None or bool(self.can_roles)

    def own_roles(self, rp: Any) -> tuple[str, ...]:
        """The roles of robot ``rp``'s own firmware entities (none for most robots)."""
        return () if self.roles is None else tuple(self.roles(rp))

    def own_ports(self, rp: Any) -> dict[str, int]:
        """Robot ``rp``'s own modules on a serial line to its computer, with their rates (role -> bit/s)."""
        roles = set(self.own_roles(rp))
        return {role: baud for role, baud in self.ports.items() if role in roles}

    def make_modules(self, rp: Any, cfg: Any) -> dict[str, Any]:
        """Robot ``rp``'s own firmware entities, by role, as the firmware host runs them."""
        return {} if self.modules is None else dict(self.modules(rp, cfg))

    def profile_with(self, options: dict[str, Any] | None) -> RobotProfile:
        """The profile a group's options make (its own figures without any)."""
        if not options or self.configure is None or self.options is None:
            return self.profile
        return self.configure(self.profile, self.options.model_validate(options))

    def make_board(self, rp: Any) -> Any:
        """The firmware of robot ``rp``'s low-level controller, as the firmware host runs it."""
        if self.board is None:
            raise PluginError(f"robot {self.name!r} declares no LLC firmware (RobotSpec.board)")
        return self.board(self.profile_with(rp.options), rp)

    def frame_names(self) -> dict[int, str]:
        """CAN id -> frame name, from the robot's DBC (empty without one)."""
        return {} if self.can_db is None else {m.frame_id: m.name for m in self.can_db().messages}


@dataclass(frozen=True)
class Study:
    """A study's simulation side: its experiments (modules that register them when imported), the loop functions its
    sessions run, where its session configs are, and its benchmark."""

    name: str
    title: str
    experiments: tuple[str, ...] = ()
    # its loop functions: the class, or "module:Class" (imported by the world only, when it builds them: the other
    # processes of a session read the study's config sections, not its metrics)
    loop_functions: type[LoopFunctions] | str | None = None
    configs: str = ""  # its session configs, relative to the repository
    sections: tuple[str, ...] = field(default=())  # the summary.json sections its loop functions write
    # its own top-level config sections: name -> their type (a pydantic model, or e.g. list[Model] for [[name]])
    config: dict[str, Any] = field(default_factory=dict)
    # checks across sections once a config is whole (a particle inside an obstacle): (config) -> None, raising
    # ValueError naming the field; run when the config has one of its sections or a robot group runs one of its
    # ``behaviours``
    check: Callable[[Any], None] | None = None
    behaviours: tuple[str, ...] = ()  # the behaviours whose groups its check covers (a target inside an obstacle)
    # its speed figures for ``swarm-sitl bench --study NAME``: "module:function", called as
    # function(quick=bool, duration=float | None, out_dir=str) -> exit code (imported only when asked for)
    bench: str = ""

    def loop_functions_class(self) -> type[LoopFunctions] | None:
        """The study's loop functions class, importing it if named by reference."""
        lf = self.loop_functions
        return load_ref(lf) if isinstance(lf, str) else lf


def _is_medium(obj: Any) -> bool:
    from bridge.core.medium import Medium

    return isinstance(obj, type) and issubclass(obj, Medium)


Preflight = Callable[[Any, str], None]  # (config, its path): raise ConfigError naming the field if it cannot start

ROBOTS: Registry[RobotSpec] = Registry("swarm_sitl.robots", "robot", lambda o: isinstance(o, RobotSpec))
MEDIA: Registry[type[Medium]] = Registry("swarm_sitl.media", "medium", _is_medium)
STUDIES: Registry[Study] = Registry("swarm_sitl.studies", "study", lambda o: isinstance(o, Study))
def _is_service(obj: Any) -> bool:
    from bridge.core.services import ServiceSpec

    return isinstance(obj, ServiceSpec)


SERVICES: Registry[ServiceSpec] = Registry("swarm_sitl.services", "service", _is_service)
# checks the launcher runs before it starts anything (the hardware bridges: does each real device answer?)
PREFLIGHT: Registry[Preflight] = Registry("swarm_sitl.preflight", "preflight check", callable)


def register_robot(spec: RobotSpec) -> RobotSpec:
    return ROBOTS.register(spec.name, spec)


def register_medium(cls: type[Medium]) -> type[Medium]:
    return MEDIA.register(cls.name, cls)


def register_study(study: Study) -> Study:
    return STUDIES.register(study.name, study)


def robot_spec(name: str) -> RobotSpec:
    return ROBOTS.get(name)


def default_robot() -> str:
    """The robot model a group that names none gets: the one whose plugin declares itself the default."""
    names = [name for name, spec in ROBOTS.items() if spec.default]
    if len(names) != 1:
        raise PluginError(f"robot groups must name their profile: {len(names)} installed robot plugins declare "
                          f"themselves the default ({', '.join(names) or 'none'})")
    return names[0]


def robot_profile(name: str, options: dict[str, Any] | None = None) -> RobotProfile:
    """The profile of robot model ``name`` with a group's ``options`` (a ``PluginError`` names the models there
    are)."""
    return ROBOTS.get(name).profile_with(options)
