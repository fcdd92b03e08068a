"""The scenarios of Roy's chapters 4-6 as versioned TOML files (``hil_configs/roy/*.toml``), validated.

The thesis' maps are lost (digest 001 §5.4): each file is a parametric look-alike built from a figure's caption, with
a ``version`` string that changes whenever the layout does. One schema covers the three chapters:

- ``[world]``: ``size`` [w, h], ``walls`` (the border as four edges), ``segments`` [[x1, y1], [x2, y2]],
  ``polygons`` (each a list of vertices, used as its edges: chapter 5's blobs and boxes), ``circles`` [x, y, r], and
  ``[[world.movers]]`` (``a``, ``b``, ``radius``, ``speed``: a circle going back and forth, chapter 6 case 3).
- ``[agents]``: ``n``, the start box ``start_lo`` .. ``start_hi``, ``min_sep``, ``v_max`` (units/s, calibrated per
  scenario, digest §5.3).
  ``RegionScenario.with_agents(n)`` is the same map with n agents (r_s scaled to keep N pi r_s^2: chapter 6's
  scaling runs).
- ``[sensing]``: ``beams`` m, ``spacing_deg`` z (m z = 360: a ring), the window ``d_min`` .. ``d_max``.
- ``[mission]``: ``targets`` (one or more [x, y]), ``lanes`` (optional: the target indices each lane visits in order,
  chapter 6), ``arrival_radius``, ``timeout_s``, ``dt`` (0.05 s, erratum 1).
- ``[failures]``: actuator failures: a ``fraction`` of the agents stop at the scheduled ``times`` (s), in turn.
- ``[metrics]``: the structural density's ``density_rule`` ("ch4", "ch5", "ch6") and its ``r_s`` (chapters 5, 6);
  ``density_pairs`` "swarm" (every pair, as printed) or "sub_swarms" (pairs within a plan's sub-swarm only).
- ``[planner]``: ``name`` (an entry point of ``swarm_sitl.region_planners``) and ``params``, its parameters.

A wrong file is a ``ConfigError`` naming the file, the field and the reason.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, ValidationError, field_validator, model_validator

from bridge.core.config import ConfigError, Section, _format, read_toml
from swarm_logic.families.roy.regions.planner import PLANNERS, RegionPlanner
from swarm_logic.plugins import PluginError

SCENARIO_DIR = Path(__file__).resolve().parents[3] / "hil_configs" / "roy"
Point = tuple[float, float]


def _finite(p: Any) -> Any:
    if not all(math.isfinite(v) for v in np.ravel(np.asarray(p, float))):
        raise ValueError("must be finite")
    return p


class MoverCfg(Section):
    a: Point
    b: Point
    radius: float = Field(gt=0)
    speed: float = Field(ge=0)


class WorldCfg(Section):
    size: Point
    walls: bool = True
    segments: list[tuple[Point, Point]] = Field(default_factory=list)
    polygons: list[list[Point]] = Field(default_factory=list)
    circles: list[tuple[float, float, float]] = Field(default_factory=list)
    movers: list[MoverCfg] = Field(default_factory=list)

    @field_validator("size")
    @classmethod
    def _size(cls, v: Point) -> Point:
        if not all(math.isfinite(s) and s > 0 for s in v):
            raise ValueError(f"must be two finite sizes > 0, got {list(v)}")
        return v

    @field_validator("segments", "polygons", "circles")
    @classmethod
    def _fin(cls, v: Any) -> Any:
        for k, item in enumerate(v):
            try:
                _finite(item)
            except ValueError:
                raise ValueError(f"item {k} must be finite, got {item}") from None
        return v

    @field_validator("polygons")
    @classmethod
    def _poly(cls, v: list[list[Point]]) -> list[list[Point]]:
        for k, poly in enumerate(v):
            if len(poly) < 3:
                raise ValueError(f"polygon {k} needs at least 3 vertices, got {len(poly)}")
        return v

    @field_validator("circles")
    @classmethod
    def _circ(cls, v: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
        for k, c in enumerate(v):
            if not c[2] > 0:
                raise ValueError(f"circle {k} needs a radius > 0, got {c[2]}")
        return v

    def edges(self) -> np.ndarray:
        """Every straight obstacle edge (G, 2, 2): the border (when ``walls``), the segments, the polygons' sides."""
        out: list[Any] = []
        w, h = self.size
        if self.walls:
            out += [((0, 0), (w, 0)), ((w, 0), (w, h)), ((w, h), (0, h)), ((0, h), (0, 0))]
        out += [tuple(s) for s in self.segments]
        for poly in self.polygons:
            out += [(poly[i], poly[(i + 1) % len(poly)]) for i in range(len(poly))]
        return np.asarray(out, float).reshape(-1, 2, 2)


