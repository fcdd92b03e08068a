"""A session's CAN traffic as python-can log files, so CAN tools (CANalyzer, candump, cantools) can read it.

The hub records every frame a robot's bus delivered on ``/rNNN/can0`` (``bridge.core.hub``). This module turns
those records into ``can.Message`` objects and writes them with python-can's own writers, and decodes any
python-can log with the robots' DBC.

Decisions:

- ``timestamp`` is the frame's ``wire_end_ns`` in seconds: the simulated time its last bit left the wire,
  which is when a real controller stamps a received frame. The log time is the quantum boundary at which
  the hub delivered it (up to one quantum later) and is used only for a record without ``wire_end_ns``.
  Records come in log-time order; frames delivered at the same boundary are sorted by wire end time, which
  makes the whole stream time-ordered (a frame delivered at a later boundary ended after the earlier one);
  frames that ended at the same time are ordered by robot id.
- ``channel`` is ``"rNNN"`` (the robot id, as in the topic): candump's log format writes it as the interface
  name. Formats with numbered channels (ASC, BLF, TRC) take its trailing number plus one, since they count
  channels from 1: robot ``r`` is channel ``r + 1`` in the file, and python-can reads it back as ``r``.
  CSV has no channel column.
- ASC and BLF store times relative to the start of the measurement, which python-can's writers take from
  the first object: ``export`` logs a marker event at simulated time 0 first, so these files hold simulated
  time itself. TRC has no such event; python-can restores its start from a header stored in days (about
  1 µs off).
- Records with ``"ext": true`` (or an id above 0x7FF) are extended frames, ``"error": true`` error frames;
  records that are no classic CAN frame (no integer id, data not hex of at most 8 bytes) are skipped. TRC
  files get no error frames (python-can's TRC writer cannot write them).
"""

from __future__ import annotations

import contextlib
import json
import re
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
from cantools.database.can import Database
from cantools.database.errors import DecodeError
from mcap.exceptions import McapError
from mcap.records import Chunk, DataEnd, Footer, Header, Message, Metadata
from mcap.stream_reader import StreamReader
from zstandard import ZstdError

from bridge.core.recorder import MCAP_MAGIC, iter_messages
from swarm_logic.robots.eswarbot import eswarbot_llc_db

SUFFIXES = (".asc", ".blf", ".log", ".csv", ".trc")
LIBRARY = "swarm-sitl"  # the header's library field of a session recording (bridge.core.recorder.Recorder)
START_EVENT = "swarm-sitl: simulated time"
_TOPIC = re.compile(r"^/r(\d{3,})/can0$")
_ROBOT_TOPIC = re.compile(r"^/r(\d{3,})/")  # any topic of a robot (its bus, its LLC's pins, its logic's logs)


def channel_name(robot: int) -> str:
    """The channel of a robot's bus in a log (``"r003"``)."""
    return f"r{robot:03d}"


def _check_suffix(path: Path) -> None:
    if path.suffix.lower() not in SUFFIXES:
        raise ValueError(f"{path}: unknown CAN log format {path.suffix or '(no suffix)'!r}; "
                         f"use one of {', '.join(SUFFIXES)}")


