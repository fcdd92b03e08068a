"""The controller API, in the spirit of ARGoS: ``init`` / ``step`` / ``reset`` / ``destroy``.

A controller sees only its ``Robot`` (devices, clock, parameters, random stream); it knows nothing of
the simulator. The runner calls ``step()`` every ``period_s`` of the robot's clock.

Two hooks serve a ground station (``swarm_logic.mavlink.face``): ``set_param`` changes a parameter while the robot
runs, ``telemetry`` names a few numbers of the behaviour's state.

Parameters are declared once, on the class: ``defaults`` (name -> default; an int default makes an integer parameter),
``ranges`` (name -> the interval its values must lie in, e.g. ``"(0, 2]"``) and ``choices`` (name -> the readings a
string parameter may take). ``param_error`` checks a value against them, and everything that takes a parameter uses
it: ``with_defaults`` (so a controller's ``init`` and ``resolve``), ``set_param``, a session config's validation
(``bridge.core.config``) and the MAVLink face's PARAM_SET. A controller's ``resolve`` checks only what one range
cannot say (one parameter against another).
"""

from __future__ import annotations

import math
import numbers
import re
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    from swarm_logic.robot import Robot

# what DRIVE_CMD can carry (eswarbot_llc.dbc: v_mm_s within +/-2000, w_mrad_s within +/-20000); the LLCs cap lower
MAX_SPEED_MPS = 2.0
MAX_TURN_RATE_RPS = 20.0
DBM_RANGE = "[-128, 0]"  # an RSSI threshold, dBm (RADIO_RSSI's rssi_dbm; an XBee reads -40 to -100)

_INTERVAL = re.compile(r"\s*([\[(])\s*([^,\s]+)\s*,\s*([^\])\s]+)\s*([\])])\s*")


