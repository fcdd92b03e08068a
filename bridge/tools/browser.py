"""Open a page in a headless browser and read back what it shows: Qt WebEngine (Chromium's engine, wheels on PyPI).

``swarm-sitl report --screenshot`` and the report's own test use it: the page is loaded offscreen with no network and
an off-the-record profile, its console messages and any request it makes beyond ``file:`` and ``data:`` are collected,
its sections and images are read back from the DOM, and once the renderer has painted it at its full height the view is
grabbed to a PNG (the whole page, or one section). Every step waits on the browser's own signals (load finished, a
painted animation frame), never on a guessed delay.

Qt wants one application per process and its own main thread, so the browser runs in a child process
(``python -m bridge.tools.browser``) that prints its findings as JSON; :func:`render` starts it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: Chromium's switches for a machine with no screen, no GPU and no network: no background requests, no updates
CHROMIUM_FLAGS = ("--disable-gpu --disable-background-networking --disable-component-update --disable-sync "
                  "--no-first-run --disable-quic")

#: What the page is asked once loaded: its title, sections, images (decoded size) and full height
_INSPECT = """JSON.stringify({
  title: document.title,
  sections: Array.from(document.querySelectorAll('section')).map(s => {
    const r = s.getBoundingClientRect();
    return {id: s.id, heading: (s.querySelector('h2') || {}).textContent || '',
            x: r.left + scrollX, y: r.top + scrollY, width: r.width, height: r.height};
  }),
  images: Array.from(document.images).map(i => ({alt: i.alt, complete: i.complete, width: i.naturalWidth,
                                                height: i.naturalHeight, shown_width: i.width})),
  tables: document.querySelectorAll('table').length,
  height: Math.ceil(document.documentElement.scrollHeight),
})"""

#: Sets the title to ``marker`` once the view is ``h`` pixels tall and a frame at that size has been painted
_PAINTED = """(function (h, marker) {
  function wait() {
    if (window.innerHeight !== h) { requestAnimationFrame(wait); return; }
    requestAnimationFrame(() => requestAnimationFrame(() => { document.title = marker; }));
  }
  wait();
})(%d, %s)"""


class BrowserError(Exception):
    """The page could not be opened or rendered; the message says why."""


@dataclass
class Rendered:
    """What the browser showed: the page's own findings, plus what went wrong on the way."""

    title: str
    sections: list[dict[str, Any]]
    images: list[dict[str, Any]]
    tables: int
    height: int
    console: list[dict[str, Any]] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)  # every URL asked for beyond file: and data:
    png: str | None = None
    png_size: tuple[int, int] | None = None
    png_colours: int = 0  # distinct colours in the grabbed image: 1 means nothing was painted
    paint_rounds: int = 0  # frames asked for until the grab showed the page

    @property
    def errors(self) -> list[dict[str, Any]]:
        """Console messages at error level (a script error, a resource that failed to load)."""
        return [m for m in self.console if m["level"] == "error"]


