"""The swarm-sitl pytest plugin (entry point ``pytest11``): sessions a test drives in simulated time.

    def test_the_swarm_spreads(swarm_session):
        s = swarm_session("hil_configs/demo.toml", {"robots.count": 4, "session.seed": 7})
        s.run_until(lambda s: s.distance_m(0) > 0.5, timeout_s=30)
        assert s.alive(0)

``swarm_session(config, overrides=None, out_dir=None, mavlink=False)`` starts a session
(``bridge.testing.SwarmSession``) recorded under the test's ``tmp_path`` (or ``out_dir``), held at simulated time 0,
and stops it when the test ends. When a test fails, its report gets a ``swarm-sitl`` section per session: the
simulated time it stood at, its recording's path and the last log lines of the robots the test touched. ``pytest
-n`` runs tests with sessions in parallel: each session has its own namespace, socket and output directory.

This module imports nothing of the simulator until a test asks for a session: it is loaded by every pytest run in
the environment.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

_SESSIONS = pytest.StashKey[list]()
_FAILED = pytest.StashKey[bool]()  # the test itself failed: its report has said what went wrong


@pytest.fixture
def swarm_session(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Callable[..., Any]]:
    """Start a session from a config with overrides, held at simulated time 0: ``swarm_session(config,
    overrides=None, out_dir=None, mavlink=False) -> SwarmSession`` (``mavlink``: every robot gets its MAVLink face, and
    ``session.mavlink`` is a ground station of the swarm). Every session it started is stopped when the test ends."""
    from bridge.testing.session import SwarmSession

    sessions: list[SwarmSession] = []
    request.node.stash[_SESSIONS] = sessions

    def start(config: str | Path, overrides: dict[str, Any] | None = None, out_dir: str | Path | None = None,
              mavlink: bool = False) -> SwarmSession:
        out = Path(out_dir) if out_dir is not None else tmp_path / f"session-{len(sessions)}"
        s = SwarmSession(config, overrides, out, mavlink=mavlink)
        sessions.append(s)
        return s.start()

    yield start
    errors = []
    for s in sessions:  # every one is stopped, whatever another's stop raises
        try:
            s.stop()
        except RuntimeError:  # one that never started (its config was refused: the test saw that already)
            pass
        except Exception as e:  # its launcher failed (the test saw it too, if it got that far)
            errors.append(e)
    if errors and not request.node.stash.get(_FAILED, False):
        raise errors[0]


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    report = yield
    if report.failed:
        item.stash[_FAILED] = True
    if report.failed and report.when == "call":
        for i, s in enumerate(item.stash.get(_SESSIONS, [])):
            report.sections.append((f"swarm-sitl session {i}", s.describe()))
    return report
