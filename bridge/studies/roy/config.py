"""The roy study's config sections, apart from its loop functions (every process of a session reads the config; only
the world runs the loop functions, and their metrics' imports cost each process a third of a second)."""

from __future__ import annotations

import itertools

from pydantic import Field, field_validator

from bridge.core.config import Section


class PhaseCfg(Section):
    """One stretch of the route: its name, and where it ends (none: at arrival, the last phase)."""

    name: str = Field(min_length=1)
    until_dist_m: float | None = Field(None, gt=0, description="the phase ends when the centroid first comes this "
                                                               "near T (m); none: at arrival")


class FormationCfg(Section):
    """``[formation]``: how a chapter 3 session is scored and when it ends."""

    target: tuple[float, float] = Field(description="T (m, world frame)")
    r_s_m: float = Field(0.113, gt=0, description="r_s (m): the hardware's 11.3 cm (digest §4.5.4)")
    goal_tol_m: float = Field(0.1, gt=0, description="the centroid's arrival radius (m; 1 unit, digest §5.5)")
    sample_s: float = Field(1.0, gt=0, le=60, description="the sampling step of FE and the arrival test")
    end_after_arrival_s: float | None = Field(0.0, ge=0, description="end the session this long after the swarm "
                                                                     "arrives (none: run to duration_s)")
    end_on_event: str | None = Field(None, pattern=r"^[A-Za-z_][A-Za-z0-9_-]*/[A-Za-z_][A-Za-z0-9_]*$",
                                     description="SERVICE/KIND: end the session when service SERVICE logs an event "
                                                 "of this kind (a region controller's 'controller/done'); the "
                                                 "swarm's arrival then ends nothing")
    end_after_event_s: float = Field(1.0, ge=0, description="... this long after that event")
    phases: list[PhaseCfg] = Field(default_factory=list, description="the route's phases in order, each scored "
                                                                      "apart; only the last may end at arrival")

    @field_validator("phases")
    @classmethod
    def _phases_in_order(cls, v: list[PhaseCfg]) -> list[PhaseCfg]:
        ends = [p.until_dist_m for p in v]
        if any(e is None for e in ends[:-1]):
            raise ValueError("only the last phase may leave out until_dist_m (it ends at arrival)")
        dist = [e for e in ends if e is not None]
        if any(b >= a for a, b in itertools.pairwise(dist)):
            raise ValueError(f"until_dist_m must fall from phase to phase (nearer T each time), got {dist}")
        return v
