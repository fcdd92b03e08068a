"""Device probes against stand-ins that speak the real byte protocols, with no hardware attached.

- XBee: a pseudo-terminal whose other side is the project's XBee firmware emulation (``XBeeModule``), stepped
  in wall time by a thread. Both ends have a line speed (the module's BD, the host's as pyserial set it on the
  terminal); when they differ, bytes cross as a UART at one rate samples a line driven at the other.
- CAN: python-can's in-process ``virtual`` interface, a thread sending DBC-encoded frames.
- MAVLink: UDP on 127.0.0.1 with ephemeral ports, a pymavlink peer thread sending heartbeats.

Every stand-in is a context manager that stops its thread and closes its fds; a fixture checks that no
thread or fd outlives a test.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import socket
import threading
import tty
from collections.abc import Iterator
from pathlib import Path

import can
import pytest
import serial
from can.interfaces import virtual

from bridge.hil import devices
from bridge.hil.devices import probe_can, probe_mavlink, probe_xbee
from swarm_logic.robots.eswarbot import eswarbot_llc_db
from tests.support.standins import EmulatedXBee, uart_resample

pytestmark = pytest.mark.timeout(120)
ANSWER_S = 60.0  # a probe that gets its answer returns at once: this timeout only bounds a hang (a loaded machine)



@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    threads, fds = set(threading.enumerate()), set(os.listdir("/proc/self/fd"))
    yield
    assert set(threading.enumerate()) <= threads, "a thread outlived the test"
    assert set(os.listdir("/proc/self/fd")) <= fds, "an fd outlived the test"


# -- XBee ---------------------------------------------------------------------------------------------------------


def test_uart_resample() -> None:
    data = bytes(range(256))
    assert uart_resample(data, 9600, 9600) == data
    assert uart_resample(b"\x7e\x00\x04", 9600, 115200) != b"\x7e\x00\x04"
    assert len(uart_resample(b"\x00" * 10, 9600, 115200)) > 10  # a slow zero byte reads as several bytes


def before_the_probe_waits(monkeypatch: pytest.MonkeyPatch, then) -> None:
    """Once a probe opened its serial port (which empties the port's input) and before it starts its timeout, run
    ``then(port)``: what the probe must hear is on the line before its clock runs, however slow the machine."""
    real = devices._open_serial

    def opened(port: str, baudrate: int):
        ser = real(port, baudrate)
        if not isinstance(ser, str):
            then(ser)
        return ser

    monkeypatch.setattr(devices, "_open_serial", opened)


@pytest.mark.parametrize(("series", "api_mode"), [(1, 1), (1, 2), (2, 1), (2, 2)])
def test_xbee_answers(series: int, api_mode: int) -> None:
    with EmulatedXBee(series=series, api_mode=api_mode) as x:
        r = probe_xbee(x.path, api_mode=api_mode, timeout_s=ANSWER_S)
        assert x.host_baud() == 9600
    assert r.ok, r.detail
    assert (r.kind, r.name) == ("xbee", x.path)
    assert r.info["serial"] == "0013A20040B0C0D1" and r.info["series"] == series
    assert r.info["node_id"] == "probe-me"
    assert r.info["fw_version"] == (0x10EF if series == 1 else 0x23A7)
    assert f"Series {series}" in r.detail and "serial 0013A20040B0C0D1" in r.detail and x.path in r.detail


def test_xbee_answers_while_neighbours_talk() -> None:
    with EmulatedXBee(neighbour_every_s=0.02) as x:
        r = probe_xbee(x.path, timeout_s=ANSWER_S)
    assert r.ok, r.detail


def test_xbee_at_the_wrong_baud_rate_answers_garbage(monkeypatch: pytest.MonkeyPatch) -> None:
    with EmulatedXBee(baud=9600, neighbour_every_s=0.05) as x:
        before_the_probe_waits(monkeypatch, lambda port: x.wait_writes(2))  # neighbours' frames, at the wrong rate
        r = probe_xbee(x.path, baudrate=115200, timeout_s=1.0)
        assert x.host_baud() == 115200
        assert x.module.counters["at_commands"] == 0  # it never understood a request either
    assert not r.ok
    assert r.detail.startswith(f"{x.path}: answers garbage: ")
    assert "noise bytes - wrong baud rate (tried 115200) or not in API mode AP=1?" in r.detail
    assert r.info["counters"]["dropped_bytes"] > 0


def test_xbee_in_the_other_api_mode_answers_garbage(monkeypatch: pytest.MonkeyPatch) -> None:
    """A module in AP=2 escapes 0x13 in its answer to SH (0013A200): read as AP=1 the checksum fails."""
    sh = bytes((0x08, 0x52)) + b"SH"  # AT SH, frame id 0x52: no byte to escape, the same frame in both modes
    request = bytes((0x7E, 0, len(sh))) + sh + bytes((0xFF - sum(sh) & 0xFF,))

    def ask(port: serial.SerialBase) -> None:  # as the probe does, answered in full before the probe's clock runs
        port.write(request)
        x.settle()

    with EmulatedXBee(api_mode=2) as x:
        before_the_probe_waits(monkeypatch, ask)
        r = probe_xbee(x.path, api_mode=1, timeout_s=0.5)
    assert not r.ok
    assert r.info["counters"]["checksum_errors"] >= 1
    assert r.detail.startswith(f"{x.path}: answers garbage: {r.info['counters']['checksum_errors']} malformed frames")
    assert r.detail.endswith("or not in API mode AP=1?")


def test_xbee_silent_line_is_no_answer() -> None:
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        path = os.ttyname(slave)
        r = probe_xbee(path, timeout_s=0.5)
    finally:
        os.close(master)
        os.close(slave)
    assert not r.ok
    assert r.detail == (f"{path}: no answer within 0.5 s - is the module powered and connected, "
                        "at 9600 baud in API mode AP=1?")


def test_xbee_missing_device(tmp_path: Path) -> None:
    r = probe_xbee(str(tmp_path / "ttyNOPE"))
    assert not r.ok and r.detail == f"{tmp_path / 'ttyNOPE'}: no such device"


def test_xbee_not_a_serial_device(tmp_path: Path) -> None:
    f = tmp_path / "notes.txt"
    f.write_text("hello")
    r = probe_xbee(str(f))
    assert not r.ok and r.detail == f"{f}: not a serial device (not a character device)"


def test_xbee_busy_port() -> None:
    with EmulatedXBee() as x:
        other = serial.Serial(x.path, 9600, exclusive=True)
        try:
            r = probe_xbee(x.path)
        finally:
            other.close()
        assert probe_xbee(x.path, timeout_s=ANSWER_S).ok  # free again
    assert not r.ok and r.detail == f"{x.path}: busy: locked by another process"


def test_xbee_permission_denied(monkeypatch: pytest.MonkeyPatch) -> None:
    """As pyserial reports an open(2) that fails with EACCES (tests run as root here, so it is raised for it)."""
    master, slave = os.openpty()
    path = os.ttyname(slave)

    def denied(port: str, **kw: object) -> None:
        raise serial.SerialException(errno.EACCES, f"could not open port {port}: [Errno 13] Permission denied")

    monkeypatch.setattr(devices.serial, "serial_for_url", denied)
    try:
        r = probe_xbee(path)
    finally:
        os.close(master)
        os.close(slave)
    assert not r.ok
    assert r.detail == f"{path}: permission denied (is the user in the group owning the device, e.g. dialout?)"


# -- CAN ----------------------------------------------------------------------------------------------------------


@contextlib.contextmanager
def can_traffic(channel: str, frames: list[can.Message], period_s: float = 0.1) -> Iterator[None]:
    """A thread sending ``frames`` every ``period_s`` on a virtual bus, as the LLC sends STATUS at 10 Hz. The first
    ``frames`` are sent as the probe's bus opens on ``channel``, before it starts listening (and its timeout): it
    hears them however slow the machine."""
    bus = can.Bus(interface="virtual", channel=channel)
    stop = threading.Event()
    real_bus = can.Bus

    def probe_bus(**kwargs: object) -> can.BusABC:
        opened = real_bus(**kwargs)
        if kwargs.get("channel") == channel:
            for f in frames:
                bus.send(f)
        return opened

    def run() -> None:
        while not stop.wait(period_s):
            for f in frames:
                bus.send(f)

    th = threading.Thread(target=run, name="can-sender", daemon=True)
    th.start()
    can.Bus = probe_bus
    try:
        yield
    finally:
        can.Bus = real_bus
        stop.set()
        th.join(timeout=60)
        bus.shutdown()
        assert not th.is_alive()


def status_frame(heartbeat: int) -> can.Message:
    status = eswarbot_llc_db().get_message_by_name("STATUS")
    data = status.encode({**{s.name: 0 for s in status.signals}, "heartbeat": heartbeat})
    return can.Message(arbitration_id=status.frame_id, data=data, is_extended_id=False)


def test_can_traffic_is_named_with_the_dbc(request: pytest.FixtureRequest) -> None:
    channel = f"probe-{request.node.name}"
    odo = eswarbot_llc_db().get_message_by_name("ODOMETRY")
    frames = [status_frame(1), can.Message(arbitration_id=odo.frame_id, data=bytes(8), is_extended_id=False),
              can.Message(arbitration_id=0x7AB, data=b"\x01", is_extended_id=False)]
    with can_traffic(channel, frames):
        r = probe_can({"interface": "virtual", "channel": channel})
    assert channel not in virtual.channels  # both buses were shut down
    assert r.ok, r.detail
    assert (r.kind, r.name) == ("can", f"virtual:{channel}")
    assert r.info["ids"] == {0x181: "ODOMETRY", 0x185: "STATUS", 0x7AB: ""}
    assert r.info["frames"] >= 3
    assert r.detail.endswith("3 ids: ODOMETRY (0x181), STATUS (0x185), 0x7AB")


def test_can_silent_bus(request: pytest.FixtureRequest) -> None:
    r = probe_can({"interface": "virtual", "channel": f"probe-{request.node.name}"}, timeout_s=0.3)
    assert f"probe-{request.node.name}" not in virtual.channels  # the probe shut its bus down
    assert not r.ok
    assert r.detail == (f"virtual:probe-{request.node.name}: no traffic within 0.3 s - is the board powered and "
                        "the bitrate right?")


def test_can_error_frames_only(request: pytest.FixtureRequest) -> None:
    channel = f"probe-{request.node.name}"
    with can_traffic(channel, [can.Message(is_error_frame=True)], period_s=0.05):
        r = probe_can({"interface": "virtual", "channel": channel}, timeout_s=0.5)
    assert not r.ok and r.info["error_frames"] > 0
    assert f"{channel}: only {r.info['error_frames']} error frames within 0.5 s" in r.detail


def test_can_unknown_interface() -> None:
    r = probe_can({"interface": "nosuch", "channel": "can7"})
    assert not r.ok
    assert r.detail.startswith('nosuch:can7: interface not available here: Unknown interface type "nosuch"')
    assert "socketcan" in r.detail  # lists the ones python-can knows


def test_can_missing_adapter(tmp_path: Path) -> None:
    port = tmp_path / "ttyACM-gone"
    r = probe_can({"interface": "slcan", "channel": str(port), "bitrate": 500000})
    assert not r.ok
    assert r.detail.startswith(f"slcan:{port}: cannot open: ") and "No such file or directory" in r.detail


# -- MAVLink ------------------------------------------------------------------------------------------------------


@contextlib.contextmanager
def reserved_udp_port() -> Iterator[int]:
    """A free UDP port on 127.0.0.1 that stays ours while the probe binds it: held by a socket bound with
    SO_REUSEADDR (pymavlink's udpin binds with it too, other programs without it are refused) and connected
    to itself, so it receives nothing sent there from elsewhere."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        s.connect(("127.0.0.1", port))
        yield port
    finally:
        s.close()


@contextlib.contextmanager
def mavlink_peer(url: str, *, sysid: int = 42, corrupt_first: int = 0, garbage_first: int = 0,
                 heartbeats: bool = True) -> Iterator[object]:
    """A vehicle on ``url`` sending a HEARTBEAT every 0.1 s (a ground rover, system ``sysid``), after
    ``garbage_first`` datagrams that are not MAVLink and ``corrupt_first`` heartbeats with a broken CRC.
    As ``udpin`` it answers whoever sent to it. Yields the pymavlink connection.

    As ``udpout`` (to a probe's ``udpin`` port) it speaks only once the probe's connection is open, and the garbage
    and broken heartbeats are sent then, before the probe starts its timeout: nothing is lost before the probe binds,
    and the probe hears them all however slow the machine."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=1, dialect="common")
    stop, probe_open = threading.Event(), threading.Event()
    ml = mavutil.mavlink
    real_connection = mavutil.mavlink_connection

    def bad_first() -> None:
        for _ in range(garbage_first):
            conn.write(b"\x00\x01this is not mavlink")
        for _ in range(corrupt_first):
            buf = bytearray(conn.mav.heartbeat_encode(ml.MAV_TYPE_GROUND_ROVER, ml.MAV_AUTOPILOT_GENERIC,
                                                      0, 0, ml.MAV_STATE_ACTIVE).pack(conn.mav))
            buf[-1] ^= 0xFF  # the CRC's high byte
            conn.write(bytes(buf))

    def probe_connection(*args: object, **kwargs: object) -> object:
        opened = real_connection(*args, **kwargs)
        bad_first()
        probe_open.set()
        return opened

    def run() -> None:
        if url.startswith("udpout:"):
            while not probe_open.wait(0.01):
                if stop.is_set():
                    return
        else:
            bad_first()
        while not stop.wait(0.1):
            while conn.recv_msg() is not None:  # learn the probe's address (udpin) and drain
                pass
            if heartbeats:
                conn.mav.heartbeat_send(ml.MAV_TYPE_GROUND_ROVER, ml.MAV_AUTOPILOT_GENERIC, 0, 0,
                                        ml.MAV_STATE_ACTIVE)

    th = threading.Thread(target=run, name="mavlink-peer", daemon=True)
    if url.startswith("udpout:"):
        mavutil.mavlink_connection = probe_connection
    th.start()
    try:
        yield conn
    finally:
        mavutil.mavlink_connection = real_connection
        stop.set()
        th.join(timeout=60)
        conn.close()
        assert not th.is_alive()


def test_mavlink_heartbeat_on_udpin() -> None:
    with reserved_udp_port() as port, mavlink_peer(f"udpout:127.0.0.1:{port}", sysid=42):
        r = probe_mavlink(f"udpin:127.0.0.1:{port}", timeout_s=ANSWER_S)
    assert r.ok, r.detail
    assert (r.kind, r.info["sysid"], r.info["compid"]) == ("mavlink", 42, 1)
    assert r.info["type"] == "MAV_TYPE_GROUND_ROVER" and r.info["autopilot"] == "MAV_AUTOPILOT_GENERIC"
    assert r.info["mavlink"] == 2 and r.info["bad_crc"] == 0
    assert r.detail == f"udpin:127.0.0.1:{port}: system 42 component 1, MAV_TYPE_GROUND_ROVER, MAV_AUTOPILOT_GENERIC"


def test_mavlink_bad_crcs_before_a_good_heartbeat_are_counted() -> None:
    with reserved_udp_port() as port, mavlink_peer(f"udpout:127.0.0.1:{port}", corrupt_first=3, garbage_first=2):
        r = probe_mavlink(f"udpin:127.0.0.1:{port}", timeout_s=ANSWER_S)
    assert r.ok, r.detail
    assert r.info["bad_crc"] == 3 and r.info["bad_data"] == 2
    assert r.detail.endswith("(3 packets with a bad CRC, 2 bad data)")


def test_mavlink_udpout_sends_a_gcs_heartbeat_and_gets_an_answer() -> None:
    with mavlink_peer("udpin:127.0.0.1:0", sysid=9) as peer:  # the peer's socket is bound first: no race
        port = peer.port.getsockname()[1]
        r = probe_mavlink(f"udpout:127.0.0.1:{port}", timeout_s=ANSWER_S)
    assert r.ok, r.detail
    assert r.info["sysid"] == 9


def test_mavlink_silence() -> None:
    with reserved_udp_port() as port, mavlink_peer(f"udpout:127.0.0.1:{port}", heartbeats=False,
                                                   corrupt_first=2):
        r = probe_mavlink(f"udpin:127.0.0.1:{port}", timeout_s=0.6)
    assert not r.ok
    assert r.detail == f"udpin:127.0.0.1:{port}: no heartbeat within 0.6 s (2 packets with a bad CRC, 0 bad data)"


def test_mavlink_missing_serial_device_and_bad_url(tmp_path: Path) -> None:
    r = probe_mavlink(str(tmp_path / "ttyUSB-gone"))
    assert not r.ok and r.detail == f"{tmp_path / 'ttyUSB-gone'}: no such device"
    r = probe_mavlink("udpin:14550")
    assert not r.ok and r.detail.startswith("udpin:14550: bad connection string: ")


def test_mavlink_tcp_refused() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:  # bound, not listening: connections are refused
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        r = probe_mavlink(f"tcp:127.0.0.1:{port}")
    assert not r.ok and r.detail == f"tcp:127.0.0.1:{port}: cannot open: [Errno 111] Connection refused"


def test_mavlink_on_a_serial_line() -> None:
    """A telemetry radio on a pty: heartbeats written to the other side at 10 Hz; busy while held exclusively."""
    from pymavlink.dialects.v20 import common as mavlink2

    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    enc = mavlink2.MAVLink(None, srcSystem=3, srcComponent=1)
    stop = threading.Event()

    def run() -> None:
        while not stop.wait(0.1):
            hb = enc.heartbeat_encode(mavlink2.MAV_TYPE_SURFACE_BOAT, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0)
            os.write(master, hb.pack(enc))
            while select.select([master], [], [], 0)[0]:  # the probe's GCS heartbeats
                os.read(master, 4096)

    th = threading.Thread(target=run, name="mavlink-serial", daemon=True)
    th.start()
    try:
        r = probe_mavlink(path, baudrate=57600, timeout_s=ANSWER_S)
        other = serial.Serial(path, exclusive=True)
        try:
            busy = probe_mavlink(path)
        finally:
            other.close()
    finally:
        stop.set()
        th.join(timeout=60)
        os.close(master)
        os.close(slave)
    assert r.ok, r.detail
    assert (r.info["sysid"], r.info["type"], r.info["autopilot"]) == (3, "MAV_TYPE_SURFACE_BOAT",
                                                                      "MAV_AUTOPILOT_ARDUPILOTMEGA")
    assert not busy.ok and busy.detail == f"{path}: busy: locked by another process"
