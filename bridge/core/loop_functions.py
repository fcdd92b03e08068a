"""Loop functions: a study's hooks into a session, as ARGoS's loop functions are.

A study measures what it needs (a deployment's dispersion, the routing layer's counters, a map's exploration),
ends a session when its own condition holds, and adds its sections to ``summary.json``, without the world process
knowing the study. The hub builds the loop functions of every study in the ``swarm_sitl.studies`` entry points
whose ``wanted`` says the session is theirs, and calls each hook in study-name order.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from bridge.core.config import Config
    from bridge.core.hub import Hub


class LoopFunctions:
    """Override what the study needs; every hook does nothing by default."""

    def __init__(self, hub: Hub) -> None:
        self.hub = hub

    @classmethod
    def wanted(cls, cfg: Config) -> bool:
        """Whether a session with this config is one the study measures."""
        return False

    def pre_step(self, t: int) -> None:
        """Quantum ``t``: after the deliveries, before the media's ``start_quantum`` and the sensors are read."""

    def on_log(self, robot: int, topic: str, values: dict[str, Any], t: int) -> None:
        """A robot's logic logged ``values`` under ``topic`` (already recorded); raise ``ValueError`` if malformed."""

    def on_service_log(self, service: str, topic: str, values: dict[str, Any], t: int) -> None:
        """Service ``service`` logged ``values`` under ``topic`` at quantum ``t`` (already recorded): a study may end
        the session on a service's decision (``hub.end_ns``); raise ``ValueError`` if malformed."""

    def on_radio_sample(self, t: int, live: list[int], adj: np.ndarray) -> None:
        """The radio medium sampled the live robots' radio graph (``live`` robots, adjacency ``adj``)."""

    def scene(self, t: int) -> list[dict[str, Any]]:
        """What the study adds to the recording's scene at ``t`` (``foxglove.SceneEntity`` dicts, built with
        ``bridge.core.foxglove``): its particles, targets, regions."""
        return []

    def radio_report(self, connectivity: dict[str, Any]) -> None:
        """Add the study's figures to the summary's ``radio.connectivity``."""

    def summary(self) -> dict[str, Any]:
        """The study's top-level sections of ``summary.json``."""
        return {}
