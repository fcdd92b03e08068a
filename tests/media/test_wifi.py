"""The Wi-Fi medium (datagrams, seeded latency and loss, counters) under a stand-in hub, the robot's sitl://wifi link
in a robot thread as the logic host runs it, and the real UDP link on loopback."""

from __future__ import annotations

import socket
from collections import defaultdict
from typing import Any

import pytest

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.core.services import service_entity
from bridge.hosts.sim_context import RobotRuntime, SessionClock
from bridge.media.wifi import WifiNetwork
from swarm_logic.drivers.wifi import UdpLink, open_link

Q = 10_000_000


class Recorder:
    def __init__(self) -> None:
        self.records: list[tuple[int, str, dict]] = []

    def write(self, t: int, topic: str, schema: str, payload: Any) -> None:
        self.records.append((t, topic, payload))


class WifiBench:
    """The medium under a stand-in hub: three robots' logic and one service (``ctl``)."""

    def __init__(
        self, wifi: dict[str, Any] | None = None, seed: int = 1, robots: list[dict[str, Any]] | None = None
    ) -> None:
        self.cfg = Config.model_validate(
            {
                "session": {"seed": seed, **({"speed": 1} if robots else {})},
                "robots": robots or [{"profile": "eswarbot", "count": 3}],
                "services": [{"kind": "global_controller", "name": "ctl"}],
                "wifi": wifi or {},
            }
        )
        self.plan = make_plan(self.cfg)
        self.q_ns = Q
        self.service_entities = {"ctl": service_entity("ctl")}
        self.dead: set[int] = set()
        self.inbox: dict[str, list] = defaultdict(list)
        for e in [f"r{rp.id:03d}/logic" for rp in self.plan.robots if rp.has_logic] + ["svc/ctl"]:
            self.inbox[e] = []
        self.deliveries: dict[int, list[tuple]] = defaultdict(list)
        self.rec = Recorder()
        self.medium = WifiNetwork(self)  # type: ignore[arg-type]
        self.k = 0

    def deliver_at(self, t_ns: int, handler, *args: Any) -> None:
        self.deliveries[t_ns].append((handler, args))

    def is_dead(self, e: str) -> bool:
        return e.startswith("r") and int(e[1:4]) in self.dead

    @property
    def t(self) -> int:
        return self.k * Q

    def send(self, e: str, dest: str | None, data: Any) -> None:
        self.medium.transmit(e, 0, self.t, ["wifi", dest, data])

    def step(self) -> None:
        for handler, args in self.deliveries.pop(self.t, []):
            handler(self.t, *args)
        self.k += 1
        for handler, args in self.deliveries.pop(self.t, []):
            handler(self.t, *args)

    def take(self, e: str) -> list:
        out, self.inbox[e] = self.inbox[e], []
        return out

    def report(self) -> dict[str, Any]:
        rep: dict[str, Any] = {}
        self.medium.report(rep)
        return rep["wifi"]


OUTSIDE_ROBOTS = [
    {"profile": "sonpi", "count": 2},
    {"profile": "sonpi", "logic": "external", "i2c_pty": "r{id}-i2c", "wifi_udp": "127.0.0.1:0"},
]


def _outside_program(b: WifiBench) -> socket.socket:
    """A program outside the session on loopback, and where the session bound robot 2's node."""
    host, port = b.medium.started()["wifi_udp"]["r002"].split(":")
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.connect((host, int(port)))
    s.settimeout(5.0)  # a guard: loopback datagrams are there when sendto returns
    return s


def test_ideal_unicast_and_broadcast_arrive_one_quantum_later() -> None:
    b = WifiBench()
    assert b.medium.nodes == {"r000": "r000/logic", "r001": "r001/logic", "r002": "r002/logic", "ctl": "svc/ctl"}
    b.send("svc/ctl", None, b"all")
    b.send("r001/logic", "ctl", b"to ctl")
    assert not any(b.inbox.values())
    b.step()
    assert b.take("r000/logic") == [["wifi", ["ctl", b"all"]]]
    assert b.take("r001/logic") == [["wifi", ["ctl", b"all"]]]
    assert b.take("svc/ctl") == [["wifi", ["r001", b"to ctl"]]]  # a broadcast does not come back to its sender
    rep: dict[str, Any] = {}
    b.medium.report(rep)
    assert rep["wifi"]["sent"] == 2 and rep["wifi"]["delivered"] == 4 and rep["wifi"]["lost"] == 0
    assert rep["wifi"]["broadcasts"] == 1
    assert [p["heard"] for _, topic, p in b.rec.records if topic == "/wifi/tx"] == [["r000", "r001", "r002"], ["ctl"]]


