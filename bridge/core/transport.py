"""zenoh, configured explicitly: peer mode, no multicast or gossip scouting, a unix socket endpoint in
the session's private directory, and a namespace per session, so two sessions on one machine never see
each other and nothing leaves the machine. A session whose config sets ``session.listen`` also listens on
that TCP endpoint, so that a robot's swarm logic or a host's processes on another computer can join it (``swarm-sitl
join``), each process with a connection of its own; its namespace then follows from the session's name, which the
joiner gives.

Key space (relative to the session namespace ``swarm-sitl/<session id>``, or ``swarm-sitl/<session name>``
for a session that listens on TCP):

==================  ===================  =====================================================
key                 direction            payload (msgpack)
==================  ===================  =====================================================
``hello/<proc>``    participant -> world  ``{"proc", "pid"}`` once subscribed and matched
``tick/<proc>``     world -> participant  one quantum's work for the process's due entities
``done/<proc>``     participant -> world  the entities' outputs and next wake times
``control``         launcher -> world     ``{"op": "stop"}`` or ``{"op": "dead", "proc", ...}`` (also a
                                          joiner that leaves: ``{"op": "dead", "proc": "remote<id>"}``)
``status``          world -> launcher     progress once per simulated second, events, the end (a joiner
                                          listens too: its robot's failure, the end)
``plan``            joiner -> world       queryable, TCP sessions only: the reply (JSON, not msgpack) is
                                          the plan, the swarm-sitl version and which remote procs may join
``world``           world                 liveliness token, TCP sessions only: a joiner sees the world go
``joined/<proc>``   joiner                liveliness token per process a joiner runs: the world sees its
                                          computer go (the connection closed or its lease ran out)
==================  ===================  =====================================================

Every publisher that carries something that must arrive uses ``CongestionControl.BLOCK`` (``DROP``
lost messages under load in our measurements). zenoh-python may hang at interpreter exit, so processes
close their session explicitly and leave with ``os._exit``.
"""

from __future__ import annotations

import json
import queue
import time
import urllib.parse
import uuid
from typing import Any

import msgpack
import zenoh

PLAN_KEY = "plan"  # the world's queryable in a session that listens on TCP (see the key table)
#: zenoh's link lease in a session: a world paused (SIGSTOP, a suspended laptop, a starved CPU) up to this long loses
#: no participant, as what was on its way when it stopped still arrives (zenoh's own 10 s dropped the links: the
#: paused side, on waking, found it had heard no one for longer). A link cut silently is still noticed sooner, by
#: ``hang_timeout_s``; a closed connection at once.
WORLD_LEASE_S = 120.0
WORLD_KEY = "world"  # the world's liveliness token in such a session
JOINED_KEY = "joined"  # a joiner's liveliness tokens, joined/<proc>: the world sees a remote computer go


def endpoint_for(session_dir: str) -> str:
    return f"unixsock-stream/{session_dir}/zenoh.sock"


def namespace_for(session_name: str | None) -> str:
    """The session's key namespace: random (``None``: nobody outside the launcher needs to know it), or derived
    from the session's name for a session that remote logic joins (the joiner knows only the name). Every character
    a key expression reserves (``* $ ? # /``) is percent-encoded, so any non-empty name works."""
    if session_name is None:
        return f"swarm-sitl/{uuid.uuid4().hex[:16]}"
    if not session_name:
        raise ValueError("session.name: must not be empty for a session that listens on TCP (joiners name it)")
    return "swarm-sitl/" + urllib.parse.quote(session_name, safe="")


def make_config(endpoint: str, namespace: str | None, listen: bool, extra_listen: list[str] | None = None,
                connect_timeout_s: float | None = None) -> zenoh.Config:
    """Peer mode, no scouting, no shared memory, no adminspace. ``listen``: this process (the world) listens on
    ``endpoint`` and ``extra_listen`` (e.g. ``tcp/0.0.0.0:7447`` for joiners); otherwise it connects to
    ``endpoint``. ``connect_timeout_s``: fail to open unless the connection succeeds by then, trying every second at
    most (a joiner, whose world may still be starting; by default a peer opens anyway and keeps trying in the
    background). ``namespace`` None: full keys (a joiner asking which
    sessions answer at an endpoint)."""
    if extra_listen and not listen:
        raise ValueError("extra_listen: only a listening session (the world) listens on more endpoints")
    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    if namespace is not None:
        c.insert_json5("namespace", json.dumps(namespace))
    c.insert_json5("listen/endpoints", json.dumps([endpoint, *(extra_listen or [])] if listen else []))
    c.insert_json5("connect/endpoints", json.dumps([] if listen else [endpoint]))
    if connect_timeout_s is not None:
        c.insert_json5("connect/timeout_ms", json.dumps(max(1, round(connect_timeout_s * 1000))))
        c.insert_json5("connect/exit_on_failure", "true")
        c.insert_json5("connect/retry", '{"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}')
    c.insert_json5("transport/shared_memory/enabled", "false")
    c.insert_json5("adminspace/enabled", "false")
    # how long a silent peer keeps its link (and what was on its way): a world or a participant stopped for a while
    # (and a world that wakes up to find it heard no one for as long) must not drop the others' links
    c.insert_json5("transport/link/tx/lease", json.dumps(round(WORLD_LEASE_S * 1000)))
    return c


def open_session(endpoint: str, namespace: str | None, listen: bool, extra_listen: list[str] | None = None,
                 connect_timeout_s: float | None = None) -> zenoh.Session:
    return zenoh.open(make_config(endpoint, namespace, listen, extra_listen, connect_timeout_s))


def pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def unpack(data: bytes) -> Any:
    return msgpack.unpackb(data, raw=False, strict_map_key=False)


def publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    return session.declare_publisher(key, express=True, congestion_control=zenoh.CongestionControl.BLOCK)


def queue_subscriber(session: zenoh.Session, key: str, q: queue.SimpleQueue, tag: str | None = None) -> Any:
    """Subscribe ``key``; every sample goes into ``q`` as ``(tag or key, payload bytes)``."""

    def cb(sample: zenoh.Sample) -> None:
        q.put((tag or str(sample.key_expr), sample.payload.to_bytes()))

    return session.declare_subscriber(key, cb)


def wait_matched(pub: zenoh.Publisher, timeout_s: float, what: str) -> None:
    """Block until someone subscribes to ``pub`` (start-up only; wall clock for the timeout)."""
    deadline = time.monotonic() + timeout_s
    while not pub.matching_status.matching:
        if time.monotonic() > deadline:
            raise TimeoutError(f"nobody subscribed to {what} within {timeout_s:.0f} s")
        time.sleep(0.005)


def on_gone(session: zenoh.Session, prefix: str, fn: Any) -> Any:
    """Call ``fn(name)`` from a zenoh thread when the liveliness token ``prefix/<name>`` goes away (its session
    closed, its connection broke or its lease ran out); the subscriber, to keep."""

    def cb(sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE:
            fn(str(sample.key_expr).rsplit("/", 1)[-1])

    return session.liveliness().declare_subscriber(f"{prefix}/*", cb)
