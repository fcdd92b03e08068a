"""The zebro-decisions experiment: registered with the study, its smoke run, the same bytes from the same seed, the
behaviours found by name."""

from __future__ import annotations

from pathlib import Path

from bridge.core.registry import STUDIES
from bridge.experiments.runner import execute_experiment, experiments
from swarm_logic.behaviours import load_behaviour
from swarm_logic.families.zebro.immature import ZebroImmature
from swarm_logic.families.zebro.mature import ZebroMature
from swarm_logic.families.zebro.silent import ZebroSilent


def test_registered() -> None:
    assert "zebro" in STUDIES.names()
    assert {"zebro-decisions", "zebro-sensitivity"} <= set(experiments())
    assert load_behaviour("zebro_silent") is ZebroSilent
    assert load_behaviour("zebro_immature") is ZebroImmature
    assert load_behaviour("zebro_mature") is ZebroMature


def test_smoke_run_is_deterministic(tmp_path: Path) -> None:
    runs = []
    for k in range(2):
        r = execute_experiment("zebro-decisions", smoke=True, jobs=1, out=tmp_path / str(k), progress=False,
                               only={"setup": ["E3"]})
        assert r.failed == 0 and r.total == 6
        runs.append((tmp_path / str(k) / "trials.csv").read_bytes())
    assert runs[0] == runs[1]
    header = runs[0].decode().splitlines()[0].split(",")
    for col in ("setup", "algorithm", "best", "ignored", "split", "ticks", "tx_per_tick", "rx_per_tick"):
        assert col in header
    report = (tmp_path / "0" / "report.md").read_text()
    assert all(f"Z-S{i}" in report for i in range(1, 8))
