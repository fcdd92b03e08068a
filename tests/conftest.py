"""Shared fixtures. Session tests start real multi-process sessions; nothing opens a fixed port."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "hil_configs" / "demo.toml"
os.environ.setdefault("MAVLINK20", "1")
pytest_plugins = ["pytester"]


@pytest.fixture
def demo_config() -> Path:
    return DEMO


def swarm_sitl_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "bridge.tools.cli", *args]
