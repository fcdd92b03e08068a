"""``swarm-sitl report``: one self-contained page per session, with its figures, plots, robots, failures, events and
config; a directory that is no session's is refused."""

from __future__ import annotations

import base64
import io
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest
from PIL import Image

from bridge.core.launcher import run_session

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.sections: list[str] = []
        self.images: list[str] = []
        self.cells: list[str] = []
        self.links: list[str] = []
        self._in_td = False

    def handle_starttag(self, tag: str, attrs: list) -> None:
        a = dict(attrs)
        if tag == "section":
            self.sections.append(a["id"])
        elif tag == "img":
            self.images.append(a["src"])
        elif tag == "td":
            self._in_td = True
        elif tag in ("script", "link") or (tag == "a" and a.get("href")):
            self.links.append(tag)

    def handle_endtag(self, tag: str) -> None:
        if tag == "td":
            self._in_td = False

    def handle_data(self, data: str) -> None:
        if self._in_td:
            self.cells.append(data)


def test_the_report_holds_the_session(tmp_path: Path) -> None:
    run = tmp_path / "run"
    res = run_session(str(ROOT / "hil_configs" / "demo.toml"), {
        "robots.count": 4, "session.robots_per_process": 4, "session.duration_s": 4.0,
        "faults": [{"robot": 2, "at_s": 2.0, "kind": "firmware_crash"}]}, str(run), progress=None, plot=False)
    assert res.code == 0
    p = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "report", str(run)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    page = _Page()
    page.feed((run / "report.html").read_text())
    assert page.sections == ["figures", "trajectories", "connectivity", "rssi", "robots", "failures", "events",
                             "config"]
    assert not page.links  # self-contained: no script, stylesheet or link to load
    for src in page.images:  # every plot an embedded PNG that decodes
        assert src.startswith("data:image/png;base64,")
        img = Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1])))
        assert img.format == "PNG" and img.size[0] > 300
    assert res.summary["digest"] in page.cells and "raised" in page.cells  # the figures; robot 2's failure


def test_a_directory_that_is_no_session_is_refused(tmp_path: Path) -> None:
    p = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "report", str(tmp_path)], capture_output=True,
                       text=True)
    assert p.returncode == 2 and "not a session's output directory" in p.stderr and "Traceback" not in p.stderr
