"""CAN export: a session's frames survive the trip through python-can's log formats, and decode with the DBC.

Timestamps are the frames' wire end times in simulated seconds. The text formats (candump -l, ASC: 1 µs
steps; CSV: float repr) give them back exactly, since at the buses' bit rates every wire end time is a
whole number of microseconds. BLF stores integer nanoseconds since the measurement start, which
python-can truncates from a float: within 1 ns. TRC restores its start from a header in days: within 1 µs.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter, defaultdict
from collections.abc import Sequence
from pathlib import Path

import can
import pytest
from mcap.writer import Writer

from bridge.core.recorder import Recorder, iter_messages
from bridge.media.can import CanMedium, Delivery
from bridge.tools import canlog
from swarm_logic.robots.eswarbot import eswarbot_llc_db
from tests.conftest import swarm_sitl_cmd

ROOT = Path(__file__).resolve().parents[2]
DBC = ROOT / "swarm_logic" / "robots" / "eswarbot" / "eswarbot_llc.dbc"
Q_NS = 10_000_000
TOL_S = {".log": 0.0, ".asc": 0.0, ".csv": 0.0, ".blf": 1e-9, ".trc": 1e-6}


def write_delivery(rec: Recorder, t_ns: int, robot: int, d: Delivery) -> None:
    """Record a delivered frame as ``Hub._deliver`` does."""
    name = {m.frame_id: m.name for m in eswarbot_llc_db().messages}.get(d.arbitration_id, "")
    rec.write_json(t_ns, f"/r{robot:03d}/can0", "swarm_sitl.CanFrame", (
        f'{{"id":{d.arbitration_id},"data":"{d.data.hex()}","src":"{d.src}",'
        f'"name":"{name}","wire_end_ns":{d.wire_end_ns}}}').encode())


def make_recording(path: Path, robots: int = 3, quanta: int = 50, extra: Sequence[tuple[int, dict]] = (),
                   metadata: dict[str, str] | None = None) -> None:
    """A recording with the hub's CAN records: each robot's LLC and logic offer DBC frames on the robot's
    bus every quantum, the bus delivers them as ``CanMedium`` decides (at a quantum boundary, possibly
    several quanta after they were offered). ``extra`` records (robot, payload) come last."""
    db = eswarbot_llc_db()
    status = db.get_message_by_name("STATUS")
    buses = [CanMedium(f"r{r:03d}") for r in range(robots)]
    deliveries: dict[int, list[tuple[int, Delivery]]] = defaultdict(list)
    rec = Recorder(path, metadata or {"config": "{}"})
    for k in range(quanta):
        t = k * Q_NS
        for r, d in deliveries.pop(t, []):
            write_delivery(rec, t, r, d)
        rec.write(t, "/world/poses", "swarm_sitl.Poses", {"x": [0.0] * robots})
        for r, bus in enumerate(buses):
            llc, logic = f"r{r:03d}/llc", f"r{r:03d}/logic"
            bus.offer(logic, k, 0x100, db.encode_message("DRIVE_CMD", {
                "v_mm_s": 100 + k, "w_mrad_s": -r, "seq": k % 256}))
            bus.offer(llc, 3 * k, 0x180, db.encode_message("ENCODERS", {"left": k * 7, "right": -k * 5}))
            bus.offer(llc, 3 * k + 1, 0x181, db.encode_message("ODOMETRY", {
                "x_mm": k, "y_mm": r, "theta_mrad": 3, "v_mm_s": 100}))
            if k % 10 == 0:
                bus.offer(llc, 3 * k + 2, 0x185, status.encode({
                    **{sig.name: 0 for sig in status.signals}, "heartbeat": k // 10, "uptime_s": k // 100}))
            for d in bus.transmit(t, Q_NS):
                deliveries[d.t_ns].append((r, d))
    t_end = quanta * Q_NS
    for t in sorted(deliveries):
        t_end = t
        for r, d in deliveries[t]:
            write_delivery(rec, t, r, d)
    for r, payload in extra:
        rec.write(t_end, f"/r{r:03d}/can0", "swarm_sitl.CanFrame", payload)
    rec.finish()


def recorded_frames(path: Path) -> list[tuple[int, int, bytes, int]]:
    """(robot, id, data, wire_end_ns) of every CAN record, straight from the JSON, sorted by wire end."""
    out = []
    for topic, _t, payload in iter_messages(path):
        if topic.endswith("/can0"):
            d = json.loads(payload)
            out.append((int(topic[2:topic.index("/", 1)]), d["id"], bytes.fromhex(d["data"]), d["wire_end_ns"]))
    return sorted(out, key=lambda f: (f[3], f[0]))


def robot_of_channel(suffix: str, channel: int | str) -> int:
    """The robot a read-back frame's channel names: ``rNNN`` in candump logs, robot + 1 in TRC (python-can's
    TRC reader does not undo the writer's +1), the robot itself in ASC and BLF."""
    if suffix == ".log":
        return int(str(channel)[1:])
    return int(channel) - 1 if suffix == ".trc" else int(channel)


