"""swarm_logic is what a robot's companion computer runs: it must not import the simulator."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# what a companion computer would run (cantools decodes the robot's DBC; smbus2 is a Zebro's I2C bus to its legs;
# scipy, shapely, networkx and pyefd are the geometry of the virtual-region planners, which run on a PC or a Pi)
ALLOWED = {"numpy", "can", "serial", "pymavlink", "filterpy", "cantools", "digi", "smbus2", "swarm_logic", "scipy",
           "shapely", "networkx", "pyefd"}


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


def test_no_module_imports_itself_back() -> None:
    """No import cycle at run time (type-only imports aside) among the project's modules: each depends one way."""
    import grimp

    g = grimp.build_graph("bridge", "swarm_logic", "firmware_sim", exclude_type_checking_imports=True)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(g.find_modules_directly_imported_by(v)):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for m in sorted(g.modules):
        if m not in index:
            visit(m)
    assert not cycles, f"import cycles: {cycles}"
