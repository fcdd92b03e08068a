"""The medium plugin: one kind of link between a session's entities (a bus, a channel, a serial line, a link to the
outside), with the output items it carries and its part in each quantum.

The world process (``bridge.core.hub``) knows no medium by name. It builds the media a session wants, found in the
``swarm_sitl.media`` entry points, and routes every output item by ``(kind, role of its sender)`` through the table
their ``routes`` declare: a new bus is a new module and an entry point, no edit here or in the hub. A handler that
raises ``ValueError``, ``TypeError``, ``KeyError`` or ``IndexError`` on an item has met a malformed one: the hub
counts it (``malformed_items``) and drops it.

A quantum, as the hub drives it (``docs/architecture.md``, "How one tick flows"): deliveries due at t (a medium
schedules its own with ``hub.deliver_at``), then every medium's ``start_quantum`` (bytes that finished crossing a
line, packets from outside), the tick, physics, the answers, each output item to its route, every medium's
``end_outputs`` (a bus arbitrates what was offered), and ``advance`` (a channel resolves its air).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    from bridge.core.hub import Hub

Route = Callable[[str, int, int, list], None]  # (sender entity, its robot, t, item)


class Medium:
    """Base of a session's medium: declare ``name``, ``order`` and ``routes``; override the hooks it needs."""

    name: ClassVar[str] = ""
    order: ClassVar[int] = 100  # media run their hooks in this order (then by name)
    routes: ClassVar[dict[tuple[str, str], str]] = {}  # (item kind, sender role or "*") -> method name

    def __init__(self, hub: Hub) -> None:
        self.hub = hub

    @classmethod
    def wanted(cls, hub: Hub) -> bool:
        """Whether this session has anything on this medium (nothing is built for a medium it does not use)."""
        return True

    def started(self) -> dict[str, Any]:
        """What the launcher should know once the session has started (an endpoint it bound)."""
        return {}

    def start_quantum(self, t: int) -> None:
        """After the deliveries due at ``t``, before the entities due at ``t`` are found."""

    def end_outputs(self, t: int) -> None:
        """After every output item of quantum ``t`` has been routed."""

    def advance(self, t: int) -> None:
        """At the end of quantum ``t``, after the failures it brought."""

    def on_log(self, robot: int, topic: str, values: dict[str, Any], t: int) -> None:
        """A robot's logic logged ``values`` under ``topic`` (already recorded); raise ``ValueError`` if malformed."""

    def inject_fault(self, f: Any, t: int) -> bool:
        """A fault (``FaultCfg``, from ``f.at_s`` on) injected while the session runs, at quantum ``t``: True if this
        medium carries it (a CAN fault into a robot's bus)."""
        return False

    def end_fault(self, f: Any, t: int) -> bool:
        """End fault ``f`` (the entry given to ``inject_fault``) at ``t`` if it would last longer (a ground station's
        FAILURE_TYPE_OK): True if this medium carries it."""
        return False

    def unplug(self, r: int, device: str) -> None:
        """Robot ``r``'s ``device`` module (``xbee``, ``uwb``) was pulled out (an ``unplugged`` fault): a medium that
        carries it takes it off (the radio, the UWB ranging)."""

    def scene(self, t: int) -> list[dict[str, Any]]:
        """What this medium adds to the recording's scene at ``t`` (``foxglove.SceneEntity`` dicts, built with
        ``bridge.core.foxglove``): the radio links."""
        return []

    def report(self, result: dict[str, Any]) -> None:
        """Add this medium's figures to the world's result (at the end of the run)."""

    def radio_report(self, out: dict[str, Any]) -> None:
        """Add to the result's ``radio`` section (after ``Hub.shutdown``: the modules have sent their counters)."""

    def close(self) -> None:
        """Release what the medium holds outside the process (sockets)."""


def route_table(media: list[Medium]) -> dict[tuple[str, str], Route]:
    """Every medium's routes as bound handlers; two media claiming one route is a programming error."""
    table: dict[tuple[str, str], Route] = {}
    for m in media:
        for key, method in m.routes.items():
            if key in table:
                raise RuntimeError(f"media {m.name!r} and {table[key].__self__.name!r} both route {key}")  # type: ignore[attr-defined]
            table[key] = getattr(m, method)
    return table
