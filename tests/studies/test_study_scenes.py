"""The studies' own entities in the recording's Foxglove scene (``LoopFunctions.scene``): the PFSM search's targets
by their state, the RDPSO's subgroups with their best solutions."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from bridge.core.launcher import run_session

pytestmark = pytest.mark.session

ROOT = Path(__file__).resolve().parents[2]


def _scenes(out: Path) -> list[dict]:
    with open(out / "session.mcap", "rb") as f:
        return [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/scene/robots"])]


def test_the_pfsm_targets_are_ringed_by_their_state(tmp_path: Path) -> None:
    res = run_session(str(ROOT / "hil_configs" / "pfsm" / "demo.toml"), {"session.duration_s": 3.0,
                      "session.robots_per_process": 10}, str(tmp_path), progress=None, plot=False)
    assert res.code == 0
    last = _scenes(tmp_path)[-1]
    rings = {e["id"]: e for e in last["entities"] if e["id"].startswith("pfsm/target")}
    assert len(rings) == res.summary["search"]["targets"] > 0
    found = set(res.summary["search"]["found_s"])
    for ident, e in rings.items():
        state = e["metadata"][0]["value"]
        assert (state != "waiting") == (ident.removeprefix("pfsm/target") in found)
        assert e["lines"][0]["type"] == 1 and len(e["lines"][0]["points"]) == 24


def test_the_rdpso_subgroups_and_their_best_solutions(tmp_path: Path) -> None:
    res = run_session(str(ROOT / "hil_configs" / "rdpso" / "rdpso_arena.toml"), {"session.duration_s": 12.0,
                      "session.robots_per_process": 6}, str(tmp_path), progress=None, plot=False)
    assert res.code == 0
    last = _scenes(tmp_path)[-1]
    groups = [e for e in last["entities"] if e["id"].startswith("rdpso/subgroup")]
    assert groups
    for g in groups:
        members = [int(m) for m in g["metadata"][0]["value"].split(",")]
        assert len(g["spheres"]) == 1 and len(g["lines"][0]["points"]) == 2 * len(members)
