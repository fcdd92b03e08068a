"""The robot's log: named records of what the logic believes (filtered ranges, neighbour tables, states).

On a real robot records go to a JSON-lines file; in a session they go into the recording, next to the ground
truth, so a run can score the logic's beliefs. The controller calls ``robot.log(topic, **values)`` either way.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from swarm_logic.clock import Clock

Sink = Callable[[str, dict[str, Any]], None]


def plain(values: dict[str, Any]) -> dict[str, Any]:
    """JSON-safe copy: numpy scalars and arrays become numbers and lists."""
    return json.loads(json.dumps(values, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


class JsonlLog:
    """Appends ``{"t": clock time, "topic": ..., **values}`` lines to a file."""

    def __init__(self, path: str | Path, clock: Clock) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self.clock = clock

    def __call__(self, topic: str, values: dict[str, Any]) -> None:
        self._f.write(json.dumps({"t": round(self.clock.now(), 6), "topic": topic, **values}) + "\n")
        self._f.flush()

    def close(self) -> None:
        self._f.close()