@dataclass(frozen=True)
class Range:
    """The values a numeric parameter may take: ``lo`` to ``hi``, each end included unless open. NaN is never in
    a range, an infinity only at a closed infinite end."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False

    @classmethod
    def parse(cls, text: str) -> Range:
        """An interval in the usual notation: ``"[0, 2]"``, ``"(0, inf)"``, ``"[-128, 0]"``, ``"(0, inf]"``."""
        m = _INTERVAL.fullmatch(text)
        try:
            lo, hi = float(m[2]), float(m[3])  # type: ignore[index]
        except (TypeError, ValueError):
            raise ValueError(f"{text!r} is not an interval such as '(0, 2]'") from None
        if not lo <= hi:
            raise ValueError(f"{text!r}: the lower end exceeds the upper end")
        return cls(lo, hi, m[1] == "(", m[4] == ")")  # type: ignore[index]

    def __contains__(self, v: float) -> bool:
        return (v > self.lo if self.lo_open else v >= self.lo) and (v < self.hi if self.hi_open else v <= self.hi)

    def phrase(self) -> str:
        """What a value must be: "lie in [0, 2]", "be > 0", "be finite"."""
        lo_free, hi_free = self.lo == -math.inf and self.lo_open, self.hi == math.inf and self.hi_open
        if lo_free and hi_free:
            return "be finite"
        if hi_free:
            return f"be {'>' if self.lo_open else '>='} {self.lo:g}"
        if lo_free:
            return f"be {'<' if self.hi_open else '<='} {self.hi:g}"
        return f"lie in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"


class Controller(ABC):
    period_s: float = 0.1
    defaults: ClassVar[dict[str, Any]] = {}  # parameters and their defaults: configs are checked against them
    # the log topic of its one record per iteration (k, sid, improved, x, y): what the numerical runner scores
    # (subgroups, exclusions, ruptures); None for a controller without iterations
    iteration_log: ClassVar[str | None] = None
    # the numeric parameters' ranges, in interval notation ("(0, 2]"); made ``Range``s when the class is defined
    ranges: ClassVar[Mapping[str, str | Range]] = {}
    # the string parameters' allowed values (a thesis' readings of an ambiguity: "literal", "repaired", ...)
    choices: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    # parameters read only by ``init``: ``set_param`` stores them for the next start (a reboot) and no sooner
    static_params: ClassVar[frozenset[str]] = frozenset()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Parse the class's ``ranges``; a range for no parameter, or a default outside its range, is a TypeError."""
        super().__init_subclass__(**kwargs)
        ranges = {name: r if isinstance(r, Range) else Range.parse(r) for name, r in cls.ranges.items()}
        cls.ranges = ranges
        for name in ranges:
            if name not in cls.defaults:
                raise TypeError(f"{cls.__name__}.ranges: {name!r} is not one of its parameters")
            error = cls.param_error(name, cls.defaults[name])
            if error is not None:
                raise TypeError(f"{cls.__name__}.defaults: {name} = {cls.defaults[name]!r}: {error}")
        for name in cls.choices:
            if name not in cls.defaults:
                raise TypeError(f"{cls.__name__}.choices: {name!r} is not one of its parameters")
            error = cls.param_error(name, cls.defaults[name])
            if error is not None:
                raise TypeError(f"{cls.__name__}.defaults: {name} = {cls.defaults[name]!r}: {error}")

    def init(self, robot: Robot) -> None:
        self.robot = robot

    @classmethod
    def param_error(cls, name: str, value: Any) -> str | None:
        """Why ``value`` cannot be numeric parameter ``name``: not a number, not an integer where the default is one,
        outside the parameter's declared range, not one of its ``choices``; None when it can (and for names that are
        neither)."""
        allowed = cls.choices.get(name)
        if allowed is not None:
            return None if value in allowed else f"expected one of {', '.join(allowed)}, got {value!r}"
        default = cls.defaults.get(name)
        if isinstance(default, bool) or not isinstance(default, int | float):
            return None  # flags, strings, lists: the controller's own checks
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return f"expected a number, got {value!r}"
        if isinstance(default, int) and not float(value).is_integer():
            return f"must be an integer, got {value!r}"
        r = cls.ranges.get(name)
        if isinstance(r, Range) and value not in r:
            return f"must {r.phrase()}, got {value!r}"
        return None

    @classmethod
    def with_defaults(cls, params: dict[str, Any]) -> dict[str, Any]:
        """``defaults`` overlaid with ``params``; ValueError naming any parameter the controller does not have, or
        the first one with a value it cannot take (``param_error``)."""
        unknown = sorted(set(params) - set(cls.defaults))
        if unknown:
            raise ValueError(f"{cls.__name__}: unknown parameters {unknown}; known: {sorted(cls.defaults)}")
        for name, value in params.items():
            error = cls.param_error(name, value)
            if error is not None:
                raise ValueError(f"{name}: {error}")
        return {**cls.defaults, **params}

    @classmethod
    def resolve(cls, params: dict[str, Any]) -> dict[str, Any]:
        """The parameters a controller runs with: ``with_defaults``; a controller overrides it to check what one range
        or choice cannot say (one parameter against another)."""
        return cls.with_defaults(params)

    @abstractmethod
    def step(self) -> None: ...

    def reset(self) -> None:
        """Return to the state right after ``init``."""

    def destroy(self) -> None:
        """Leave the robot safe (motors stopped)."""

    def set_param(self, name: str, value: Any) -> None:
        """Change parameter ``name`` at run time: stored in ``robot.params`` (a restart keeps it) and, unless it is
        one of ``static_params``, in ``self.p`` where the controller keeps its parameters there. ValueError for an
        unknown name or a value outside the parameter's kind and range (``param_error``; overrides check what else
        they must, then call this)."""
        if name not in self.defaults:
            raise ValueError(f"unknown parameter {name!r}")
        error = self.param_error(name, value)
        if error is not None:
            raise ValueError(f"{name}: {error}")
        self.robot.params[name] = value
        p = getattr(self, "p", None)
        if isinstance(p, dict) and name not in self.static_params:
            p[name] = value

    def telemetry(self) -> dict[str, float | int]:
        """A few numbers of the behaviour's state for a ground station, by name (at most 10 characters)."""
        return {}