def render(page: str | Path, png: str | Path | None = None, *, width: int = 1100, section: str | None = None,
           max_height: int = 12000) -> Rendered:
    """Open ``page`` headless at ``width`` pixels, and grab it to ``png`` (the whole page, or section ``section``)."""
    page = Path(page)
    if not page.is_file():
        raise BrowserError(f"{page}: no such file")
    cmd = [sys.executable, "-m", "bridge.tools.browser", str(page.resolve()), "--width", str(width),
           "--max-height", str(max_height)]
    if png is not None:
        cmd += ["--png", str(Path(png).resolve())]
    if section is not None:
        cmd += ["--section", section]
    p = subprocess.run(cmd, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    if p.returncode != 0:
        why = [ln for ln in p.stderr.strip().splitlines() if ln.startswith("browser: ")]
        raise BrowserError(why[-1][len("browser: "):] if why else
                           f"the headless browser exited with status {p.returncode}: {p.stderr.strip()[-400:]}")
    d = json.loads(p.stdout)
    if d.get("png_size") is not None:
        d["png_size"] = tuple(d["png_size"])
    return Rendered(**d)


def _colours(img: Any) -> int:
    """Distinct colours in a sample of ``img`` (a QImage in RGB32): 1 means nothing was painted there."""
    bits = img.constBits()
    bits.setsize(img.sizeInBytes())
    raw = bytes(bits)
    step = 4 * max(1, img.width() * img.height() // 40000)
    return len({raw[i:i + 4] for i in range(0, len(raw) - 3, step)})


def _main(argv: list[str] | None = None) -> int:  # the child: Qt's event loop, driven by the browser's signals
    a = argparse.ArgumentParser(prog="python -m bridge.tools.browser")
    a.add_argument("page")
    a.add_argument("--png")
    a.add_argument("--section")
    a.add_argument("--width", type=int, default=1100)
    a.add_argument("--max-height", type=int, default=12000)
    args = a.parse_args(argv)

    os.environ["QT_QPA_PLATFORM"] = "offscreen"
    os.environ["QTWEBENGINE_CHROMIUM_FLAGS"] = CHROMIUM_FLAGS
    os.environ.setdefault("QTWEBENGINE_DISABLE_SANDBOX", "1")  # Chromium's sandbox needs user namespaces or root
    os.environ.setdefault("QT_LOGGING_RULES", "*.debug=false;qt.webenginecontext.info=false")
    try:
        from PyQt6.QtCore import QSize, QTimer, QUrl
        from PyQt6.QtGui import QImage
        from PyQt6.QtQuickWidgets import QQuickWidget
        from PyQt6.QtWebEngineCore import (
            QWebEnginePage,
            QWebEngineProfile,
            QWebEngineSettings,
            QWebEngineUrlRequestInfo,
            QWebEngineUrlRequestInterceptor,
        )
        from PyQt6.QtWebEngineWidgets import QWebEngineView
        from PyQt6.QtWidgets import QApplication
    except ImportError as e:
        print(f"browser: a headless browser needs PyQt6-WebEngine (pip install 'swarm-sitl[browser]'): {e}",
              file=sys.stderr)
        return 2

    found: dict[str, Any] = {"console": [], "requests": []}
    failure: list[str] = []

    class Offline(QWebEngineUrlRequestInterceptor):
        """Lets the page read itself and its data: URLs; anything else is noted and blocked."""

        def interceptRequest(self, info: QWebEngineUrlRequestInfo) -> None:
            url = info.requestUrl()
            if url.scheme() not in ("file", "data"):
                if url.toString() not in found["requests"]:  # once, though the page is loaded twice
                    found["requests"].append(url.toString())
                info.block(True)

    class Page(QWebEnginePage):
        def javaScriptConsoleMessage(self, level: Any, message: str, line: int, source: str) -> None:
            if self is not views[0].page():  # the first load's messages: the second one only repeats them
                return
            names = {QWebEnginePage.JavaScriptConsoleMessageLevel.InfoMessageLevel: "info",
                     QWebEnginePage.JavaScriptConsoleMessageLevel.WarningMessageLevel: "warning",
                     QWebEnginePage.JavaScriptConsoleMessageLevel.ErrorMessageLevel: "error"}
            found["console"].append({"level": names.get(level, str(level)), "message": message, "line": line,
                                     "source": source})

    app = QApplication([sys.argv[0]])
    profile = QWebEngineProfile(app)  # no name: off the record, nothing written to disk
    interceptor = Offline(app)
    profile.setUrlRequestInterceptor(interceptor)
    url = QUrl.fromLocalFile(str(Path(args.page).resolve()))
    marker = "swarm-sitl:painted"
    rounds = 30  # frames asked for before giving up on a painted grab: counted in frames, not seconds
    state: dict[str, Any] = {"round": 0, "marked": False, "hooked": False}
    views: list[Any] = []

    def fail(why: str) -> None:
        failure.append(why)
        app.exit(1)

    def open_view(height: int, on_load: Any) -> Any:
        """A view ``args.width`` x ``height`` pixels on the page: sized before it loads, so its first frames are."""
        view = QWebEngineView()
        page = Page(profile, view)
        # as a desktop browser opens a file: it may ask the network, so that the interceptor sees what it asks
        page.settings().setAttribute(QWebEngineSettings.WebAttribute.LocalContentCanAccessRemoteUrls, True)
        view.setPage(page)
        view.resize(QSize(args.width, height))
        page.loadFinished.connect(on_load)
        page.renderProcessTerminated.connect(lambda status, code: fail(f"the browser's renderer died ({code})"))
        views.append(view)
        view.load(url)
        view.show()
        return view

    def measured(ok: bool) -> None:  # 1st load: what the page holds, and how tall it is
        if not ok:
            fail(f"{args.page}: the page did not load")
            return
        views[0].page().runJavaScript(_INSPECT, inspected)

    def inspected(result: Any) -> None:
        if not isinstance(result, str):
            fail(f"{args.page}: the page could not be inspected (scripts disabled?)")
            return
        found.update(json.loads(result))
        if args.png is None:
            app.exit(0)
            return
        if args.section is not None and args.section not in [s["id"] for s in found["sections"]]:
            fail(f"{args.page}: no section {args.section!r} (it has {[s['id'] for s in found['sections']]})")
            return
        height = found["height"]
        if args.section is None:
            height = min(height, args.max_height)
        else:  # down to the section's bottom, whatever the limit
            box = next(s for s in found["sections"] if s["id"] == args.section)
            height = math.ceil(box["y"] + box["height"])
        view = open_view(max(1, height), shoot)
        view.page().titleChanged.connect(titled)

    def shoot(ok: bool) -> None:  # 2nd load, at full height: wait for the renderer to paint it
        if not ok:
            fail(f"{args.page}: the page did not load")
            return
        ask()

    def ask() -> None:
        views[-1].page().runJavaScript(_PAINTED % (views[-1].height(), json.dumps(f"{marker}:{state['round']}")))

    def titled(title: str) -> None:
        if title != f"{marker}:{state['round']}":
            return
        widget = views[-1].findChild(QQuickWidget)
        if widget is None:
            fail(f"{args.page}: the view has no surface to grab")
            return
        if not state["hooked"]:
            widget.quickWindow().afterRendering.connect(lambda: QTimer.singleShot(0, painted))
            state["hooked"] = True
        state["marked"] = True
        widget.quickWindow().update()  # at least one more frame drawn, with what the renderer has sent

    def painted() -> None:
        """Qt drew a frame after the renderer's paint: grab it, or ask for another if it is not the page yet."""
        if not state["marked"]:
            return
        state["marked"] = False
        view = views[-1]
        img = view.grab().toImage().convertToFormat(QImage.Format.Format_RGB32)
        r = img.devicePixelRatio()

        def crop(box: dict[str, Any]) -> Any:  # a section's box, clipped to what the view shows
            x, y = int(box["x"] * r), int(box["y"] * r)
            w = min(int(box["width"] * r), img.width() - x)
            h = min(int(box["height"] * r), img.height() - y)
            return img.copy(x, y, max(1, w), max(1, h))

        # every section in view shows at least its heading once painted: one that is blank is an older frame
        boxes = [s for s in found["sections"] if (args.section is None or s["id"] == args.section)
                 and s["y"] < view.height() and s["height"] > 0]
        parts = [crop(b) for b in boxes] or [img]
        if min(_colours(p) for p in parts) < 2:  # an older frame than the page's: ask for the next
            if state["round"] == rounds:
                fail(f"{args.page}: {rounds} frames drawn and the page is still blank in them")
                return
            state["round"] += 1
            ask()
            return
        out = parts[0] if args.section is not None else img
        if not out.save(args.png, "PNG"):
            fail(f"{args.png}: could not write the image")
            return
        found["png"], found["png_size"] = args.png, [out.width(), out.height()]
        found["png_colours"], found["paint_rounds"] = _colours(out), state["round"] + 1
        app.exit(0)

    open_view(800, measured)
    code = app.exec()
    for view in views:  # pages go before their profile, as Qt wants
        view.page().deleteLater()
    views.clear()
    if code != 0 or failure:
        print(f"browser: {failure[0] if failure else f'Qt exited with status {code}'}", file=sys.stderr)
        return 1
    found.setdefault("png", None)
    found.setdefault("png_size", None)
    found.setdefault("png_colours", 0)
    found.setdefault("paint_rounds", 0)
    print(json.dumps(found))
    return 0


if __name__ == "__main__":
    sys.exit(_main())