def check_roundtrip(mcap: Path, out: Path) -> list[can.Message]:
    want = recorded_frames(mcap)
    n = canlog.export(mcap, out)
    back = list(can.LogReader(out))
    assert n == len(want) == len(back) > 0
    tol = TOL_S[out.suffix]
    for (robot, arb_id, data, wire_end), msg in zip(want, back, strict=True):
        assert (msg.arbitration_id, bytes(msg.data), msg.is_extended_id) == (arb_id, data, False)
        assert abs(msg.timestamp - wire_end / 1e9) <= tol, (out.suffix, msg, wire_end)
        if tol == 0.0:
            assert msg.timestamp == wire_end / 1e9
        if out.suffix != ".csv":  # CSV has no channel or direction columns
            assert robot_of_channel(out.suffix, msg.channel) == robot
            assert msg.is_rx
    return back


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("canlog") / "session.mcap"
    make_recording(path)
    return path


@pytest.fixture(scope="module")
def real_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("session")
    r = subprocess.run(swarm_sitl_cmd("run", str(ROOT / "hil_configs" / "demos" / "random_walk.toml"),
                                       "--duration", "2",
                                      "--robots", "3", "--quiet", "--out", str(out)),
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return out / "session.mcap"


def test_iter_frames_are_time_ordered_with_wire_end_timestamps(synthetic: Path) -> None:
    frames = list(canlog.iter_frames(synthetic))
    want = recorded_frames(synthetic)
    assert [(int(m.channel[1:]), m.arbitration_id, bytes(m.data), round(m.timestamp * 1e9)) for m in frames] == want
    assert all(m.is_rx and not m.is_extended_id and not m.is_error_frame for m in frames)
    ts = [m.timestamp for m in frames]
    assert ts == sorted(ts)
    only = list(canlog.iter_frames(synthetic, robots={1}))
    assert only and {m.channel for m in only} == {"r001"}
    assert len(only) == sum(1 for f in want if f[0] == 1)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv", ".trc"])
def test_export_roundtrips_through_python_can(synthetic: Path, tmp_path: Path, suffix: str) -> None:
    check_roundtrip(synthetic, tmp_path / f"can{suffix}")


def test_extended_error_and_unknown_records(tmp_path: Path) -> None:
    mcap = tmp_path / "s.mcap"
    make_recording(mcap, robots=1, quanta=2, extra=[
        (0, {"id": 0x18FF0102, "data": "0102", "src": "r000/x", "name": "", "wire_end_ns": 30_000_000, "ext": True}),
        (0, {"id": 0x7FF + 1, "data": "aa", "src": "r000/x", "name": "", "wire_end_ns": 30_000_001}),
        (0, {"id": 0, "data": "", "src": "r000/x", "name": "", "wire_end_ns": 30_000_002, "error": True}),
        (0, {"id": 0x123, "data": "00" * 64, "src": "r000/x", "wire_end_ns": 30_000_003, "fd": True}),
        (0, {"kind": "overload", "wire_end_ns": 30_000_004}),
        (0, {"id": "0x123", "data": "zz"}),
    ])
    tail = list(canlog.iter_frames(mcap))[-3:]
    assert [(m.arbitration_id, m.is_extended_id, m.is_error_frame) for m in tail] == [
        (0x18FF0102, True, False), (0x800, True, False), (0, False, True)]
    for suffix in (".log", ".asc", ".blf"):
        canlog.export(mcap, tmp_path / f"x{suffix}")
        back = list(can.LogReader(tmp_path / f"x{suffix}"))[-3:]
        assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in back[:2]] == [
            (0x18FF0102, True, b"\x01\x02"), (0x800, True, b"\xaa")], suffix
        assert back[2].is_error_frame, suffix


