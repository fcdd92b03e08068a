"""``swarm-sitl bench --study NAME`` finds a study's benchmark through its ``Study.bench``; the core names none."""

from __future__ import annotations

import importlib
import inspect
import subprocess
import sys

from bridge.core.registry import STUDIES
from tests.conftest import ROOT


def test_every_declared_study_bench_is_a_function_taking_the_bench_options() -> None:
    declared = {name: st.bench for name, st in STUDIES.items() if st.bench}
    assert {"rdpso", "zebro", "pfsm"} <= set(declared)
    for ref in declared.values():
        module, _, fn = ref.partition(":")
        params = inspect.signature(getattr(importlib.import_module(module), fn)).parameters
        assert {"quick", "duration", "out_dir"} <= set(params)


def test_an_unknown_study_or_one_without_a_bench_is_a_clear_error() -> None:
    for study, msg in (("nosuch", "unknown study 'nosuch'"),):
        r = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "bench", "--study", study], cwd=ROOT,
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 1 and msg in r.stderr and "Traceback" not in r.stderr


def test_the_core_bench_knows_no_study() -> None:
    src = (ROOT / "bridge" / "tools" / "bench.py").read_text().lower()
    assert "rdpso" not in src and "zebro" not in src and "pfsm" not in src
