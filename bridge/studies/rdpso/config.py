"""The RDPSO study's config section: ``[objective]``, what the light sensor reads in its sessions."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from bridge.core.config import Section


class ObjectiveCfg(Section):
    """``[objective]``: what the robots' light sensor reads: the light field, or the chapter 8 mapping objective
    (the objective family's ``mapping`` field, ``bridge.numerical.objectives``, driven in a session by
    ``mapping.SessionMap``): eq. 8.1 on an entropy map the world keeps from the robots' true poses, as lux from
    ``lux_min`` (nothing to map nearby) to ``lux_max`` (the best frontier)."""

    kind: Literal["light", "mapping"] = "light"
    r_w_m: float = Field(1.0, gt=0, description="mapping: sensing radius R_w of each robot's scan")
    cell_m: float = Field(0.1, gt=0, description="mapping: occupancy-grid cell size")
    sigma_m: float | None = Field(None, gt=0, description="mapping: entropy smoothing for the gradient (R_w / 2)")
    scan_period_s: float = Field(0.5, gt=0, description="mapping: simulated seconds between the robots' scans")
    lux_min: float = Field(10.0, ge=0, description="mapping: lux read where the objective is 0")
    lux_max: float = Field(200.0, gt=0, description="mapping: lux read where the objective is 1")

    @model_validator(mode="after")
    def _consistent(self) -> ObjectiveCfg:
        if self.kind == "light":
            self._only_for_kind(self.kind, set(), {"kind"})
            return self
        if self.r_w_m < self.cell_m:
            raise ValueError(f"r_w_m = {self.r_w_m} is smaller than one cell (cell_m = {self.cell_m})")
        if self.lux_max <= self.lux_min:
            raise ValueError(f"lux_max = {self.lux_max} must exceed lux_min = {self.lux_min}")
        return self
