"""``swarm-sitl fuzz``: run the fuzz targets (``fuzz/``, one per parser a byte from outside reaches) under atheris, a
coverage-guided fuzzer on libFuzzer, each in a process of its own for a fixed budget, and print what they did.

Each target runs ``python -m fuzz run NAME`` in the checkout's root with libFuzzer's ``-runs`` (inputs),
``-max_total_time`` (seconds), ``-timeout`` (seconds one input may take: beyond it, a hang) and ``-seed`` (a run is
reproducible), on two corpus directories: a scratch one under ``--out`` (first: what the run finds goes there) and the
committed ``fuzz/corpus/<target>/``. With ``--merge`` the scratch finds that reach new code are merged into the
committed corpus (libFuzzer's ``-merge=1 -use_counters=0``: only inputs that cover an edge it does not, so the corpus
stays small). A crash (an exception the parser does not document) or a hang stops that target; its input is saved
under ``--out/<target>/`` and named in the table, the log beside it (``--out/<target>.log``) has the traceback. The
table: target, inputs executed, coverage (libFuzzer's ``cov``, edges, and ``ft``, features), crashes, hangs, seconds.
Exit 1 if any target crashed or hung, 2 if a target could not run.

atheris is not in the project's own requirements: ``make fuzz`` installs it (``requirements-fuzz.lock``).
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

_COV = re.compile(r"\bcov: (\d+) ft: (\d+)")
_EXECUTED = re.compile(r"stat::number_of_executed_units: (\d+)")
_DONE = re.compile(r"Done (\d+) runs in (\d+) second")
_ARTIFACT = re.compile(r"Test unit written to (\S+)")


@dataclass
class Result:
    """One target's run, as read from libFuzzer's output."""

    target: str
    inputs: int = 0
    cov: int = 0
    ft: int = 0
    crashes: int = 0
    hangs: int = 0
    seconds: float = 0.0
    reproducer: str | None = None
    slow: str | None = None  # libFuzzer's slowest input, when it reported one (not a failure)
    error: str | None = None  # the exception a crash raised (its last traceback line), or why the target did not run
    code: int = 0

    @property
    def failed(self) -> bool:
        return bool(self.crashes or self.hangs or self.error)


def fuzz_root() -> Path:
    """The checkout holding ``fuzz/`` (an editable install: the directory above the ``bridge`` package), else the
    current directory."""
    for root in (Path(__file__).resolve().parents[2], Path.cwd()):
        if (root / "fuzz" / "__main__.py").is_file():
            return root
    raise FileNotFoundError("fuzz/__main__.py (run swarm-sitl fuzz from the project's checkout)")


def list_targets(root: Path) -> list[tuple[str, str]]:
    """(name, what it fuzzes) of every registered target."""
    out = subprocess.run([sys.executable, "-m", "fuzz", "list"], cwd=root, capture_output=True, text=True,
                         check=False)
    if out.returncode != 0:
        raise RuntimeError(f"python -m fuzz list failed: {out.stderr.strip().splitlines()[-1:]}")
    return [tuple(line.split("\t", 1)) for line in out.stdout.splitlines() if "\t" in line]  # type: ignore[misc]


def _wrapper(root: Path, out: Path, name: str) -> Path:
    """An executable libFuzzer can re-run for ``-merge=1`` (it re-runs its own argv[0]; a script run by ``python -m``
    is not one): this interpreter on this target, written under ``out`` (a run's output, not the project's)."""
    path = out / f".{name}-exe.sh"
    path.write_text(f"#!/bin/sh\ncd {shlex.quote(str(root))} && exec {shlex.quote(sys.executable)} -m fuzz run "
                    f"{shlex.quote(name)} \"$@\"\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def _last_exception(log: str) -> str | None:
    """The exception an uncaught-exception report names (its traceback's last line)."""
    lines = log.splitlines()
    for i, line in enumerate(lines):
        if "Uncaught Python exception" in line:
            tail = [x for x in lines[i + 1:] if x.strip() and not x.startswith(("Traceback", "  "))]
            return tail[0].strip() if tail else None
    return None


def read_output(res: Result, text: str, code: int, log_path: Path) -> None:
    """Fill ``res`` from libFuzzer's output ``text`` and exit code: inputs run, coverage, and what failed."""
    for m in _COV.finditer(text):
        res.cov, res.ft = int(m[1]), int(m[2])
    if (m := _EXECUTED.search(text)) or (m := _DONE.search(text)):
        res.inputs = int(m[1])
    # a crash-, timeout-, oom- or leak- file is a failure; a slow-unit- one is libFuzzer's report of its slowest input
    # (over 10 s of wall time: a process stopped while it ran one, as a paused machine does), kept but not a failure
    artifacts = [(Path(a).name.split("-", 1)[0], a) for a in _ARTIFACT.findall(text)]
    failing = [(kind, a) for kind, a in artifacts if kind != "slow"]
    res.slow = next((a for kind, a in artifacts if kind == "slow"), None)
    if failing:
        kind, res.reproducer = failing[0]
        if kind == "timeout":
            res.hangs = 1
        else:
            res.crashes = 1
            res.error = _last_exception(text) or kind
    elif code != 0:
        res.error = f"exit code {code}, see {log_path}"


def run_target(root: Path, name: str, out: Path, *, runs: int, max_time: int, timeout: int, seed: int,
               merge: bool) -> Result:
    """Fuzz ``name`` once (its scratch corpus under ``out/name/corpus``); with ``merge``, then merge new coverage into
    the committed corpus."""
    work = out / name
    scratch = work / "corpus"
    scratch.mkdir(parents=True, exist_ok=True)
    corpus = root / "fuzz" / "corpus" / name
    corpus.mkdir(parents=True, exist_ok=True)
    log_path = out / f"{name}.log"
    args = [sys.executable, "-m", "fuzz", "run", name, f"-runs={runs}", f"-max_total_time={max_time}",
            f"-timeout={timeout}", f"-seed={seed}", f"-artifact_prefix={work}{os.sep}", "-print_final_stats=1",
            "-rss_limit_mb=4096", str(scratch), str(corpus)]
    res = Result(name)
    t0 = time.monotonic()
    tmp = work / "tmp"  # the target's temporary files, removed after it (libFuzzer ends it without Python's clean-up)
    tmp.mkdir(exist_ok=True)
    env = {**os.environ, "TMPDIR": str(tmp.resolve())}
    with open(log_path, "w") as log:
        proc = subprocess.run(args, cwd=root, stdout=log, stderr=subprocess.STDOUT, env=env, check=False)
    res.seconds = round(time.monotonic() - t0, 1)
    res.code = proc.returncode
    read_output(res, log_path.read_text(errors="replace"), proc.returncode, log_path)
    if merge and not res.failed:
        env["SWARM_SITL_FUZZ_EXE"] = str(_wrapper(root, out, name))
        with open(log_path, "a") as log:
            subprocess.run([sys.executable, "-m", "fuzz", "run", name, "-merge=1", "-use_counters=0",
                            f"-timeout={timeout}", "-rss_limit_mb=4096", str(corpus), str(scratch)], cwd=root,
                           stdout=log, stderr=subprocess.STDOUT, env=env, check=False)
    shutil.rmtree(tmp, ignore_errors=True)
    return res


def table(results: list[Result]) -> str:
    """The results as a Markdown table, then one line per failure naming its reproducer."""
    lines = ["| target | inputs | cov | ft | crashes | hangs | seconds |", "|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        lines.append(f"| {r.target} | {r.inputs} | {r.cov} | {r.ft} | {r.crashes} | {r.hangs} | {r.seconds:g} |")
    for r in results:
        if r.crashes or r.hangs:
            what = "hang" if r.hangs else f"crash ({r.error})"
            lines.append(f"{r.target}: {what}; reproduce with: python -m fuzz replay {r.target} {r.reproducer}")
        elif r.error:
            lines.append(f"{r.target}: did not run: {r.error}")
        if r.slow:
            lines.append(f"{r.target}: libFuzzer reported a slow input (over 10 s of wall time; not a failure): "
                         f"{r.slow}")
    return "\n".join(lines)


def cmd_fuzz(a: argparse.Namespace) -> int:
    root = fuzz_root()
    try:
        known = list_targets(root)
    except RuntimeError as e:
        print(f"swarm-sitl fuzz: {e}", file=sys.stderr)
        return 2
    if a.list:
        width = max(len(n) for n, _ in known)
        for name, about in known:
            print(f"{name:<{width}}  {about}")
        return 0
    names = [n for n, _ in known]
    unknown = [t for t in a.target or () if t not in names]
    if unknown:
        print(f"swarm-sitl fuzz: no target {', '.join(unknown)}; known: {', '.join(names)}", file=sys.stderr)
        return 2
    try:
        import atheris  # noqa: F401  (the targets' processes need it)
    except ImportError:
        print("swarm-sitl fuzz: atheris is not installed: make fuzz installs it (requirements-fuzz.lock)",
              file=sys.stderr)
        return 2
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    results: list[Result] = []
    for name in a.target or names:
        if not a.quiet:
            print(f"fuzzing {name} ...", file=sys.stderr, flush=True)
        r = run_target(root, name, out, runs=a.runs, max_time=a.max_time, timeout=a.timeout, seed=a.seed,
                       merge=a.merge)
        results.append(r)
    print(table(results))
    if any(r.crashes or r.hangs for r in results):
        return 1
    return 2 if any(r.error for r in results) else 0


def add_parser(sub: Any) -> None:
    from bridge.tools.argtypes import at_least_one

    p = sub.add_parser("fuzz", help="fuzz every parser a byte from outside reaches (atheris), each for a fixed budget; "
                                    "a table of inputs, coverage, crashes and hangs")
    p.add_argument("--target", action="append", metavar="NAME", help="only this target (repeatable; --list names "
                                                                     "them)")
    p.add_argument("--runs", type=at_least_one, default=100_000, help="inputs per target (default 100000)")
    p.add_argument("--max-time", type=at_least_one, default=600, help="seconds per target at most (default 600)")
    p.add_argument("--timeout", type=at_least_one, default=10,
                   help="seconds one input may take before it is a hang (10)")
    p.add_argument("--seed", type=int, default=1, help="libFuzzer's seed: the same seed and corpus, the same run (1)")
    p.add_argument("--merge", action="store_true", help="merge what reached new code into fuzz/corpus/<target>/")
    p.add_argument("--out", default="runs/fuzz", help="scratch corpora, reproducers and logs (runs/fuzz)")
    p.add_argument("--list", action="store_true", help="the targets and what each fuzzes")
    p.add_argument("--quiet", action="store_true", help="no progress line per target")
    p.set_defaults(fn=cmd_fuzz)
