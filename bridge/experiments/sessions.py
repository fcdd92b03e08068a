"""Sessions as an experiment's trials: a config built in code, written, run and summarised."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bridge.core.config import to_toml


def run_config(cfg: dict[str, Any], workdir: Path, name: str = "session") -> tuple[dict[str, Any], Path]:
    """Write ``cfg`` to ``workdir/NAME.toml``, run it into ``workdir/session``, return its summary and that output
    directory; a session that fails raises ``RuntimeError`` with its error."""
    from bridge.core.launcher import run_session

    path = workdir / f"{name}.toml"
    path.write_text(to_toml(cfg))
    out = workdir / "session"
    res = run_session(str(path), None, str(out), progress=None, plot=False)
    if res.code != 0:
        raise RuntimeError(f"session failed ({res.code}): {res.summary.get('error')}")
    return json.loads((out / "summary.json").read_text()), out
