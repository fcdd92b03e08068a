"""``swarm-sitl report``: one self-contained page per session, with its figures, plots, robots, failures, events and
config, which a headless browser opens and renders whole; a directory that is no session's is refused."""

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
from bridge.tools.browser import render

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


SECTIONS = ["figures", "trajectories", "connectivity", "rssi", "robots", "failures", "events", "config"]


@pytest.fixture(scope="module")
def reported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """A 4-s session of 4 robots, robot 2's firmware crashing at 2 s, and its report."""
    run = tmp_path_factory.mktemp("report") / "run"
    res = run_session(str(ROOT / "hil_configs" / "demo.toml"), {
        "robots.count": 4, "session.robots_per_process": 4, "session.duration_s": 4.0,
        "faults": [{"robot": 2, "at_s": 2.0, "kind": "firmware_crash"}]}, str(run), progress=None, plot=False)
    assert res.code == 0
    p = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "report", str(run)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return run, res.summary


def test_the_report_holds_the_session(reported: tuple[Path, dict]) -> None:
    run, summary = reported
    page = _Page()
    page.feed((run / "report.html").read_text())
    assert page.sections == SECTIONS
    assert not page.links  # self-contained: no script, stylesheet or link to load
    for src in page.images:  # every plot an embedded PNG that decodes
        assert src.startswith("data:image/png;base64,")
        img = Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1])))
        assert img.format == "PNG" and img.size[0] > 300
    assert summary["digest"] in page.cells and "raised" in page.cells  # the figures; robot 2's failure


def test_a_headless_browser_renders_the_report(reported: tuple[Path, dict], tmp_path: Path) -> None:
    run, _ = reported
    shown = render(run / "report.html", tmp_path / "page.png")
    assert shown.title == "swarm-sitl report: demo"
    assert not shown.errors and not shown.requests  # no script error, nothing fetched from anywhere
    assert [s["id"] for s in shown.sections] == SECTIONS
    assert all(s["height"] > 0 and s["width"] > 300 for s in shown.sections)  # laid out, one below the other
    assert [s["y"] for s in shown.sections] == sorted(s["y"] for s in shown.sections)
    assert len(shown.images) == 3 and shown.tables == 4  # the plots; figures, robots, failures, events
    for img in shown.images:  # decoded by the browser, and shown at a readable width
        assert img["complete"] and img["width"] > 300 and img["height"] > 200 and img["shown_width"] > 300
    assert shown.png_size == (1100, shown.height)  # the whole page, grabbed once painted to its bottom
    png = Image.open(tmp_path / "page.png")
    assert png.size == shown.png_size and shown.png_colours > 50
    robots = render(run / "report.html", tmp_path / "robots.png", section="robots")
    box = next(s for s in robots.sections if s["id"] == "robots")
    assert robots.png_size == (int(box["width"]), int(box["height"])) and robots.png_colours > 2


def test_the_browser_tells_a_broken_page(tmp_path: Path) -> None:
    """What the report's test relies on can fail: a script error and a request beyond the page are reported (the
    request blocked before it leaves), a top-of-page grab is as tall as asked."""
    page = tmp_path / "broken.html"
    page.write_text('<!doctype html><html><head><title>broken</title></head><body><section id="a"><h2>A</h2>'
                    '<img alt="far" src="http://192.0.2.1/x.png"></section><div style="height:3000px"></div>'
                    '<script>undefinedFunction();</script></body></html>')
    shown = render(page, tmp_path / "top.png", width=600, max_height=700)
    assert shown.title == "broken" and [s["id"] for s in shown.sections] == ["a"]
    assert shown.requests == ["http://192.0.2.1/x.png"]
    assert len(shown.errors) == 1 and "undefinedFunction" in shown.errors[0]["message"]
    assert shown.images[0]["width"] == 0  # never loaded
    assert shown.height > 3000 and shown.png_size == (600, 700)


def test_the_screenshot_of_a_missing_section_is_refused(reported: tuple[Path, dict], tmp_path: Path) -> None:
    run, _ = reported
    p = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "report", str(run), "--screenshot",
                        str(tmp_path / "x.png"), "--section", "nowhere"], capture_output=True, text=True)
    assert p.returncode == 1 and "no section 'nowhere'" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "x.png").exists()


def test_a_directory_that_is_no_session_is_refused(tmp_path: Path) -> None:
    p = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "report", str(tmp_path)], capture_output=True,
                       text=True)
    assert p.returncode == 2 and "not a session's output directory" in p.stderr and "Traceback" not in p.stderr