class AgentsCfg(Section):
    n: int = Field(gt=0, le=100_000)
    start_lo: Point
    start_hi: Point
    min_sep: float = Field(1.0, ge=0)
    v_max: float = Field(gt=0)

    @model_validator(mode="after")
    def _box(self) -> AgentsCfg:
        if not all(lo < hi for lo, hi in zip(self.start_lo, self.start_hi, strict=True)):
            raise ValueError(
                f"start_hi: must exceed start_lo {list(self.start_lo)} on both axes, got {list(self.start_hi)}"
            )
        return self


class SensingCfg(Section):
    beams: int = Field(8, gt=0, le=360)
    spacing_deg: float = Field(45.0, gt=0, le=360)
    d_min: float = Field(0.0, ge=0)
    d_max: float = Field(5.0, gt=0)

    @model_validator(mode="after")
    def _window(self) -> SensingCfg:
        if self.d_max <= self.d_min:
            raise ValueError(f"d_max: must exceed d_min ({self.d_min}), got {self.d_max}")
        return self

    def angles(self) -> np.ndarray:
        """The beams' angles from the heading (m,): a full ring from 0 when m z = 360, else a fan centred on it."""
        z = math.radians(self.spacing_deg)
        if abs(self.beams * self.spacing_deg - 360.0) < 1e-9:
            return np.arange(self.beams) * z
        return (np.arange(self.beams) - (self.beams - 1) / 2.0) * z


class MissionCfg(Section):
    targets: list[Point] = Field(min_length=1)
    lanes: list[list[int]] = Field(default_factory=list)
    arrival_radius: float = Field(gt=0)
    timeout_s: float = Field(gt=0, le=100_000)
    dt: float = Field(0.05, gt=0, le=1)

    @model_validator(mode="after")
    def _lanes(self) -> MissionCfg:
        for k, lane in enumerate(self.lanes):
            bad = [i for i in lane if not 0 <= i < len(self.targets)]
            if not lane or bad:
                raise ValueError(f"lanes: lane {k} must list target indices 0..{len(self.targets) - 1}, got {lane}")
        return self


class FailuresCfg(Section):
    fraction: float = Field(0.0, ge=0, le=1)
    times: list[float] = Field(default_factory=list)

    @model_validator(mode="after")
    def _times(self) -> FailuresCfg:
        if any(not (math.isfinite(t) and t >= 0) for t in self.times):
            raise ValueError(f"times: must be finite and >= 0, got {self.times}")
        if self.fraction > 0 and not self.times:
            raise ValueError("times: a failure fraction > 0 needs at least one scheduled time")
        return self


class MetricsCfg(Section):
    density_rule: Literal["ch4", "ch5", "ch6"] = "ch4"
    r_s: float = Field(1.0, gt=0)
    density_pairs: Literal["swarm", "sub_swarms"] = "swarm"


class PlannerCfg(Section):
    name: str
    params: dict[str, Any] = Field(default_factory=dict)


