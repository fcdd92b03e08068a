"""The pfsm study's config section, apart from its loop functions (every process of a session reads the config; only
the world runs the loop functions)."""

from __future__ import annotations

from pydantic import Field

from bridge.core.config import Section


class SearchCfg(Section):
    """``[search]``: how a PFSM session is scored and when it ends."""

    tick_s: float = Field(0.1, gt=0, le=10, description="the energy's sampling step (ARGoS's control step)")
    end_after_found_s: float | None = Field(0.0, ge=0, description="end the session this long after the last "
                                                                    "target is found (none: run to duration_s)")
    area_m2: float | None = Field(None, gt=0, description="A of eq. 2 (default: the arena's width x length)")
