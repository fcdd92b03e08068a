"""The robot's log: named records of what the logic believes (filtered ranges, neighbour tables, states).

On a real robot records go to a JSON-lines file; in a session they go into the recording, next to the ground
truth, so a run can score the logic's beliefs. The controller calls ``robot.log(topic, **values)`` either way.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from swarm_logic.clock import Clock

Sink = Callable[[str, dict[str, Any]], None]  # gets the values as the controller gave them: plain() them to store


def plain(values: dict[str, Any]) -> dict[str, Any]:
    """Strict-JSON copy: numpy scalars and arrays become numbers and lists, NaN and infinities become None."""
    raw = json.loads(json.dumps(values, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
    return _finite(raw)


def _finite(v: Any) -> Any:
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, list):
        return [_finite(x) for x in v]
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    return v


class JsonlLog:
    """Appends ``{"t": clock time, "topic": ..., **values}`` lines to a file."""

    def __init__(self, path: str | Path, clock: Clock) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self.clock = clock

    def __call__(self, topic: str, values: dict[str, Any]) -> None:
        self._f.write(json.dumps({"t": round(self.clock.now(), 6), "topic": topic, **plain(values)}) + "\n")
        self._f.flush()

    def close(self) -> None:
        self._f.close()
