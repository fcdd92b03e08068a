"""``swarm-sitl replay RUN --robot N --role logic|firmware``: re-run one robot's process against what its recording
says it was given, and compare what it answers now with what it answered then, run by run.

A session recorded with ``session.record_ticks = true`` holds every run of every entity of the robots' processes
(``/ticks/<entity>``: the inputs the world sent and the answer it got, as the processes exchanged them). Replay builds
the robot's logic host (its behaviour as the code now is) or its firmware host (its boards and modules) in this
process, feeds it the recorded inputs at their simulated times, and compares each answer with the recorded one: the
same everywhere, or the first divergence (time, entity, where in the answer, expected and got). A user edits a
controller, replays, and sees where its behaviour changed; ``--pdb`` stops there.
"""

from __future__ import annotations

import base64
import json
import pdb
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.core import transport
from bridge.core.entities import entity
from bridge.core.plan import Plan
from bridge.core.recorder import NotARecording, iter_messages


class ReplayError(Exception):
    """The run cannot be replayed (no such run, robot or role; recorded without ticks)."""


@dataclass(frozen=True)
class Divergence:
    t_ns: int
    entity: str
    where: str  # a path into the answer: out[2][1], wake
    expected: Any
    got: Any

    def __str__(self) -> str:
        return (f"first divergence at t={self.t_ns / 1e9:.3f} s, {self.entity}, {self.where}:\n"
                f"  expected {self.expected!r}\n  got      {self.got!r}")


@dataclass
class Outcome:
    runs: int
    divergence: Divergence | None


def _first_difference(a: Any, b: Any, where: str = "") -> tuple[str, Any, Any] | None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if k not in a or k not in b:
                return f"{where}.{k}".lstrip("."), a.get(k, "<absent>"), b.get(k, "<absent>")
            d = _first_difference(a[k], b[k], f"{where}.{k}")
            if d:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list):
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            d = _first_difference(x, y, f"{where}[{i}]")
            if d:
                return d
        if len(a) != len(b):
            i = min(len(a), len(b))
            return f"{where}[{i}]".lstrip("."), a[i] if i < len(a) else "<absent>", b[i] if i < len(b) else "<absent>"
        return None
    return None if a == b else (where.lstrip(".") or "answer", a, b)


def replay(run: str | Path, robot: int, role: str, stop_in_pdb: bool = False) -> Outcome:
    """Re-run robot ``robot``'s ``role`` process (``logic`` or ``firmware``) of the run in ``run`` (its output
    directory, or its ``session.mcap``) against its recorded inputs. ReplayError if it cannot be replayed."""
    run = Path(run)
    rec = run if run.suffix == ".mcap" else run / "session.mcap"
    plan_path = rec.parent / "plan.json"
    if not rec.is_file() or not plan_path.is_file():
        raise ReplayError(f"{run}: no session.mcap and plan.json there (a session's output directory)")
    plan = Plan.from_json(json.loads(plan_path.read_text()))
    if not plan.config.get("session", {}).get("record_ticks"):
        raise ReplayError(f"{run}: recorded without session.record_ticks = true: its runs' inputs are not in it")
    if not 0 <= robot < len(plan.robots):
        raise ReplayError(f"{run}: no robot {robot} (the run has {len(plan.robots)})")
    rp = plan.robots[robot]
    if role == "logic":
        if not rp.has_logic:
            raise ReplayError(f"{run}: robot {robot}'s logic did not run in the session")
        from bridge.hosts.logic import LogicHost

        ents = {entity(robot, "logic")}
        host: Any = LogicHost(plan, (robot,))
    elif role == "firmware":
        from bridge.hosts.firmware import FirmwareHost

        ents = {entity(robot, r) for r in rp.modules()}
        host = FirmwareHost(plan, (robot,))
    else:
        raise ReplayError(f"role must be logic or firmware, not {role!r}")
    topics = {f"/ticks/{e}" for e in ents}
    runs = 0
    try:
        for topic, t_ns, data in iter_messages(rec):
            if topic not in topics:
                continue
            msg = json.loads(data)
            if msg["out"] is None:
                continue
            e = topic.removeprefix("/ticks/")
            inputs = transport.unpack(base64.b64decode(msg["in"]))
            expected = transport.unpack(base64.b64decode(msg["out"]))
            try:
                got = transport.unpack(transport.pack(host.run(e, t_ns, inputs)))  # as the world would get it
            except Exception as err:
                got = {"err": f"{type(err).__name__}: {err}", "wake": None}
            runs += 1
            diff = _first_difference(expected, got)
            if diff is not None:
                d = Divergence(t_ns, e, *diff)
                if stop_in_pdb:
                    print(d, file=sys.stderr)
                    print("replay: in pdb at the divergence (expected, got, inputs, host); c to leave", file=sys.stderr)
                    pdb.Pdb().set_trace()
                return Outcome(runs, d)
    except NotARecording as e:
        raise ReplayError(str(e)) from None
    finally:
        host.stop()
    if runs == 0:
        raise ReplayError(f"{run}: no recorded run of {', '.join(sorted(ents))}")
    return Outcome(runs, None)
