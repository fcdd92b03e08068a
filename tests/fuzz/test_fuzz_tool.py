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