def test_malformed_datagrams_are_counted_and_dropped() -> None:
    b = WifiBench()
    for dest, data in (
        ("nobody", b"x"),
        ("ctl", "not bytes"),
        ("ctl", b""),
        ("ctl", b"x" * 1473),
        (7, b"x"),
        ("r001", b"to myself"),
    ):
        with pytest.raises(ValueError):
            b.medium.transmit("r001/logic", 1, 0, ["wifi", dest, data])
    with pytest.raises(ValueError):
        b.medium.transmit("r001/logic", 1, 0, ["wifi", "ctl"])  # no payload
    b.step()
    assert not any(b.inbox.values())
    rep: dict[str, Any] = {}
    b.medium.report(rep)
    assert rep["wifi"]["malformed"] == 7 and rep["wifi"]["sent"] == 0


def test_a_dead_robot_receives_nothing() -> None:
    b = WifiBench()
    b.dead.add(2)
    b.send("svc/ctl", None, b"all")
    b.step()
    assert b.take("r002/logic") == [] and len(b.take("r000/logic")) == 1


def _lossy_run(seed: int, n: int = 2000) -> tuple[list[int], int]:
    b = WifiBench({"mode": "lossy", "latency_ms": 25.0, "jitter_ms": 5.0, "loss": 0.2}, seed)
    delays = []
    for _ in range(n):
        t0 = b.t
        b.send("r000/logic", "ctl", b"p")
        for _ in range(8):
            b.step()
            if b.take("svc/ctl"):
                delays.append(b.t - t0)
                break
    return delays, n - len(delays)


def test_lossy_latency_and_loss_follow_their_settings_from_a_seeded_stream() -> None:
    delays, lost = _lossy_run(4)
    assert lost / 2000 == pytest.approx(0.2, abs=0.03)
    mean_ms = sum(delays) / len(delays) / 1e6
    assert 30 <= mean_ms <= 40  # leaves at the end of its quantum (10 ms), then 25 ms +- 5, at a quantum boundary
    assert min(delays) >= 2 * Q and all(d % Q == 0 for d in delays)
    assert _lossy_run(4, 300) == _lossy_run(4, 300)  # same seed, same fates
    assert _lossy_run(4, 300) != _lossy_run(5, 300)


def test_ideal_mode_refuses_loss_settings() -> None:
    with pytest.raises(ValueError, match="do\\(es\\) not apply to mode = 'ideal'"):
        Config.model_validate({"robots": [{"profile": "eswarbot"}], "wifi": {"loss": 0.1}})


def test_the_sitl_link_blocks_in_simulated_time() -> None:
    b = WifiBench()
    got: list[Any] = []

    def program() -> None:
        link = open_link("sitl://wifi")
        link.send(b"hello")  # to every node
        got.append(link.recv(0.5))  # the service answers
        got.append((link.recv(0.2), clock.now()))  # nothing more: None after 0.2 simulated seconds
        link.close()

    rt = RobotRuntime(0)
    clock = SessionClock(rt)
    rt.start(program)
    try:
        for _ in range(100):
            t = b.t
            arrived = set()
            for item in b.take("r000/logic"):
                rt.deliver(item[0], item[1])
                arrived.add(item[0])
            if rt.due(t, arrived):
                rt.resume(t)
            assert rt.error is None, rt.error
            for item in rt.outbox:
                b.medium.transmit("r000/logic", 0, t, item)
            rt.outbox = []
            for src, data in [x[1] for x in b.take("svc/ctl")]:
                b.send("svc/ctl", src, b"re:" + data)
            b.step()
            if rt.finished:
                break
        assert got[0] == (b"re:hello", "ctl")
        assert got[1][0] is None and got[1][1] == pytest.approx(0.02 + 0.2)  # the answer came at 20 ms
    finally:
        rt.stop()


