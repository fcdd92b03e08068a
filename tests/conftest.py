"""Shared fixtures. Session tests start real multi-process sessions; nothing opens a fixed port."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "hil_configs" / "demo.toml"
os.environ.setdefault("MAVLINK20", "1")
pytest_plugins = ["pytester"]


@pytest.fixture
def demo_config() -> Path:
    return DEMO


def swarm_sitl_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "bridge.tools.cli", *args]


@pytest.hookimpl(trylast=True)  # after pytest's own grouping of items by their fixtures
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The modules with the longest tests first (a test marked ``long``, or the example project's, which run whole
    sessions of minutes), then those with other sessions, then the rest; each module kept whole, so that its
    module-scoped fixtures run once. With ``--dist worksteal`` (``make test``) an idle worker takes over the other's
    queue, so the run ends on short tests rather than on a long session started last."""
    def rank(it: pytest.Item) -> int:
        if it.get_closest_marker("long") is not None or it.path.is_relative_to(EXAMPLES):
            return 0
        return 1 if it.get_closest_marker("session") is not None else 2

    module_rank: dict[Path, int] = {}
    for it in items:
        module_rank[it.path] = min(module_rank.get(it.path, 2), rank(it))
    items.sort(key=lambda it: module_rank[it.path])