def test_every_frame_decodes_with_the_dbc(synthetic: Path, tmp_path: Path) -> None:
    out = tmp_path / "can.blf"
    n = canlog.export(synthetic, out)
    decoded = list(canlog.decode(out))
    assert len(decoded) == n
    assert all(name and signals for _m, name, signals in decoded)
    assert {name for _m, name, _s in decoded} == {"DRIVE_CMD", "ENCODERS", "ODOMETRY", "STATUS"}
    drive = [s for m, name, s in decoded if name == "DRIVE_CMD" and m.channel == 2]
    assert [s["v_mm_s"] for s in drive] == [100 + k for k in range(len(drive))]
    assert {s["w_mrad_s"] for s in drive} == {-2}


def test_decode_unknown_ids_and_short_payloads(tmp_path: Path) -> None:
    out = tmp_path / "x.log"
    out.write_text("(0.001000) r000 7FF#01 R\n(0.002000) r000 185#01 R\n(0.003000) r000 185#010000000000 R\n")
    got = [(name, signals) for _m, name, signals in canlog.decode(out)]
    assert got[0] == ("", {}) and got[1] == ("STATUS", {})
    assert got[2][0] == "STATUS" and got[2][1]["heartbeat"] == 1


@pytest.mark.session
def test_real_session_exports_and_decodes(real_session: Path, tmp_path: Path) -> None:
    for suffix in (".log", ".asc", ".blf"):
        check_roundtrip(real_session, tmp_path / f"can{suffix}")
    decoded = list(canlog.decode(tmp_path / "can.asc"))
    assert all(name and signals for _m, name, signals in decoded)
    names = {name for _m, name, _s in decoded}
    assert {"DRIVE_CMD", "ODOMETRY", "STATUS", "ENCODERS", "SONAR", "LIGHT", "BATTERY"} <= names
    assert {m.channel for m, _n, _s in decoded} == {0, 1, 2}


@pytest.mark.session
def test_cantools_decode_reads_the_candump_log(real_session: Path, tmp_path: Path) -> None:
    out = tmp_path / "can.log"
    n = canlog.export(real_session, out)
    with open(out) as f:
        r = subprocess.run([sys.executable, "-m", "cantools", "decode", str(DBC)], stdin=f,
                           capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count(" R ::\n") == n
    assert "Unknown frame id" not in r.stdout
    for text in ("STATUS(", "heartbeat:", "DRIVE_CMD(", "v_mm_s:", "ODOMETRY(", "theta_mrad:", "ENCODERS("):
        assert text in r.stdout, text


def test_truncated_recording_exports_what_it_holds(tmp_path: Path) -> None:
    full = tmp_path / "full.mcap"
    make_recording(full, robots=4, quanta=400)
    frames = [(m.timestamp, m.channel, m.arbitration_id, bytes(m.data)) for m in canlog.iter_frames(full)]
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])  # as if the writer died mid-file: no summary, a partial chunk
    n = canlog.export(cut, tmp_path / "cut.log")
    back = [(m.timestamp, m.channel, m.arbitration_id, bytes(m.data)) for m in can.LogReader(tmp_path / "cut.log")]
    assert 0 < n == len(back) < len(frames)
    assert Counter(back) <= Counter(frames)
    # all but the frames of the last delivery read (the chunk may end within it) are a prefix of the whole
    done = back[-1][0] - 2 * Q_NS / 1e9
    assert [f for f in back if f[0] < done] == [f for f in frames if f[0] < done]
    assert back == sorted(back, key=lambda f: f[0])