class RegionScenario(Section):
    """One scenario file, validated (see the module's docstring for the schema)."""

    name: str = Field(min_length=1)
    version: str = Field(min_length=1)
    description: str = ""
    world: WorldCfg
    agents: AgentsCfg
    sensing: SensingCfg = SensingCfg()
    mission: MissionCfg
    failures: FailuresCfg = FailuresCfg()
    metrics: MetricsCfg = MetricsCfg()
    planner: PlannerCfg

    @model_validator(mode="after")
    def _inside(self) -> RegionScenario:
        w, h = self.world.size
        for k, t in enumerate(self.mission.targets):
            if not (0 < t[0] < w and 0 < t[1] < h):
                raise ValueError(f"mission.targets: target {k} {list(t)} lies outside the world 0..{w} x 0..{h}")
        lo, hi = self.agents.start_lo, self.agents.start_hi
        if not (lo[0] >= 0 and lo[1] >= 0 and hi[0] <= w and hi[1] <= h):
            raise ValueError(f"agents.start_hi: the start box {list(lo)}..{list(hi)} leaves the world {w} x {h}")
        return self

    def with_failures(self, fraction: float) -> RegionScenario:
        """The same scenario with ``fraction`` of the agents failing at its scheduled times."""
        if not 0 <= fraction <= 1:
            raise ValueError(f"failures.fraction: must lie in [0, 1], got {fraction}")
        if fraction > 0 and not self.failures.times:
            raise ValueError(f"failures.times: {self.name} schedules no failure time")
        return self.model_copy(update={"failures": FailuresCfg(fraction=fraction, times=self.failures.times)})

    def with_v_max(self, v_max: float) -> RegionScenario:
        """The same scenario with the agents' speed limit ``v_max`` (units/s)."""
        if not (math.isfinite(v_max) and v_max > 0):
            raise ValueError(f"agents.v_max: must be finite and > 0, got {v_max}")
        return self.model_copy(update={"agents": self.agents.model_copy(update={"v_max": v_max})})

    def with_agents(self, n: int) -> RegionScenario:
        """The same map with ``n`` agents (the scaling runs of chapter 6, targets C7, C8). The swarm's total area
        N pi r_s^2 is kept, so that any N fits the map and the lanes: r_s (the planner's and the metrics'), the
        planner's ``r_robot`` and the agents' ``min_sep`` scale by sqrt(n0 / n). Thresholds given in the file in
        units (the detector's, ``bin_width``) stay as they are: the lanes keep their widths."""
        if not (isinstance(n, int) and 0 < n <= 100_000):
            raise ValueError(f"agents.n: must be an integer in 1..100000, got {n!r}")
        f = math.sqrt(self.agents.n / n)
        params = dict(self.planner.params)
        for key in ("r_s", "r_robot"):
            if key in params:
                params[key] = params[key] * f
        return self.model_copy(
            update={
                "agents": self.agents.model_copy(update={"n": n, "min_sep": self.agents.min_sep * f}),
                "metrics": self.metrics.model_copy(update={"r_s": self.metrics.r_s * f}),
                "planner": self.planner.model_copy(update={"params": params}),
            }
        )


def planner_params(scenario: RegionScenario) -> dict[str, Any]:
    """The keyword arguments the scenario's planner is built with: what the scenario fixes (``v_max``, ``d_min``,
    ``d_max``; with several targets ``targets``, and with ``lanes`` the ``lane_map`` of each lane's last target; for
    a planner whose ``Params`` has such fields) overridden by ``[planner] params`` (a planner window narrower than
    the sonar's reach, for one). A ValueError names an unknown parameter."""
    cls = PLANNERS.get(scenario.planner.name)
    names = {f.name for f in dataclasses.fields(cls.Params)} if hasattr(cls, "Params") else None
    if names is not None:
        unknown = sorted(set(scenario.planner.params) - names)
        if unknown:
            raise ValueError(f"{unknown[0]}: not a parameter of planner {scenario.planner.name!r}")
    facts: dict[str, Any] = {
        "v_max": scenario.agents.v_max,
        "d_min": scenario.sensing.d_min,
        "d_max": scenario.sensing.d_max,
    }
    mission = scenario.mission
    if len(mission.targets) > 1:
        facts["targets"] = [list(t) for t in mission.targets]
    if mission.lanes:
        facts["lane_map"] = [lane[-1] for lane in mission.lanes]
    kw = {k: v for k, v in facts.items() if names is not None and k in names}
    return kw | dict(scenario.planner.params)


def make_planner(scenario: RegionScenario) -> RegionPlanner:
    """A fresh planner for ``scenario`` (its ``[planner]`` table: a name of ``swarm_sitl.region_planners`` or
    ``module:Class``, built with ``planner_params``)."""
    return PLANNERS.get(scenario.planner.name)(**planner_params(scenario))


def load_scenario(path: str | Path) -> RegionScenario:
    """Read and validate a scenario file (a name without a path or suffix is looked up among the shipped ones)."""
    p = Path(path)
    if p.suffix != ".toml" and not p.exists():
        p = SCENARIO_DIR / f"{p.name}.toml"
    raw = read_toml(p, "scenario")
    try:
        sc = RegionScenario.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(_format(str(p), e)) from None
    try:
        PLANNERS.get(sc.planner.name)
    except PluginError as e:
        raise ConfigError(f"{p}: planner.name: {e}") from None
    try:
        make_planner(sc)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{p}: planner.params.{e}") from None
    return sc
