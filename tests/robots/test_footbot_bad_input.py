"""The foot-bot's boards, driver and medium meet bad input: malformed range-and-bearing frames, a payload too long for
a message, known frames of the wrong length, a scan missing a half, a base-board command of the wrong length, a
malformed air item; each is counted and dropped, nothing raises (except the robot side's own too-long payload, a
clear ValueError), and what was good before stays. And a foot-bot group refuses the fields a foot-bot has no use for,
naming them."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from bridge.core.config import Config, ConfigError, load_config
from bridge.core.entities import entity
from bridge.core.hub import Hub
from bridge.core.plan import make_plan
from firmware_sim.board.arduino import Board
from firmware_sim.board.can_controller import Frame
from firmware_sim.robots.footbot.base_board import FootbotBase
from firmware_sim.robots.footbot.rab_board import RabBoard
from swarm_logic.robots.footbot import footbot_db
from swarm_logic.robots.footbot.can_boards import FootbotBoards
from swarm_logic.robots.footbot.interfaces import RANGE_AND_BEARING

DB = footbot_db()
ID = {m.name: m.frame_id for m in DB.messages}
D0, D1 = ID["RAB_DATA_0"], ID["RAB_DATA_1"]
PERIOD_NS = 100_000_000


def data0(payload: bytes, length: int | None = None) -> bytes:
    """RAB_DATA_0 for ``payload`` (its first 7 bytes), with ``length`` in place of its own when given."""
    return bytes([len(payload) if length is None else length]) + payload[:7].ljust(7, b"\0")


def emitted(board: RabBoard, t_ns: int, frames: list[tuple[int, bytes]]) -> tuple[list[bytes], dict]:
    """Hand the board ``frames`` and run it to ``t_ns``: the payloads it emitted and the RAB_SCAN it sent last."""
    out = board.step(t_ns, frames, [])
    scans = [DB.decode_message(i, d) for i, d in out.can if i == ID["RAB_SCAN"]]
    return [a["data"] for a in out.air], scans[-1]


# -- the range-and-bearing board ------------------------------------------------------------------------------------

@pytest.mark.parametrize(("frames", "bad"), [
    ([(D0, data0(b"abc")[:7])], 1),                         # RAB_DATA_0 with DLC 7
    ([(D0, b"")], 1),                                       # ... with DLC 0
    ([(D0, data0(b"abc") + b"\0")], 1),                     # ... with DLC 9
    ([(D0, data0(b"abcdefg", length=11))], 1),              # length byte 11 > 10
    ([(D0, data0(b"abcdefg", length=255))], 1),
    ([(D1, b"xyz")], 1),                                    # RAB_DATA_1 with no RAB_DATA_0 before it
    ([(D0, data0(b"abcdefg", length=9)), (D1, b"xy")], 1),  # the second half of the wrong length
    ([(D0, data0(b"abcdefg", length=9)), (D1, b"xy"), (D1, b"xyz")], 2),  # ... and one with nothing pending
])
def test_a_malformed_rab_frame_is_counted_and_the_last_good_payload_stays(frames: list, bad: int) -> None:
    board = RabBoard(period_ms=100)
    sent, scan = emitted(board, 0, [(D0, data0(b"hello"))])
    assert sent == [b"hello"] and scan["bad_frames"] == 0
    sent, scan = emitted(board, PERIOD_NS, frames)  # never raises
    assert sent == [b"hello"]
    assert board.counters["bad_frames"] == bad and scan["bad_frames"] == bad  # the host reads it in RAB_SCAN
    # a good long payload afterwards is taken whole
    sent, _ = emitted(board, 2 * PERIOD_NS, [(D0, data0(b"0123456789")), (D1, b"789")])
    assert sent == [b"0123456789"] and board.counters["bad_frames"] == bad


def test_a_rab_board_with_no_good_payload_stays_silent() -> None:
    board = RabBoard(period_ms=100)
    sent, scan = emitted(board, 0, [(D0, data0(b"x", length=12)), (D1, b"abc")])
    assert sent == [] and scan["bad_frames"] == 2 and scan["count"] == 0


# -- the robot's driver ---------------------------------------------------------------------------------------------

class StillClock:
    def now(self) -> float:
        return 0.0


@pytest.fixture
def wired() -> Iterator[tuple[FootbotBoards, can.BusABC]]:
    """The driver on python-can's virtual bus, and the boards' side of that bus."""
    ch = f"footbot-{uuid.uuid4().hex}"
    drv = FootbotBoards(can.Bus(interface="virtual", channel=ch), StillClock())
    boards = can.Bus(interface="virtual", channel=ch)
    yield drv, boards
    drv.bus.shutdown()
    boards.shutdown()


def put(bus: can.BusABC, frames: list[tuple[int, bytes]]) -> None:
    for arb_id, data in frames:
        bus.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))


def sent_to_boards(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (m := bus.recv(0.0)) is not None:
        out.append(m)
    return out


def test_a_payload_over_10_bytes_raises_and_sends_nothing(wired: tuple[FootbotBoards, can.BusABC]) -> None:
    drv, boards = wired
    rab = drv.faces()[RANGE_AND_BEARING]
    with pytest.raises(ValueError, match=r"payload of 11 bytes: at most 10 fit in one message"):
        rab.send(bytes(11))
    assert sent_to_boards(boards) == [] and drv.counters["send_errors"] == 0
    rab.send(b"0123456789")  # 10 fit: two frames
    assert [(m.arbitration_id, bytes(m.data)) for m in sent_to_boards(boards)] == [
        (D0, data0(b"0123456789")), (D1, b"789")]


def test_a_known_frame_of_the_wrong_length_is_counted_and_dropped(wired: tuple[FootbotBoards, can.BusABC]) -> None:
    drv, boards = wired
    good = bytes(range(10, 18))
    put(boards, [(ID["PROXIMITY_0"], good), (ID["GROUND"], bytes([51, 102, 153, 204, 0b10000101, 1]))])
    drv.poll()
    assert drv.proximity[:8] == [b / 255 for b in good] and drv.ground == [0.2, 0.4, 0.6, 0.8]
    assert drv.base_ground == [1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    put(boards, [(ID["PROXIMITY_0"], bytes(7)), (ID["GROUND"], bytes(5)), (ID["ENCODERS"], bytes(9)),
                 (ID["RAB_SCAN"], bytes(3)), (0x7FF, bytes(2))])  # the last one is no frame of the robot's: ignored
    assert drv.poll() == 5
    assert drv.counters["bad_frames"] == 4 and drv.counters["scans"] == 0
    assert drv.proximity[:8] == [b / 255 for b in good] and drv.ground == [0.2, 0.4, 0.6, 0.8]  # as they were


def rab_frames(heard: list[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
    """The frames a range-and-bearing board sends for a period in which it heard ``heard`` ([(src, payload)])."""
    board = RabBoard(period_ms=100)
    out = board.step(0, [], [{"src": s, "range_m": 0.5 + s, "bearing_rad": 0.1 * s, "data": d} for s, d in heard])
    return out.can


def test_a_rab_scan_with_a_missing_half_keeps_the_whole_readings(wired: tuple[FootbotBoards, can.BusABC]) -> None:
    """A reading of up to 4 payload bytes is one frame, a longer one two; losing either half of a long one, or the one
    frame of a short one, loses that reading alone (counted)."""
    drv, boards = wired
    frames = rab_frames([(1, b"one"), (2, b"two-and-ten"[:10]), (3, b"three")])
    rx0, rx1 = ID["RAB_RX_0"], ID["RAB_RX_1"]
    assert [i for i, _ in frames] == [rx0, rx0, rx1, rx0, rx1, ID["RAB_SCAN"]]
    put(boards, frames[:2] + frames[3:])  # reading 1's RAB_RX_1 lost
    drv.poll()
    got = drv.faces()[RANGE_AND_BEARING].readings()
    assert [p.data for p in got] == [b"one", b"three"]
    assert got[0].range_m == pytest.approx(1.5) and drv.counters == {**drv.counters, "bad_frames": 1, "scans": 1}
    put(boards, frames[1:])  # reading 0's only frame lost
    drv.poll()
    assert [p.data for p in drv.rab_scan] == [b"two-and-te", b"three"] and drv.counters["bad_frames"] == 2


def test_a_rab_reading_longer_than_a_message_is_counted(wired: tuple[FootbotBoards, can.BusABC]) -> None:
    drv, boards = wired
    frames = rab_frames([(1, b"0123456789")])
    rx0 = bytearray(frames[0][1])
    rx0[3] = (rx0[3] & 0x0F) | (15 << 4)  # length 15: the field has room for it, a message has not
    put(boards, [(frames[0][0], bytes(rx0)), *frames[1:]])
    drv.poll()
    assert drv.rab_scan == [] and drv.counters["bad_frames"] == 1 and drv.counters["scans"] == 1


# -- the base board -------------------------------------------------------------------------------------------------

def test_a_base_command_of_the_wrong_length_is_counted_and_dropped() -> None:
    b = Board(can_rx_depth=16)
    fw = FootbotBase(b)
    fw.setup()
    wheels = DB.get_message_by_name("WHEELS_CMD")
    good = wheels.encode({"left_mm_s": 100, "right_mm_s": 100, "seq": 0})
    for data in (good[:4], good + b"\0"):
        b.can.on_bus_frame(Frame(wheels.frame_id, data, 0, False))
    b.can.on_bus_frame(Frame(ID["LEDS_CMD"], bytes([255, 0]), 0, False))
    fw.loop()
    status = [DB.decode_message(f.arbitration_id, f.data) for f in b.can.take_tx()
              if f.arbitration_id == ID["BASE_STATUS"]]
    assert fw.bad_frames == 3 and status[-1]["bad_frames"] == 3
    assert fw.target_pps == [0.0, 0.0] and b.led_rgb == (0, 0, 0)  # nothing of them was obeyed
    b.time_us += 20_000
    b.can.on_bus_frame(Frame(wheels.frame_id, good, b.time_us, False))
    fw.loop()
    assert fw.target_pps[0] > 0 and fw.bad_frames == 3


# -- the rab medium -------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def footbot_hub(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Hub]:
    d = str(tmp_path_factory.mktemp("hub"))
    cfg = Config.model_validate({"robots": [{"count": 2, "profile": "footbot", "behaviour": "pfsm_searcher"}]})
    h = Hub(make_plan(cfg), d, d, "test")
    yield h
    h.rec.finish()
    h.world.close()


def route(hub: Hub, item: list) -> int:
    """Route ``item`` from robot 0's range-and-bearing board; how many malformed items the hub counted for it."""
    e = entity(0, "rab")
    proc = hub.proc_of[e]
    before = hub.counts["malformed_items"]
    hub._outputs(0, {proc: {"k": 0, "ents": {e: {"out": [item], "wake": PERIOD_NS, "wom": False}}}}, {}, {proc: [e]})
    return hub.counts["malformed_items"] - before