def test_killed_writer(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    code = (
        "import os, signal, sys\n"
        "from bridge.core.recorder import Recorder\n"
        "rec = Recorder(sys.argv[1])\n"
        "for i in range(20000):\n"
        "    rec.write((i + 1) * 10_000, '/r007/can0', 'swarm_sitl.CanFrame',\n"
        "              {'id': 0x185, 'data': f'{i % 256:02x}0000000000', 'src': 'r007/llc', 'name': 'STATUS',\n"
        "               'wire_end_ns': (i + 1) * 10_000 - 3000})\n"
        "os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    r = subprocess.run([sys.executable, "-c", code, str(path)], cwd=ROOT, capture_output=True, timeout=60)
    assert r.returncode == -9, r.stderr
    n = canlog.export(path, tmp_path / "k.asc")
    back = list(can.LogReader(tmp_path / "k.asc"))
    assert 0 < n == len(back) < 20000
    assert [m.data[0] for m in back] == [i % 256 for i in range(n)]
    assert [m.timestamp for m in back] == [((i + 1) * 10_000 - 3000) / 1e9 for i in range(n)]
    assert {m.channel for m in back} == {7}


def test_errors_name_the_file(synthetic: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"x\.xyz: unknown CAN log format '\.xyz'"):
        canlog.export(synthetic, tmp_path / "x.xyz")
    with pytest.raises(ValueError, match=r"x\.asc\.gz: unknown CAN log format '\.gz'"):
        canlog.export(synthetic, tmp_path / "x.asc.gz")
    with pytest.raises(ValueError, match=r"nope\.mcap: no such file"):
        canlog.export(tmp_path / "nope.mcap", tmp_path / "x.asc")
    text = tmp_path / "notes.mcap"
    text.write_text("just some text, not a recording\n")
    with pytest.raises(ValueError, match=r"notes\.mcap: not an MCAP file"):
        canlog.export(text, tmp_path / "x.asc")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty\.mcap: not an MCAP file"):
        canlog.export(empty, tmp_path / "x.asc")
    magic_only = tmp_path / "magic.mcap"
    magic_only.write_bytes(synthetic.read_bytes()[:10])
    with pytest.raises(ValueError, match=r"magic\.mcap: MCAP file ends or is damaged before its header"):
        canlog.export(magic_only, tmp_path / "x.asc")
    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="someone-else")
        w.finish()
    with pytest.raises(ValueError, match=r"other\.mcap: an MCAP file, but not a swarm-sitl session recording "
                                         r"\(written by 'someone-else'\)"):
        canlog.export(other, tmp_path / "x.asc")
    assert not (tmp_path / "x.asc").exists() and not (tmp_path / "x.xyz").exists()
    with pytest.raises(ValueError, match=r"gone\.log: no such file"):
        canlog.decode(tmp_path / "gone.log")
    with pytest.raises(ValueError, match=r"session\.bin: unknown CAN log format"):
        canlog.decode(synthetic.with_suffix(".bin"))


def test_session_without_can_exports_nothing(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "s.mcap")
    rec.write(0, "/world/poses", "swarm_sitl.Poses", {"x": [0.0]})
    rec.finish()
    assert canlog.export(tmp_path / "s.mcap", tmp_path / "s.log") == 0
    assert list(can.LogReader(tmp_path / "s.log")) == []


def test_damaged_recording_is_an_error_and_leaves_no_output(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    make_recording(path, quanta=20)
    data = bytearray(path.read_bytes())
    pos = len(b"\x89MCAP0\r\n")
    while data[pos] != 0x06:  # skip records (opcode, u64 length, content) up to the first chunk
        pos += 9 + int.from_bytes(data[pos + 1:pos + 9], "little")
    chunk_len = int.from_bytes(data[pos + 1:pos + 9], "little")
    data[pos + 9 + chunk_len - 20] ^= 0xFF  # a byte of its compressed records
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=r"s\.mcap: damaged recording: "):
        canlog.export(path, tmp_path / "s.blf")
    assert not (tmp_path / "s.blf").exists()


@pytest.mark.parametrize("metadata", [{"config": "{}", "robots": "3"}, None], ids=["hub-metadata", "no-metadata"])
def test_a_robot_not_in_the_run_is_an_error_and_leaves_no_output(tmp_path: Path, metadata: dict | None,
                                                                  capsys: pytest.CaptureFixture) -> None:
    """``Hub`` records the robot count in the recording's "session" metadata; without it (an older or foreign
    writer) the robots are those the recording has topics of."""
    from bridge.tools.cli import main

    mcap = tmp_path / "session.mcap"
    make_recording(mcap, robots=3, quanta=5, metadata=metadata)
    out = tmp_path / "r7.log"
    what = "run" if metadata else "recording"
    for robots in ({7}, {1, 7}):
        with pytest.raises(ValueError, match=rf"session\.mcap: robot 7 is not in this {what}; its robots are 0, 1, 2"):
            canlog.export(mcap, out, robots)
        assert not out.exists()
    with pytest.raises(SystemExit) as e:
        main(["canlog", str(tmp_path), str(out), "--robot", "7", "--robot", "9"])
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    assert f"robots 7, 9 are not in this {what}; its robots are 0, 1, 2" in err, err
    assert not out.exists()
    assert canlog.export(mcap, out, {2}) > 0  # a robot of the run still exports


@pytest.mark.session
def test_canlog_of_a_robot_not_in_a_real_run(real_session: Path, tmp_path: Path) -> None:
    out = tmp_path / "r7.log"
    r = subprocess.run(swarm_sitl_cmd("canlog", str(real_session.parent), str(out), "--robot", "7"),
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "robot 7 is not in this run; its robots are 0, 1, 2" in r.stderr, r.stderr
    assert not out.exists()
