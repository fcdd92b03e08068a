"""MCAP recording: readable by the mcap library, digest recomputable, truncated files still readable."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from bridge.core.recorder import Recorder, file_digest, iter_messages


def make(path: Path, n: int = 50) -> Recorder:
    rec = Recorder(path, {"config": "{}"})
    for i in range(n):
        rec.write(i * 10, "/r000/can0", "swarm_sitl.CanFrame", {"id": i, "data": "00", "src": "x", "name": ""})
    return rec


def test_roundtrip_schemas_and_digest(tmp_path: Path) -> None:
    rec = make(tmp_path / "a.mcap")
    rec.finish()
    with open(tmp_path / "a.mcap", "rb") as f:
        reader = make_reader(f)
        msgs = list(reader.iter_messages())
        summary = reader.get_summary()
    assert len(msgs) == 50
    schema = next(iter(summary.schemas.values()))
    assert schema.encoding == "jsonschema" and json.loads(schema.data)["type"] == "object"
    assert file_digest(tmp_path / "a.mcap") == (rec.digest, 50)


def test_same_content_same_digest_and_order_is_enforced(tmp_path: Path) -> None:
    a, b = make(tmp_path / "a.mcap"), make(tmp_path / "b.mcap")
    a.finish()
    b.finish()
    assert a.digest == b.digest
    c = make(tmp_path / "c.mcap", 3)
    with pytest.raises(ValueError, match="sim-time order"):
        c.write(0, "/x", "swarm_sitl.Event", {})
    c.finish()


def test_truncated_recording_is_still_readable(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "t.mcap")
    for i in range(20000):  # several chunks
        rec.write(i, "/world/poses", "swarm_sitl.Poses", {"x": [i], "y": [0], "yaw": [0], "alive": [True], "led": []})
    rec.finish()
    data = (tmp_path / "t.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])  # as if the writer died mid-file
    got = list(iter_messages(cut))
    assert 0 < len(got) < 20000
    assert [t for _, t, _ in got] == list(range(len(got)))


def test_digest_of_a_file_that_is_no_recording_is_an_error(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture) -> None:
    from bridge.tools.cli import main

    readme = Path(__file__).resolve().parents[2] / "README.md"
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    for p in (readme, empty, tmp_path):
        with pytest.raises(ValueError, match="not an MCAP recording"):
            file_digest(p)
        with pytest.raises(SystemExit) as e:
            main(["digest", str(p)])
        out, err = capsys.readouterr()
        assert e.value.code == 2 and out == "", (p, out, err)
        assert err.startswith(f"swarm-sitl digest: {p}: not an MCAP recording"), err
    rec = make(tmp_path / "ok.mcap")  # a recording still digests; also one its writer left without a summary
    rec.finish()
    data = (tmp_path / "ok.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) - 40])
    for p in (tmp_path / "ok.mcap", tmp_path / "cut.mcap"):
        main_code = None
        with pytest.raises(SystemExit) as e:
            main(["digest", str(p)])
        main_code = e.value.code
        assert main_code == 0
        assert json.loads(capsys.readouterr().out) == {"digest": rec.digest, "messages": 50}


def test_a_chunk_ends_at_its_size_or_its_age_in_simulated_time(tmp_path: Path) -> None:
    """A killed writer loses at most its open chunk, and the writer's index keeps one entry a chunk: a chunk ends at
    1 MiB of messages or 2 simulated seconds, whichever comes first."""
    from bridge.core.recorder import CHUNK_BYTES, CHUNK_NS, recover

    slow = Recorder(tmp_path / "slow.mcap")  # 10 s of small messages, 100 a second: five chunks of 2 s
    for i in range(1000):
        slow.write(i * 10_000_000, "/r000/log", "swarm_sitl.Log", {"i": i})
    slow.finish()
    with open(tmp_path / "slow.mcap", "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) == 5
    assert all(c.message_end_time - c.message_start_time < CHUNK_NS for c in chunks)
    data = (tmp_path / "slow.mcap").read_bytes()  # killed: the file is cut where the last chunk would have begun
    (tmp_path / "cut.mcap").write_bytes(data[: chunks[-1].chunk_start_offset + 10])
    saved = recover(tmp_path / "cut.mcap", tmp_path / "saved.mcap")
    assert saved.messages == 800 and saved.last_time_ns == 7_990_000_000

    fast = Recorder(tmp_path / "fast.mcap")  # over 3 MiB within 1 simulated second: ended by size
    payload = "x" * 1000
    for i in range(3 * 1024):
        fast.write(i * 100_000, "/r000/log", "swarm_sitl.Log", {"p": payload})
    fast.finish()
    with open(tmp_path / "fast.mcap", "rb") as f:
        sizes = [c.uncompressed_size for c in make_reader(f).get_summary().chunk_indexes]
    assert len(sizes) == 4 and all(CHUNK_BYTES < s < CHUNK_BYTES + 2048 for s in sizes[:3])