def test_the_udp_link_unicasts_and_broadcasts_on_loopback() -> None:
    a = open_link("udp://0.0.0.0:0", broadcast="127.255.255.255")
    b = UdpLink("udp://127.0.0.1:0")
    try:
        port = a.address[1]
        b.send(b"one", f"127.0.0.1:{port}")
        data, src = a.recv(5.0)
        assert data == b"one" and src == f"127.0.0.1:{b.address[1]}"
        b.broadcast = ("127.255.255.255", port)
        b.send(b"all")
        assert a.recv(5.0)[0] == b"all"
        assert a.recv(0.01) is None
    finally:
        a.close()
        b.close()
    for url in ("udp://nohost", "udp://127.0.0.1:0/path", "wifi0", "nope://x"):
        with pytest.raises(Exception, match=r"udp://|URL|unknown"):
            open_link(url)


def test_an_outside_programs_node_is_a_udp_port() -> None:
    """Robot 2's logic runs outside: its node is a UDP port on loopback. What the program sends enters the network as
    the robot's broadcasts; what the network delivers to the robot goes out to the program once it has spoken."""
    b = WifiBench(robots=OUTSIDE_ROBOTS)
    prog = _outside_program(b)
    try:
        assert b.medium.nodes["r002"] == "r002/wifi_udp" and "r002/logic" not in b.inbox
        b.send("svc/ctl", "r002", b"too early")  # nobody has spoken from outside yet: no peer to send it to
        b.step()
        prog.send(b"odometry")
        b.medium.start_quantum(b.t)
        b.step()
        assert b.take("svc/ctl") == [["wifi", ["r002", b"odometry"]]]
        assert b.take("r000/logic") == b.take("r001/logic") == [["wifi", ["r002", b"odometry"]]]
        b.send("svc/ctl", "r002", b"pose")
        b.send("r000/logic", None, b"hello all")
        b.step()
        assert {prog.recv(2048), prog.recv(2048)} == {b"pose", b"hello all"}
        rep = b.report()
        udp = rep["udp"]["r002"]
        assert udp["endpoint"] == b.medium.started()["wifi_udp"]["r002"]
        assert (udp["received"], udp["sent"], udp["unsent"], udp["malformed"]) == (1, 2, 1, 0)
        assert rep["per_node"]["r002"] == {"sent": 1, "received": 3, "lost": 0}
        assert [r[2]["src"] for r in b.rec.records] == ["ctl", "r002", "ctl", "r000"]  # recorded as the rest
    finally:
        prog.close()
        b.medium.close()


def test_a_malformed_datagram_on_the_udp_port_is_counted_and_dropped() -> None:
    b = WifiBench(robots=OUTSIDE_ROBOTS)
    prog = _outside_program(b)
    try:
        prog.send(b"")  # UDP carries an empty datagram; the network does not
        prog.send(b"x" * 1473)  # longer than [wifi] max_datagram
        prog.send(b"fine")
        b.medium.start_quantum(b.t)
        b.step()
        assert b.take("svc/ctl") == [["wifi", ["r002", b"fine"]]]
        rep = b.report()
        assert rep["malformed"] == 2 and rep["sent"] == 1
        assert rep["udp"]["r002"]["malformed"] == 2 and rep["udp"]["r002"]["received"] == 3
        b.dead.add(2)  # a dead robot's program is not heard, nor sent to
        prog.send(b"late")
        b.medium.start_quantum(b.t)
        b.send("svc/ctl", None, b"all")
        b.step()
        assert b.take("svc/ctl") == [] and b.report()["udp"]["r002"]["dead"] == 1
        prog.settimeout(0.05)
        with pytest.raises(TimeoutError):
            prog.recv(2048)
    finally:
        prog.close()
        b.medium.close()


def test_a_udp_node_is_for_an_outside_logic_and_a_fixed_port_for_one_robot() -> None:
    def cfg(**group: Any) -> None:
        Config.model_validate(
            {"session": {"speed": 1}, "robots": [{"profile": "sonpi", "i2c_pty": "r{id}-i2c", **group}]}
        )

    cfg(logic="external", wifi_udp="127.0.0.1:0", count=3)
    with pytest.raises(ValueError, match="wifi_udp: the session's own logic"):
        cfg(wifi_udp="127.0.0.1:0")
    with pytest.raises(ValueError, match="wifi_udp: 2 robots cannot share port 47801"):
        cfg(logic="external", wifi_udp="127.0.0.1:47801", count=2)
    with pytest.raises(ValueError, match="wifi_udp: HOST:PORT expected"):
        cfg(logic="external", wifi_udp="localhost")
