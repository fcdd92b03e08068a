"""``swarm-sitl fuzz``'s own parts that run without atheris: the target list, reading libFuzzer's output, the table."""

from __future__ import annotations

import subprocess
import sys

from bridge.tools.fuzz import Result, _last_exception, fuzz_root, list_targets, table
from fuzz import targets


def test_the_list_names_every_registered_target() -> None:
    listed = list_targets(fuzz_root())
    assert [name for name, _ in listed] == list(targets.MODULE_OF)
    assert all(about for _, about in listed)
    out = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "fuzz", "--list"], capture_output=True, text=True,
                         check=False)
    assert out.returncode == 0 and out.stdout.splitlines()[0].startswith("xbee_api1 ")


def test_an_unknown_target_is_a_usage_error_naming_the_known_ones() -> None:
    out = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "fuzz", "--target", "nope"], capture_output=True,
                         text=True, check=False)
    assert out.returncode == 2 and "no target nope; known: xbee_api1" in out.stderr and "Traceback" not in out.stderr


def test_a_crash_is_read_from_libfuzzer_s_output_and_named_with_its_reproducer() -> None:
    log = ("#2048\tpulse  cov: 812 ft: 1650 corp: 40/2Kb\n"
           "=== Uncaught Python exception: ===\nTraceback (most recent call last):\n"
           "  File \"x.py\", line 3, in run\n    raise ValueError('bad')\nValueError: frame too long\n"
           "==1== ERROR: libFuzzer: deadly signal\nTest unit written to runs/fuzz/zebro_radio/crash-abc\n")
    assert _last_exception(log) == "ValueError: frame too long"
    ok = Result("xbee_at", inputs=100000, cov=900, ft=2000, seconds=61.5)
    bad = Result("zebro_radio", inputs=2048, cov=812, ft=1650, crashes=1, seconds=3.0,
                 reproducer="runs/fuzz/zebro_radio/crash-abc", error="ValueError: frame too long")
    text = table([ok, bad])
    assert "| xbee_at | 100000 | 900 | 2000 | 0 | 0 | 61.5 |" in text
    assert ("zebro_radio: crash (ValueError: frame too long); reproduce with: python -m fuzz replay zebro_radio "
            "runs/fuzz/zebro_radio/crash-abc") in text
    assert not ok.failed and bad.failed


def test_a_slow_unit_report_is_kept_but_is_not_a_failure(tmp_path) -> None:
    """libFuzzer reports its slowest input (over 10 s of wall time) as a slow-unit file: a fuzzing process stopped
    for a while (a paused machine) makes one. A timeout- file is a hang, a crash- file a crash."""
    from pathlib import Path

    from bridge.tools.fuzz import read_output

    log = Path("x.log")
    slow = ("#6707\tREDUCE cov: 1116 ft: 2839 corp: 271/50Kb\n === Timeout: 962s elapsed, timeout=10s ===\n"
            "Slowest unit: 962 s:\nartifact_prefix='runs/fuzz/m/'; Test unit written to runs/fuzz/m/slow-unit-86f8\n"
            "#6792\tDONE   cov: 1116 ft: 2839 corp: 271/50Kb\nDone 6792 runs in 970 second(s)\n"
            "stat::number_of_executed_units: 6792\n")
    r = Result("mavlink_world")
    read_output(r, slow, 0, log)
    assert (r.inputs, r.cov, r.ft, r.crashes, r.hangs, r.failed) == (6792, 1116, 2839, 0, 0, False)
    assert r.slow == "runs/fuzz/m/slow-unit-86f8" and "slow input" in table([r])
    hang = Result("xbee_at")
    read_output(hang, "ALARM: working on the last Unit for 11 seconds\nTest unit written to runs/fuzz/x/timeout-ab\n",
                70, log)
    assert (hang.hangs, hang.crashes, hang.reproducer) == (1, 0, "runs/fuzz/x/timeout-ab")