@pytest.mark.parametrize("item", [
    ["rab"], ["rab", "tx"], ["rab", {"op": "rx", "data": b"x"}], ["rab", {"op": "tx"}],
    ["rab", {"op": "tx", "data": "text"}], ["rab", {"op": "tx", "data": [1, 2]}],
    ["rab", {"op": "tx", "data": bytes(256)}],
])
def test_a_malformed_air_item_is_counted_not_fatal(footbot_hub: Hub, item: list) -> None:
    counts = footbot_hub.media["rab"].count[0]
    emitted = counts["emitted"]
    assert route(footbot_hub, item) == 1 and not footbot_hub.dead and counts["emitted"] == emitted


def test_a_good_air_item_is_taken(footbot_hub: Hub) -> None:
    counts = footbot_hub.media["rab"].count[0]
    emitted = counts["emitted"]
    assert route(footbot_hub, ["rab", {"op": "tx", "data": b"hi"}]) == 0 and counts["emitted"] == emitted + 1


# -- configs --------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("field", "line", "why"), [
    ("xbee", "xbee = { series = 2 }", "a foot-bot talks through its range-and-bearing board, not an XBee"),
    ("uwb", "uwb = true", "a foot-bot measures range and bearing with its infrared board, not a UWB module"),
])
def test_a_footbot_group_refuses_a_radio_naming_the_field(tmp_path: Path, field: str, line: str, why: str) -> None:
    p = tmp_path / "c.toml"
    p.write_text(f'[[robots]]\nprofile = "footbot"\nbehaviour = "pfsm_searcher"\n{line}\n')
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == f"{p}: robots[0]: {field}: {why}"


def test_an_external_footbot_logic_needs_its_can_port(tmp_path: Path) -> None:
    p = tmp_path / "c.toml"
    p.write_text('[session]\nspeed = 1\n[[robots]]\nprofile = "footbot"\nlogic = "external"\n')
    with pytest.raises(ConfigError, match=r"robots\[0\]: can\.slcan_pty: an external logic reaches the foot-bot's "
                                          r"boards through its CAN bus: expose it, e\.g\. can = \{ slcan_pty"):
        load_config(p)
    p.write_text(p.read_text() + 'can = { slcan_pty = "r{id}-can" }\n')
    assert load_config(p).robots[0].logic == "external"