def _check_recording(path: Path) -> int | None:
    """Raise ValueError unless ``path`` is a session recording (also one whose writer died); return the run's
    robot count, from the "session" metadata the hub writes right after the header (None if it has none)."""
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    with open(path, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise ValueError(f"{path}: not an MCAP file (no MCAP magic at its start)")
        f.seek(0)
        records = StreamReader(f, skip_magic=False).records
        try:
            header = next(records, None)
        except (McapError, EOFError, struct.error) as e:
            raise ValueError(f"{path}: MCAP file ends or is damaged before its header ({e or type(e).__name__})") \
                from None
        if not isinstance(header, Header):
            raise ValueError(f"{path}: MCAP file without a header record")
        if header.library != LIBRARY:
            raise ValueError(f"{path}: an MCAP file, but not a swarm-sitl session recording "
                             f"(written by {header.library!r})")
        try:
            for rec in records:
                if isinstance(rec, Metadata) and rec.name == "session":
                    n = rec.metadata.get("robots", "")
                    return int(n) if n.isdigit() else None
                if isinstance(rec, Chunk | Message | DataEnd | Footer):  # the metadata comes before any message
                    return None
        except (McapError, EOFError, struct.error, ZstdError):  # damage: reported (or read up to) by _frames
            return None
    return None


def _not_in_run(path: Path, wanted: set[int], there: list[int], what: str = "run") -> ValueError:
    """The error for robots asked for that the run does not have, naming those it has."""
    missing = sorted(wanted - set(there))
    ids = ", ".join(map(str, missing))
    if not there:
        has = "it has no robots"
    elif there == list(range(len(there))) and len(there) > 10:
        has = f"its robots are 0 to {len(there) - 1}"
    else:
        has = f"its robots are {', '.join(map(str, there))}"
    who = f"robot {ids} is" if len(missing) == 1 else f"robots {ids} are"
    return ValueError(f"{path}: {who} not in this {what}; {has}")


def _message(robot: int, t_ns: int, payload: bytes) -> can.Message | None:
    """The frame a ``swarm_sitl.CanFrame`` record describes, or None if it is not a classic CAN frame."""
    try:
        d = json.loads(payload)
        arbitration_id = d["id"]
        data = bytes.fromhex(d.get("data", ""))
    except (ValueError, KeyError, TypeError):
        return None
    if not isinstance(arbitration_id, int) or not 0 <= arbitration_id <= 0x1FFFFFFF or len(data) > 8:
        return None
    wire_end = d.get("wire_end_ns")
    ts_ns = wire_end if isinstance(wire_end, int) else t_ns
    return can.Message(timestamp=ts_ns / 1e9, arbitration_id=arbitration_id, data=data,
                       is_extended_id=bool(d.get("ext", False)) or arbitration_id > 0x7FF,
                       is_error_frame=bool(d.get("error", False)), channel=channel_name(robot), is_rx=True)


def _frames(path: Path, robots: set[int] | None, check_robots: bool = False) -> Iterator[can.Message]:
    """``check_robots``: the recording does not say which robots its run had; raise ValueError at the end if
    ``robots`` names one it has no topic of."""
    group: list[tuple[float, int, can.Message]] = []  # (time, robot, frame) delivered at one boundary
    group_t: int | None = None
    seen: set[int] = set()
    try:
        for topic, t_ns, payload in iter_messages(path):
            if check_robots and (r := _ROBOT_TOPIC.match(topic)):
                seen.add(int(r.group(1)))
            m = _TOPIC.match(topic)
            if m is None or (robots is not None and int(m.group(1)) not in robots):
                continue
            if t_ns != group_t:
                yield from _in_order(group)
                group, group_t = [], t_ns
            robot = int(m.group(1))
            msg = _message(robot, t_ns, payload)
            if msg is not None:
                group.append((msg.timestamp, robot, msg))
    except (McapError, ValueError, ZstdError) as e:  # damage other than a truncated end (read up to quietly)
        raise ValueError(f"{path}: damaged recording: {e}") from None
    yield from _in_order(group)
    if check_robots and robots is not None and not robots <= seen:
        raise _not_in_run(path, robots, sorted(seen), "recording")


def _in_order(group: list[tuple[float, int, can.Message]]) -> Iterator[can.Message]:
    """By wire end time, then robot id; a bus's own frames keep their (wire) order."""
    for _t, _r, msg in sorted(group, key=lambda g: g[:2]):
        yield msg


def iter_frames(mcap_path: str | Path, robots: set[int] | None = None) -> Iterator[can.Message]:
    """Every CAN frame the robots' buses delivered (of ``robots`` only, if given), in time order.

    ``timestamp`` is the simulated time the frame left the wire (s), ``channel`` ``"rNNN"``, ``is_rx`` True.
    Raises ValueError at once if the file is missing or no session recording, or if ``robots`` names a robot
    the run did not have (a recording without the hub's robot count: at the end, if it has no topic of one);
    a truncated recording yields what it holds up to the damage.
    """
    path = Path(mcap_path)
    n = _check_recording(path)
    if robots is not None and n is not None and not robots <= set(range(n)):
        raise _not_in_run(path, robots, list(range(n)))
    return _frames(path, robots, check_robots=n is None)


def export(mcap_path: str | Path, out_path: str | Path, robots: set[int] | None = None) -> int:
    """Write a recording's CAN frames to ``out_path`` with ``can.Logger`` (.asc, .blf, .log = candump -l,
    .csv, .trc by suffix); return the number of frames. Raises ValueError naming the file for an unknown
    suffix, a missing file, a file that is no session recording, a robot that is not in the run, or a
    recording damaged other than by a truncated end (then no output is left behind)."""
    out = Path(out_path)
    _check_suffix(out)
    frames = iter_frames(mcap_path, robots)
    n = 0
    try:
        with can.Logger(out) as writer:
            if isinstance(writer, can.ASCWriter | can.BLFWriter):  # their time base: the first object's time
                writer.log_event(START_EVENT, 0.0)
            for msg in frames:
                if msg.is_error_frame and isinstance(writer, can.TRCWriter):
                    continue  # python-can's TRC writer cannot log error frames (it drops them with a warning)
                writer.on_message_received(msg)
                n += 1
    except BaseException:
        out.unlink(missing_ok=True)  # no half-written log
        raise
    return n


def decode(path: str | Path, db: Database | None = None) -> Iterator[tuple[can.Message, str, dict[str, Any]]]:
    """(frame, message name, signals) for every frame of a python-can log, decoded with ``db`` (default:
    the eSwarBot LLC's DBC). Unknown ids, error and remote frames give ``""`` and ``{}``; a known id whose
    payload does not fit its message gives its name and ``{}``."""
    p = Path(path)
    _check_suffix(p)
    if not p.is_file():
        raise ValueError(f"{p}: no such file")
    return _decoded(p, db if db is not None else eswarbot_llc_db())


def _decoded(path: Path, db: Database) -> Iterator[tuple[can.Message, str, dict[str, Any]]]:
    for msg in can.LogReader(path):
        spec = None
        if not (msg.is_error_frame or msg.is_remote_frame):
            with contextlib.suppress(KeyError):
                spec = db.get_message_by_frame_id(msg.arbitration_id)
        if spec is None or spec.is_extended_frame != msg.is_extended_id:
            yield msg, "", {}
            continue
        try:
            signals = dict(spec.decode(bytes(msg.data), decode_choices=False))
        except DecodeError:
            signals = {}
        yield msg, spec.name, signals
