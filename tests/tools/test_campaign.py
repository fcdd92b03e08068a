"""``swarm-sitl campaign flake``: N runs of a pytest selection, half beside a busy core, a table of them, exit 1 if
any run failed (naming it and its log)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from bridge.tools.campaign import _counts


def _campaign(tmp_path: Path, body: str, runs: int) -> subprocess.CompletedProcess:
    (tmp_path / "suite").mkdir()
    (tmp_path / "suite" / "test_it.py").write_text(body)
    return subprocess.run([sys.executable, "-m", "bridge.tools.cli", "campaign", "flake", "--runs", str(runs),
                           "--workers", "1", "--out", str(tmp_path / "logs"), "--", str(tmp_path / "suite")],
                          capture_output=True, text=True)


def test_a_clean_selection_passes_every_run(tmp_path: Path) -> None:
    p = _campaign(tmp_path, "def test_a():\n    assert True\n\ndef test_b():\n    assert 1 + 1 == 2\n", 1)
    assert p.returncode == 0, p.stderr
    assert "| 1 | no | 0 | 2 | 0 |" in p.stdout
    assert "1 runs (0 beside a busy core): 1 passed, 0 failed" in p.stdout
    assert sorted(x.name for x in (tmp_path / "logs").iterdir()) == ["run-001.log"]


def test_a_failing_run_fails_the_campaign_and_is_named(tmp_path: Path) -> None:
    # fails on its second run only: the file it leaves says it ran before
    mark = tmp_path / "ran"
    p = _campaign(tmp_path, f"from pathlib import Path\n\ndef test_once():\n    m = Path({str(mark)!r})\n"
                            "    seen = m.exists()\n    m.touch()\n    assert not seen\n", 2)
    assert p.returncode == 1
    assert "| 1 | no | 0 | 1 | 0 |" in p.stdout
    assert "2 runs (1 beside a busy core): 1 passed, 1 failed (runs 2)" in p.stdout
    assert "| 2 | yes | 1 | 0 | 1 |" in p.stdout and "run-002.log" in p.stdout


def test_pytest_summaries_are_counted() -> None:
    assert _counts("...\n== 3 passed, 1 failed, 2 errors in 4.5s ==\n") == (3, 3)
    assert _counts("....\n4 passed in 0.1s\n") == (4, 0)
    assert _counts("collected nothing") == (0, 0)
