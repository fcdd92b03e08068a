"""The session recording: every message on every bus, with its sim time, in one MCAP file.

Messages are JSON with JSON-Schema schemas embedded, so Foxglove and any MCAP reader can open the file.
``digest`` is a SHA-256 over the sim-time-ordered stream (log time, topic, payload of every message);
``file_digest`` recomputes it from a file, also from one whose writer died before finishing it; ``recover`` rewrites
such a file, up to its damage, as a whole recording that every MCAP reader opens.
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.reader import NonSeekingReader
from mcap.writer import CompressionType, Writer

SCHEMAS: dict[str, dict[str, Any]] = {
    "swarm_sitl.CanFrame": {
        "type": "object",
        "properties": {
            "id": {"type": "integer", "description": "arbitration id"},
            "data": {"type": "string", "description": "payload, hex"},
            "src": {"type": "string", "description": "sending node (entity)"},
            "name": {"type": "string", "description": "message name in the robot's DBC, if known"},
            "wire_end_ns": {"type": "integer", "description": "sim time the last bit left the wire"},
            "error": {"type": "boolean", "description": "an error frame: the frame of this id and src was destroyed "
                                                         "on the wire (it is retransmitted); data is empty"},
        },
    },
    "swarm_sitl.CanState": {
        "type": "object",
        "description": "A CAN node's fault-confinement state changed (ISO 11898-1): error-active, error-passive "
                       "(a counter above 127) or bus-off (TEC above 255)",
        "properties": {"node": {"type": "string"}, "state": {"enum": ["active", "passive", "bus_off"]},
                       "tec": {"type": "integer"}, "rec": {"type": "integer"}, "wire_ns": {"type": "integer"}},
    },
    "swarm_sitl.MavlinkIn": {
        "type": "object",
        "description": "A MAVLink packet a ground station sent to a robot's face (from outside the session, in wall "
                       "time)",
        "properties": {"robot": {"type": "integer"}, "type": {"type": "string"}, "data": {"type": "string"}},
    },
    "swarm_sitl.Tick": {
        "type": "object",
        "description": "One run of an entity (session.record_ticks): the inputs the world gave it and its answer, "
                       "each msgpack as the world and the process exchanged them, base64 (swarm-sitl replay)",
        "properties": {"k": {"type": "integer", "description": "the quantum"},
                       "in": {"type": "string"}, "out": {"type": ["string", "null"],
                                                         "description": "null: no answer (its process failed)"}},
    },
    "swarm_sitl.Poses": {
        "type": "object",
        "description": "Ground-truth planar poses of all robots",
        "properties": {
            "x": {"type": "array", "items": {"type": "number"}},
            "y": {"type": "array", "items": {"type": "number"}},
            "yaw": {"type": "array", "items": {"type": "number"}},
            "alive": {"type": "array", "items": {"type": "boolean"}},
            "led": {"type": "array", "items": {"type": "array", "items": {"type": "integer"}}},
            "carried": {"type": "array", "items": {"type": "boolean"},
                        "description": "on board another robot (sessions with carried robots only)"},
        },
    },
    "swarm_sitl.Release": {
        "type": "object",
        "description": "A carried robot went down from its carrier onto the floor",
        "properties": {"robot": {"type": "integer"}, "carrier": {"type": "integer"}, "slot": {"type": "integer"},
                       "pose": {"type": "array", "items": {"type": "number"}}},
    },
    "swarm_sitl.Uart": {
        "type": "object",
        "description": "Bytes on a robot's serial line to one of its modules (to_module: as handed to the host's "
                       "UART; to_host: as the module clocked them out)",
        "properties": {"dir": {"enum": ["to_module", "to_host"]}, "data": {"type": "string", "description": "hex"}},
    },
    "swarm_sitl.RadioRx": {
        "type": "object",
        "description": "A frame a module decoded off the air (before its address filter), with the RSSI it measured",
        "properties": {
            "t_ns": {"type": "integer", "description": "end of the frame on the air"},
            "dst": {"type": "integer", "description": "receiving robot"},
            "src": {"type": "integer", "description": "sending robot"},
            "handle": {"type": ["integer", "null"], "description": "the sender's handle of the frame"},
            "rssi_dbm": {"type": ["integer", "null"]},
            "len": {"type": "integer", "description": "payload bytes"},
            "distance_m": {"type": ["number", "null"], "description": "ground-truth distance at delivery"},
        },
    },
    "swarm_sitl.RadioTx": {
        "type": "object",
        "description": "The outcome of one transmission as the sending module learns it",
        "properties": {
            "t_ns": {"type": "integer"},
            "src": {"type": "integer"},
            "handle": {"type": ["integer", "null"]},
            "status": {"type": ["string", "null"], "description": "ok, no_ack or cca_fail"},
            "attempts": {"type": ["integer", "null"]},
            "dst": {"type": ["integer", "null"], "description": "addressed robot of a unicast, null for broadcast"},
            "seq": {"type": ["integer", "null"], "description": "the frame's MAC sequence number (kept by retries)"},
            "distance_m": {"type": ["number", "null"], "description": "ground-truth distance to dst at the outcome"},
            "walls": {"type": ["integer", "null"], "description": "obstacles between src and dst at the outcome"},
        },
    },
    "swarm_sitl.Connectivity": {
        "type": "object",
        "description": "Algebraic connectivity (Fiedler value) of the radio graph of live robots, from ground truth",
        "properties": {"lambda2": {"type": "number"}},
    },
    "swarm_sitl.Log": {
        "type": "object",
        "description": "A record the swarm logic logged (Robot.log); on a real robot it goes to a JSONL file",
    },
    "swarm_sitl.Event": {
        "type": "object",
        "properties": {"kind": {"type": "string"}, "robot": {"type": "integer"}, "detail": {"type": "string"}},
    },
}



def register_schema(name: str, schema: dict[str, Any]) -> None:
    """A plugin's message schema (a robot's pins, a study's metric), by the name its writes give."""
    SCHEMAS[name] = schema


