"""swarm_logic is what a robot's companion computer runs: it must not import the simulator."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# what a companion computer would run (cantools decodes the robot's DBC)
ALLOWED = {"numpy", "can", "serial", "pymavlink", "filterpy", "cantools", "digi", "swarm_logic"}


def imports_of(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def test_swarm_logic_imports_only_companion_computer_libraries() -> None:
    stdlib = set(sys.stdlib_module_names) | {"__future__"}
    offenders = {}
    for f in sorted((ROOT / "swarm_logic").rglob("*.py")):
        bad = imports_of(f) - ALLOWED - stdlib
        if bad:
            offenders[str(f.relative_to(ROOT))] = sorted(bad)
    assert not offenders, f"swarm_logic imports outside its allowed set: {offenders}"


def test_import_linter_contracts_hold() -> None:
    exe = Path(sys.executable).with_name("lint-imports")
    r = subprocess.run([str(exe)], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout


def test_swarm_logic_runs_without_simulator_modules() -> None:
    code = (
        "import sys\n"
        "for m in ('pybullet', 'zenoh', 'bridge', 'firmware_sim', 'mcap'):\n"
        "    sys.modules[m] = None  # any import of these now fails\n"
        "import swarm_logic.behaviours, swarm_logic.runner, swarm_logic.robot, swarm_logic.drivers.llc_client\n"
        "print('ok')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.stdout.strip() == "ok", r.stderr
