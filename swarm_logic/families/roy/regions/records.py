"""What every region module's records share: ``Logged``, a record a planner logs as strict JSON, and the parameter
checks (``require``, ``check_fields``) that name the field, the reason and the value in their ValueError."""

from __future__ import annotations

import math
from dataclasses import asdict

from swarm_logic.log import plain


class Logged:
    """A record a planner logs: ``as_dict`` gives it as strict JSON (arrays as lists, NaN and infinities as None)."""

    def as_dict(self) -> dict[str, object]:
        return plain(asdict(self))


def require(ok: bool, name: str, reason: str, value: object) -> None:
    """A parameter check: ValueError naming the field, the reason and the value."""
    if not ok:
        raise ValueError(f"{name}: {reason}, got {value!r}")


def check_fields(obj: object, names: tuple[str, ...], positive: bool = True) -> None:
    """A ValueError naming the first of the dataclass' ``names`` that is not finite and > 0 (``positive``) or >= 0."""
    for name in names:
        v = getattr(obj, name)
        require(
            math.isfinite(v) and (v > 0 if positive else v >= 0),
            name,
            f"must be finite and {'>' if positive else '>='} 0",
            v,
        )