_TIME = struct.Struct("<q")


_COMPACT = json.JSONEncoder(separators=(",", ":"))  # json.dumps(msg, separators=...) without a new encoder per call


def _digest_update(h: Any, log_time: int, topic: str, data: bytes) -> None:
    h.update(b"".join((_TIME.pack(log_time), topic.encode(), b"\0", _TIME.pack(len(data)), data)))


CHUNK_BYTES = 1 << 20  # a chunk ends at 1 MiB of messages (the mcap library's default) ...
CHUNK_NS = 2_000_000_000  # ... or 2 simulated seconds after its first message, whichever comes first


class Recorder:
    """The session's MCAP recording, written as it goes, and the digest of its messages.

    A chunk ends at ``chunk_bytes`` of messages or ``chunk_ns`` of simulated time, whichever comes first: a writer
    killed outright loses at most its last chunk (``recover`` saves the rest), and the writer's in-memory index (one
    entry a chunk, kept for the summary section) grows by a few MiB an hour at 10 robots, not tens."""

    def __init__(self, path: str | Path, metadata: dict[str, str] | None = None, *, chunk_bytes: int = CHUNK_BYTES,
                 chunk_ns: int = CHUNK_NS) -> None:
        self.path = Path(path)
        self._f: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - closed in finish()
        self._w = Writer(self._f, chunk_size=chunk_bytes, compression=CompressionType.ZSTD)
        self._chunk_ns = chunk_ns
        self._chunk_t0: int | None = None  # the simulated time of the open chunk's first message
        self._w.start(profile="", library="swarm-sitl")
        self._schema_ids: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._hash = hashlib.sha256()
        self.count = 0
        self.last_time = 0
        if metadata:
            self._w.add_metadata("session", metadata)
        self._finished = False

    def channel(self, topic: str, schema: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schema_ids.get(schema)
            if sid is None:  # a schema is written before the first channel that uses it
                sid = self._schema_ids[schema] = self._w.register_schema(schema, "jsonschema",
                                                                         json.dumps(SCHEMAS[schema]).encode())
            cid = self._w.register_channel(topic, "json", sid)
            self._channels[topic] = cid
        return cid

    def write(self, t_ns: int, topic: str, schema: str, msg: dict[str, Any]) -> None:
        self.write_json(t_ns, topic, schema, _COMPACT.encode(msg).encode())

    def write_json(self, t_ns: int, topic: str, schema: str, data: bytes) -> None:
        """Record an already JSON-encoded message (hot paths encode fixed shapes themselves)."""
        if t_ns < self.last_time:
            raise ValueError(f"recording must be in sim-time order: {t_ns} after {self.last_time} on {topic}")
        cid = self.channel(topic, schema)
        if self._chunk_t0 is None:
            self._chunk_t0 = t_ns
        elif t_ns - self._chunk_t0 >= self._chunk_ns:  # the open chunk is old enough: to the file with it
            self._w.flush()
            self._chunk_t0 = t_ns
        self._w.add_message(cid, log_time=t_ns, data=data, publish_time=t_ns, sequence=self.count)
        _digest_update(self._hash, t_ns, topic, data)
        self.count += 1
        self.last_time = t_ns

    @property
    def digest(self) -> str:
        return self._hash.hexdigest()

    def finish(self) -> None:
        if self._finished:
            return
        self._finished = True
        self._w.finish()
        self._f.close()


MCAP_MAGIC = b"\x89MCAP0\r\n"


class NotARecording(ValueError):
    """The file is no MCAP recording at all (another file, an empty one, a directory)."""


def iter_messages(path: str | Path) -> Iterator[tuple[str, int, bytes]]:
    """(topic, log_time_ns, payload) in file order; reads what a crashed writer left, up to the damage.
    Raises NotARecording if ``path`` does not start as an MCAP file (a truncated end is damage; a wrong start is
    another file)."""
    if Path(path).is_dir():
        raise NotARecording(f"{path}: not an MCAP recording (a directory)")
    with open(path, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise NotARecording(f"{path}: not an MCAP recording (no MCAP magic at its start)")
        f.seek(0)
        reader = NonSeekingReader(f, validate_crcs=True)
        try:
            for _schema, channel, message in reader.iter_messages(log_time_order=False):
                yield channel.topic, message.log_time, message.data
        except Exception as e:  # a truncated file ends in a partial record
            if not _is_truncation(e):
                raise


def _is_truncation(e: Exception) -> bool:
    name = type(e).__name__
    return name in {"EndOfFile", "RecordLengthLimitExceeded", "InvalidMagic"} or isinstance(e, EOFError | struct.error)


def file_digest(path: str | Path) -> tuple[str, int]:
    """Recompute (digest, message count) from a recording."""
    h = hashlib.sha256()
    n = 0
    for topic, t, data in iter_messages(path):
        _digest_update(h, t, topic, data)
        n += 1
    return h.hexdigest(), n


@dataclass
class Recovered:
    """What :func:`recover` saved of a damaged recording."""

    messages: int
    last_time_ns: int
    digest: str  # of the messages saved, as ``file_digest`` computes it
    complete: bool  # the file had its footer: nothing was damaged


def is_complete(path: str | Path) -> bool:
    """Whether ``path`` ends as a finished MCAP file does (its footer, then the magic)."""
    with open(path, "rb") as f:
        f.seek(0, 2)
        if f.tell() < 2 * len(MCAP_MAGIC):
            return False
        f.seek(-len(MCAP_MAGIC), 2)
        return f.read() == MCAP_MAGIC


def recover(src: str | Path, dst: str | Path) -> Recovered:
    """Write to ``dst`` every schema, channel, metadata record and message ``src`` holds up to its damage (the
    partial record a killed writer left, whose last chunk was never written), as a finished MCAP file."""
    from mcap.records import Channel, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    with open(src, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise NotARecording(f"{src}: not an MCAP recording (no MCAP magic at its start)")
    complete = is_complete(src)
    h = hashlib.sha256()
    n = last = 0
    with open(src, "rb") as f, open(dst, "wb") as g:
        w = Writer(g, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
        started = False
        schemas: dict[int, int] = {}
        channels: dict[int, tuple[int, str]] = {}
        try:
            for rec in StreamReader(f, validate_crcs=True).records:
                if isinstance(rec, Header):
                    w.start(profile=rec.profile, library=rec.library)
                    started = True
                elif isinstance(rec, Schema):
                    schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
                elif isinstance(rec, Channel):
                    channels[rec.id] = (w.register_channel(rec.topic, rec.message_encoding,
                                                           schemas.get(rec.schema_id, 0), rec.metadata), rec.topic)
                elif isinstance(rec, Metadata):
                    w.add_metadata(rec.name, rec.metadata)
                elif isinstance(rec, Message) and rec.channel_id in channels:
                    cid, topic = channels[rec.channel_id]
                    w.add_message(cid, log_time=rec.log_time, data=rec.data, publish_time=rec.publish_time,
                                  sequence=rec.sequence)
                    _digest_update(h, rec.log_time, topic, rec.data)
                    n += 1
                    last = max(last, rec.log_time)
        except Exception as e:  # the damage: a partial record, or a chunk whose checksum fails
            if not (_is_truncation(e) or type(e).__name__ == "CRCValidationError"):
                raise
        if not started:
            w.start(profile="", library="swarm-sitl")
        w.finish()
    return Recovered(n, last, h.hexdigest(), complete)


def recover_in_place(path: str | Path) -> Recovered | None:
    """Rewrite the recording at ``path``, cut by a writer that died, as a finished one up to the cut, keeping the cut
    file beside it as ``<name>.damaged``. None if it was already finished. FileExistsError if ``<name>.damaged``
    exists (it may be the only copy of an earlier one); on any failure the file is left as it was."""
    rec = Path(path)
    with open(rec, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise NotARecording(f"{rec}: not an MCAP recording (no MCAP magic at its start)")
    if is_complete(rec):
        return None
    damaged, part = rec.with_name(rec.name + ".damaged"), rec.with_name(rec.name + ".part")
    if damaged.exists():
        raise FileExistsError(f"{damaged} exists: move it away first (it may be the only copy)")
    rec.replace(damaged)
    try:
        fixed = recover(damaged, part)
    except BaseException:
        damaged.replace(rec)  # as it was
        part.unlink(missing_ok=True)
        raise
    part.replace(rec)
    return fixed
