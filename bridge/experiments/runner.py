"""Experiments: a named, seeded set of trials over conditions (cells), run in parallel and reported.

An experiment declares its cells, how one trial runs and which of the thesis' figures it checks (targets). This
module derives each trial's seed from (seed, experiment, cell, index), runs the trials in worker processes, keeps
the results in a fixed order whatever order they finish in (so trials.csv does not depend on --jobs), and writes
trials.csv, curves/, plots/ and report.md. A trial that raises is reported, never dropped, and never stops the
others.
"""

from __future__ import annotations

import contextlib
import csv
import importlib
import json
import math
import multiprocessing
import os
import re
import shlex
import shutil
import signal
import sys
import threading
import time
import traceback
import warnings
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from bridge.core.rng import stream_seed
from bridge.experiments.stats import finite_values, quartiles
from swarm_logic.plugins import Registry

RESERVED_COLUMNS = ("index", "seed", "error")
_RESULT_FILES = ("trials.csv", "timings.csv", "report.md")
_RESULT_DIRS = ("plots", "curves")

Scalar = float | int | str | bool


@dataclass(frozen=True)
class Trial:
    """One run of an experiment: a cell (the condition), its number within the cell and its own seed."""

    experiment: str
    cell: dict[str, Any]
    index: int
    seed: int
    smoke: bool
    workdir: str  # scratch directory for this trial (sessions go here); removed afterwards if left empty


@dataclass
class TrialResult:
    metrics: dict[str, Scalar | None]  # one trials.csv row (None: left empty)
    curves: dict[str, list[float]] = field(default_factory=dict)  # time series per curve name
    curve_x: dict[str, list[float]] = field(default_factory=dict)  # x values per curve (default 0..n-1)
    # wall-clock measurements of the trial (compute time of its parts, s): timings.csv, never trials.csv, so that
    # trials.csv stays the same bytes for the same seed on any machine
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class Outcome:
    """What a target's evaluate() sees, one per trial; error's first line is the exception, then where."""

    trial: Trial
    result: TrialResult | None
    error: str | None


@dataclass
class Target:
    """A figure of the thesis the experiment reproduces, and how ours is judged against it."""

    id: str
    what: str
    thesis: str
    tolerance: str
    evaluate: Callable[[list[Outcome]], tuple[str, bool | None, str]]  # -> (ours, pass/fail/None, note)


class Experiment:
    """Subclass, set the attributes, implement cells() and run(), decorate with @register.

    Instances are created without arguments, in the parent and in every worker process, so keep the state
    a trial needs in the class, the cell and the trial.
    """

    name: str
    title: str
    description: str  # a paragraph for report.md: setup, parameters, assumptions
    trials: int  # trials per cell
    smoke_trials: int = 2
    x_label: str = "iteration"
    curves: ClassVar[Sequence[tuple[str, str]]] = ()  # (curve name, y label): median and IQR band per cell
    boxes: ClassVar[Sequence[tuple[str, str]]] = ()  # (metric name, y label): a box per cell
    # (factor, metrics, y label, cells): each metric's mean over the trials at each level of a cell factor, with its
    # 95 % confidence interval, over the cells matching ``cells`` (a sub-dict of their values; {} all)
    means: ClassVar[Sequence[tuple[str, tuple[str, ...], str, dict[str, Any]]]] = ()
    # cell keys left out of the trial seed: cells that differ only in these share their trials' seeds (common random
    # numbers: e.g. algorithms compared on the same deployments)
    seed_ignores: ClassVar[tuple[str, ...]] = ()
    # trials of one cell handed to one worker at once (``run_batch``): for models that step many runs together; each
    # trial's result must not depend on which others share its batch
    batch: int = 1

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        raise NotImplementedError

    def cell_trials(self, cell: dict[str, Any], n: int) -> int:
        """How many trials this cell runs when the experiment runs ``n`` per cell (``n`` by default; a costly cell
        may run fewer)."""
        return n

    def cell_batch(self, cell: dict[str, Any]) -> int:
        """How many of this cell's trials one worker takes at once (``batch`` by default; 1 for a cell whose trials
        are better spread over the workers, e.g. sessions in an experiment whose model cells batch)."""
        return self.batch

    def run(self, trial: Trial) -> TrialResult:
        raise NotImplementedError

    def run_batch(self, trials: list[Trial]) -> list[TrialResult]:
        """Several trials of one cell at once (``batch`` > 1); by default one after the other with ``run``."""
        return [self.run(t) for t in trials]

    def targets(self) -> list[Target]:
        return []

    def sections(self, outcomes: list[Outcome]) -> list[str]:
        """Extra markdown lines for report.md, after the targets (e.g. a comparison table); none by default."""
        return []

    def figures(self, outcomes: list[Outcome], plots: Path) -> list[str]:
        """Plots of the experiment's own into ``plots`` (matplotlib's Agg backend is set), after the curves, boxes and
        means; returns the report lines showing them (``![what](plots/NAME.png)``); none by default. Should it raise,
        the report says so and keeps the other plots."""
        return []


class UnknownExperimentError(ValueError):
    pass


_REGISTRY: dict[str, type[Experiment]] = {}


def register(cls: type[Experiment]) -> type[Experiment]:
    """Class decorator: make an experiment known by its name (used in paths and make targets)."""
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
        raise ValueError(f"{cls.__qualname__}.name must be a word of letters, digits, '_', '.', '-'; got {name!r}")
    old = _REGISTRY.get(name)
    if old is not None and old.__qualname__ != cls.__qualname__:
        raise ValueError(f"experiment {name!r} is registered twice: {old.__module__}.{old.__qualname__} and "
                         f"{cls.__module__}.{cls.__qualname__}")
    _REGISTRY[name] = cls
    return cls


def _import_optional(module: str) -> None:
    try:
        importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name != module:  # the module exists but something it imports does not: a real error
            raise


def experiment_modules() -> list[str]:
    """The modules that define experiments: every study's (``bridge.core.registry.STUDIES``)."""
    from bridge.core.registry import STUDIES

    return [m for _, study in STUDIES.items() for m in study.experiments]


def experiments() -> dict[str, type[Experiment]]:
    """Every registered experiment by name, after importing the studies' experiment modules."""
    for module in experiment_modules():
        _import_optional(module)
    return dict(sorted(_REGISTRY.items()))


def get_experiment(name: str) -> type[Experiment]:
    known = experiments()
    if name not in known:
        raise UnknownExperimentError(f"unknown experiment {name!r}; known: {', '.join(known) or 'none'}")
    return known[name]


def trial_seed(seed: int, experiment: str, cell: dict[str, Any], index: int) -> int:
    """A stable seed < 2**63 for one trial; the cell's key order does not matter."""
    return stream_seed(seed, "experiment", experiment, tuple(sorted(cell.items())), index) >> 1


# --- running one trial (in a worker process, or in-process with jobs=1) ---

_Ref = tuple[str, str, str]  # (experiment name, class module, class qualname): what a worker needs to find it
_INSTANCES: dict[_Ref, Experiment] = {}
_Done = tuple[TrialResult | None, str | None, float]  # (result, error, wall seconds)


def _ref(cls: type[Experiment]) -> _Ref:
    return cls.name, cls.__module__, cls.__qualname__


def _instance(ref: _Ref) -> Experiment:
    """The experiment in this process: import its module (which registers it), else look in the studies' modules."""
    inst = _INSTANCES.get(ref)
    if inst is None:
        name, module, qualname = ref
        importlib.import_module(module)
        cls = _REGISTRY.get(name)
        if cls is None or (cls.__module__, cls.__qualname__) != (module, qualname):
            cls = get_experiment(name)
        inst = _INSTANCES[ref] = cls()
    return inst


def _worker_init() -> None:
    # the parent owns Ctrl-C: it cancels what is pending and terminates the workers; and should the parent die
    # without that (SIGKILL), the kernel stops the worker, whose session then stops its own processes
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _worker_terminated)
    from bridge.hosts.parent import die_with_parent

    die_with_parent(signal.SIGTERM)


def _worker_terminated(signum: int, frame: Any) -> None:
    """A worker ends on SIGTERM, as with the default action. A handler and not the default, because a session
    running in the worker takes the signal first to stop its processes and write its recording, then hands it to
    the handler it found (``launcher._pass_on``); the default there would be no handler, and a worker whose runner
    had died would live on, waiting for work."""
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)


# the directory holding the packages (the checkout): error texts name files relative to it, so that they do not
# depend on where a worker was started
_CODE_ROOT = str(Path(__file__).resolve().parents[2]) + os.sep


def _error_text(e: BaseException, frames: int = 3, skip: int = 0) -> str:
    """The exception on one line, then the traceback's last frames (after the first `skip`), with paths relative to
    the directory holding the packages."""
    what = " ".join("".join(traceback.format_exception_only(type(e), e)).split())
    tb = traceback.extract_tb(e.__traceback__)[skip:]
    lines = "".join(traceback.format_list(tb[-frames:] if frames else [])).splitlines()
    where = [s for s in lines if s.strip(" ^~")]  # without 3.11's column markers
    return "\n".join([what, *where]).replace(_CODE_ROOT, "")


def _error_line(e: BaseException) -> str:
    """The exception on one line (``_error_text``'s first)."""
    return _error_text(e, frames=0)


def _scalar(k: str, v: Any) -> Scalar | None:
    if v is None or isinstance(v, bool | str):
        return v
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, int | np.integer):
        return int(v)
    if isinstance(v, float | np.floating):
        return float(v)
    raise TypeError(f"metric {k!r}: expected a number, bool or str, got {type(v).__name__}")


def _clean(res: Any, trial: Trial) -> TrialResult:
    """Check a trial's result and turn numpy values into plain ones, so rows do not depend on who ran them."""
    if not isinstance(res, TrialResult):
        raise TypeError(f"run() returned {type(res).__name__}, not TrialResult")
    metrics: dict[str, Scalar | None] = {}
    for k, v in res.metrics.items():
        if k in RESERVED_COLUMNS or k in trial.cell:
            raise ValueError(f"metric name {k!r} is taken by a trials.csv column")
        metrics[str(k)] = _scalar(k, v)
    curves = {str(k): np.asarray(v, dtype=float).reshape(-1).tolist() for k, v in res.curves.items()}
    curve_x = {}
    for k, x in res.curve_x.items():
        if k not in curves:
            raise ValueError(f"curve_x[{k!r}] has no curve")
        curve_x[str(k)] = np.asarray(x, dtype=float).reshape(-1).tolist()
        if len(curve_x[k]) != len(curves[k]):
            raise ValueError(f"curve {k!r}: {len(curves[k])} values but {len(curve_x[k])} x values")
    timings = {str(k): round(float(v), 6) for k, v in res.timings.items()}
    return TrialResult(metrics, curves, curve_x, timings)


def _run_trials(ref: _Ref, trials: list[Trial]) -> list[_Done]:
    """A batch of trials of one cell (``Experiment.run_batch``); should it raise, each trial runs alone, so one bad
    trial fails only itself. Each trial's wall time is its share of the batch's."""
    if len(trials) == 1:
        return [_run_trial(ref, trials[0])]
    t0 = time.perf_counter()
    try:
        for t in trials:
            Path(t.workdir).mkdir(parents=True, exist_ok=True)
        results = _instance(ref).run_batch(trials)
        if len(results) != len(trials):
            raise ValueError(f"run_batch() returned {len(results)} results for {len(trials)} trials")
        done = [(_clean(r, t), None) for r, t in zip(results, trials, strict=True)]
    except Exception:
        return [_run_trial(ref, t) for t in trials]
    share = (time.perf_counter() - t0) / len(trials)
    for t in trials:
        with contextlib.suppress(OSError):
            Path(t.workdir).rmdir()
    return [(r, e, share) for r, e in done]


RESULTS_DIR = "results"  # in the output directory: each finished trial's result, what --resume picks up


def _result_path(out_dir: Path, trial: Trial) -> Path:
    return out_dir / RESULTS_DIR / _slug(trial.cell) / f"{trial.index}.json"


def _result_key(trial: Trial) -> dict[str, Any]:
    """What a stored result must match to stand for a planned trial: the experiment, cell, index, seed, smoke."""
    return json.loads(json.dumps({"experiment": trial.experiment, "cell": trial.cell, "index": trial.index,
                                  "seed": str(trial.seed), "smoke": trial.smoke}))


def _store(path: Path, trial: Trial, done: _Done) -> None:
    """Keep a successful trial's result at ``path`` (written whole, then renamed: never half a file)."""
    res, err, wall = done
    if res is None or err is not None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    body = {"key": _result_key(trial), "wall_s": wall, "metrics": res.metrics, "curves": res.curves,
            "curve_x": res.curve_x, "timings": res.timings}
    tmp = path.with_suffix(".part")
    tmp.write_text(json.dumps(body))
    tmp.replace(path)


def _stored(path: Path, trial: Trial) -> _Done | None:
    """The result an earlier run of this very trial stored at ``path``, or None (none, another trial's, unreadable)."""
    try:
        body = json.loads(path.read_text())
        if body["key"] != _result_key(trial):
            return None
        res = TrialResult(body["metrics"], body["curves"], body["curve_x"], body["timings"])
        return res, None, float(body["wall_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _run_trial(ref: _Ref, trial: Trial) -> _Done:
    t0 = time.perf_counter()
    wd = Path(trial.workdir)
    try:
        wd.mkdir(parents=True, exist_ok=True)
        res: TrialResult | None = _clean(_instance(ref).run(trial), trial)
        err = None
    except Exception as e:
        res, err = None, _error_text(e, skip=1)  # from the experiment's code on
    with contextlib.suppress(OSError):
        wd.rmdir()  # only if the trial left nothing there
    return res, err, time.perf_counter() - t0


# --- progress ---


class _Progress:
    """A rich bar on a terminal, else a plain line every ~10 %."""

    def __init__(self, name: str, total: int, enabled: bool) -> None:
        self.name, self.total, self.done, self.failed = name, total, 0, 0
        self.t0 = time.monotonic()
        self.step = max(1, math.ceil(total / 10))
        self.bar: Any = None
        self.plain = enabled
        if enabled and sys.stderr.isatty():
            from rich import progress as rp
            from rich.console import Console

            self.bar = rp.Progress(rp.TextColumn("{task.description}"), rp.BarColumn(), rp.MofNCompleteColumn(),
                                   rp.TextColumn("trials, {task.fields[failed]} failed"), rp.TimeElapsedColumn(),
                                   rp.TextColumn("ETA"), rp.TimeRemainingColumn(), console=Console(stderr=True))
            self.task = self.bar.add_task(name, total=total, failed=0)
            self.bar.start()
            self.plain = False

    def advance(self, failed: bool) -> None:
        self.done += 1
        self.failed += failed
        if self.bar is not None:
            self.bar.update(self.task, advance=1, failed=self.failed)
        elif self.plain and (self.done % self.step == 0 or self.done == self.total):
            print(f"{self.name}: {self.done}/{self.total} trials, {self.failed} failed, "
                  f"{time.monotonic() - self.t0:.0f} s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


# --- running all trials ---


def _start_method() -> str:
    # pybullet and zenoh do not survive fork(); spawn (not forkserver) makes the workers children of this process,
    # so they can be told to die with it
    return "spawn"


@contextlib.contextmanager
def _no_interrupts():
    """Ignore Ctrl-C and SIGTERM while shutting down: a second one (a user pressing Ctrl-C twice, a supervisor's
    repeated TERM) would cut the shutdown short, and the runner would then wait on trials still running, or die
    leaving its workers behind."""
    from bridge.core.launcher import on_main_thread

    if not on_main_thread():
        yield
        return
    old = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def _abort(pool: ProcessPoolExecutor, grace_s: float = 5.0) -> None:
    """Cancel pending trials and end the workers: SIGTERM (a session in a worker stops), then SIGKILL."""
    with _no_interrupts():
        procs = list((pool._processes or {}).values())  # the executor's only handle on its workers
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            with contextlib.suppress(Exception):
                p.terminate()
        deadline = time.monotonic() + grace_s
        for p in procs:
            p.join(max(0.0, deadline - time.monotonic()))
        for p in procs:
            if p.is_alive():
                p.kill()
                p.join()
        pool.shutdown(wait=True)


_STOP = threading.Event()  # set by Ctrl-C or SIGTERM during a run: a trial that swallows the interrupt still ends it


def _terminate_as_interrupt(signum: int, frame: Any) -> None:
    _STOP.set()
    raise KeyboardInterrupt


def _chunks(trials: list[Trial], size: int | Callable[[dict[str, Any]], int]) -> list[list[int]]:
    """Positions in ``trials`` grouped into runs of up to ``size`` (or ``size(cell)``) consecutive trials of one
    cell."""
    out: list[list[int]] = []
    for k, t in enumerate(trials):
        n = max(1, size(t.cell)) if callable(size) else size
        if out and len(out[-1]) < n and trials[out[-1][0]].cell == t.cell:
            out[-1].append(k)
        else:
            out.append([k])
    return out


def _task_results(f: Any, n: int) -> list[_Done]:
    """A finished task's results; a task that did not come back (its worker died, its result could not be sent, the
    cluster gave it up) is a failure of each of its ``n`` trials."""
    try:
        return f.result()
    except Exception as e:
        return _failed(n, f"worker: {_error_line(e)}")


def _failed(n: int, why: str) -> list[_Done]:
    """A task's ``n`` trials, failed with ``why``."""
    return [(None, why, 0.0)] * n


class Workers(Protocol):
    """Where a run's tasks (each a batch of one cell's trials, ``_run_trials``) execute: this process, worker
    processes of this machine, or a cluster (``bridge.experiments.cluster``). The runner stores, counts and orders
    the results the same way whichever runs them."""

    what: str  # for the report's last line: "with 4 jobs (spawn workers)"

    def run(self, ref: _Ref, tasks: list[list[Trial]]) -> Iterator[tuple[int, list[_Done]]]:
        """Run the tasks; yield (task number, its trials' results) as each finishes, in whatever order."""
        ...

    def abort(self) -> list[tuple[int, list[_Done]]]:
        """After an interrupt or error: cancel what is pending, stop what runs; the tasks that had finished but were
        not yielded yet."""
        ...

    def close(self) -> None: ...


class _InProcess:
    """Trials one after the other in this process (``--jobs 1``, for a debugger)."""

    what = "with 1 job (in-process)"

    def run(self, ref: _Ref, tasks: list[list[Trial]]) -> Iterator[tuple[int, list[_Done]]]:
        for j, task in enumerate(tasks):
            res = _run_trials(ref, task)
            # a trial's session may catch the interrupt to shut down cleanly and end as a failed trial: the flag
            # stops the run all the same, and that trial, cut short, is not kept
            if _STOP.is_set():
                raise KeyboardInterrupt
            yield j, res

    def abort(self) -> list[tuple[int, list[_Done]]]:
        return []

    def close(self) -> None:
        pass


class _LocalPool:
    """Spawned worker processes of this machine, each dying with the runner."""

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.what = f"with {jobs} jobs ({_start_method()} workers)"
        self.pool: ProcessPoolExecutor | None = None
        self.pending: dict[Future, int] = {}

    def run(self, ref: _Ref, tasks: list[list[Trial]]) -> Iterator[tuple[int, list[_Done]]]:
        self.pool = ProcessPoolExecutor(max_workers=min(self.jobs, len(tasks)), initializer=_worker_init,
                                        mp_context=multiprocessing.get_context(_start_method()))
        self.pending = {self.pool.submit(_run_trials, ref, t): j for j, t in enumerate(tasks)}
        for f in as_completed(list(self.pending)):
            j = self.pending.pop(f)
            yield j, _task_results(f, len(tasks[j]))

    def abort(self) -> list[tuple[int, list[_Done]]]:
        if self.pool is not None:
            _abort(self.pool)
        return [(j, f.result()) for f, j in self.pending.items()
                if f.done() and not f.cancelled() and f.exception() is None]

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True)


# distributed engines that run a run's tasks on a cluster, by name: a callable (address, timeout_s) -> Workers, found
# by entry point (``swarm_sitl.clusters``: swarm-sitl's own ``dask``, ``bridge.experiments.cluster``)
CLUSTERS: Registry[Callable[[str, float], Workers]] = Registry("swarm_sitl.clusters", "cluster engine", callable)
CLUSTER_ENGINE = "dask"


def _workers(jobs: int, cluster: str | None = None, cluster_timeout_s: float = 30.0) -> Workers:
    """This process (``jobs`` 1), ``jobs`` local worker processes, or the cluster whose scheduler is at ``cluster``
    (connected now, so that a cluster that cannot run the trials is refused before anything is written)."""
    if cluster is not None:
        return CLUSTERS.get(CLUSTER_ENGINE)(cluster, cluster_timeout_s)
    return _InProcess() if jobs == 1 else _LocalPool(jobs)


class WorkersLost(Exception):
    """The workers went away during the run (a cluster's scheduler): the run ends as Ctrl-C ends it, its outputs
    written with what finished, then this is raised."""


def _execute(ref: _Ref, trials: list[Trial], workers: Workers, bar: _Progress,
             batch: int | Callable[[dict[str, Any]], int] = 1,
             on_done: Callable[[int, _Done], None] = lambda k, d: None
             ) -> tuple[dict[int, _Done], KeyboardInterrupt | WorkersLost | None]:
    """Run the trials (``batch`` of one cell per task) on ``workers``; returns what finished by position in
    `trials`, and what cut the run short (Ctrl-C, lost workers) if anything did. ``on_done`` sees each finished
    trial as it comes."""
    done: dict[int, _Done] = {}
    groups = _chunks(trials, batch if callable(batch) else max(1, batch))
    try:
        for j, res in workers.run(ref, [[trials[k] for k in g] for g in groups]):
            for k, r in zip(groups[j], res, strict=True):
                done[k] = r
                on_done(k, r)
                bar.advance(r[1] is not None)
    except BaseException as e:
        late = workers.abort()
        if not isinstance(e, KeyboardInterrupt | WorkersLost):
            raise
        for j, res in late:  # finished as the interrupt came; a trial the interrupt cut short is not kept
            for k, r in zip(groups[j], res, strict=True):
                if r[1] is None:
                    done[k] = r
                    on_done(k, r)
        return done, e
    return done, None


# --- outputs ---


def _label(cell: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in cell.items()) or "all"


def _slug(cell: dict[str, Any]) -> str:
    parts = [re.sub(r"[^A-Za-z0-9.+-]+", "-", f"{k}-{v}").strip("-") for k, v in cell.items()]
    return "_".join(parts) or "all"


def _file_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "_"


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    return repr(v) if isinstance(v, float) else str(v)


def _num(v: float) -> str:
    return f"{v:.4g}"


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'' if n == 1 else 's'}"


def _md(text: Any) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _check_cells(cells: list[dict[str, Any]]) -> None:
    if not cells:
        raise ValueError("the experiment has no cells")
    for c in cells:
        if not isinstance(c, dict):
            raise TypeError(f"a cell must be a dict, got {type(c).__name__}")
        for k, v in c.items():
            if not isinstance(k, str) or not (v is None or isinstance(v, bool | int | float | str)):
                raise TypeError(f"cell {c!r}: keys must be str and values JSON scalars ({k!r}: {v!r})")
            if k in RESERVED_COLUMNS:
                raise ValueError(f"cell key {k!r} is taken by a trials.csv column")
    slugs = [_slug(c) for c in cells]
    if len(set(slugs)) != len(slugs):
        raise ValueError(f"cells must differ (their names clash): {slugs}")


def _write_csv(path: Path, header: list[str], rows: list[list[Any]]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        w.writerows([[_fmt(v) for v in r] for r in rows])


def _band(series: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """(x, quartiles [3, len(x)]) over trials; trials on other x grids are interpolated, NaN outside their range."""
    x0 = series[0][0]
    if all(len(x) == len(x0) and np.array_equal(x, x0) for x, _ in series):
        grid, ys = x0, np.vstack([y for _, y in series])
    else:
        grid = np.unique(np.concatenate([x for x, _ in series]))
        if len(grid) > 2000:
            grid = np.linspace(grid[0], grid[-1], 2000)
        ys = np.full((len(series), len(grid)), np.nan)
        for r, (x, y) in enumerate(series):
            if len(x):
                order = np.argsort(x, kind="stable")
                inside = (grid >= x[order[0]]) & (grid <= x[order[-1]])
                ys[r, inside] = np.interp(grid[inside], x[order], y[order])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an x where no trial has a value
        return grid, np.nanpercentile(ys, [25, 50, 75], axis=0)


def _plots(exp: Experiment, cells: list[dict[str, Any]], by_cell: list[list[Outcome]], plots: Path,
           outcomes: list[Outcome] | None = None) -> list[str]:
    """Draw the experiment's curves, boxes, means and own figures; returns report lines (links, or why a plot is
    missing)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines: list[str] = []
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for curve, ylabel in exp.curves:
        path = plots / f"curve-{_file_name(curve)}.png"
        try:
            fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=110)
            drawn = 0
            for ci, (cell, outs) in enumerate(zip(cells, by_cell, strict=True)):
                series = [(np.asarray(o.result.curve_x.get(curve, range(len(y))), dtype=float),
                           np.asarray(y, dtype=float))
                          for o in outs if o.result is not None and (y := o.result.curves.get(curve)) is not None]
                series = [s for s in series if len(s[1])]
                if not series:
                    continue
                x, (q25, q50, q75) = _band(series)
                c = colors[ci % len(colors)]
                ax.plot(x, q50, color=c, lw=1.4, label=f"{_label(cell)} ({len(series)})")
                ax.fill_between(x, q25, q75, color=c, alpha=0.2, lw=0)
                drawn += 1
            if not drawn:
                ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
            else:
                ax.legend(fontsize=7, title="cell (trials)", title_fontsize=7)
            ax.set_xlabel(exp.x_label)
            ax.set_ylabel(ylabel)
            ax.set_title(f"{exp.title}: {curve} (median, 25-75 % band)", fontsize=9)
            ax.grid(alpha=0.3)
            fig.tight_layout()
            fig.savefig(path)
            plt.close(fig)
            lines.append(f"![{curve}](plots/{path.name})")
        except Exception as e:
            plt.close("all")
            lines.append(f"- plot of curve `{curve}` failed: {_md(_error_line(e))}")
    for metric, ylabel in exp.boxes:
        path = plots / f"box-{_file_name(metric)}.png"
        try:
            data = [finite_values(outs, metric) for outs in by_cell]
            fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(cells) + 2), 4.5), dpi=110)
            pos = [i + 1 for i, d in enumerate(data) if len(d)]
            if pos:
                ax.boxplot([d for d in data if len(d)], positions=pos, widths=0.6,
                           flierprops={"markersize": 3, "alpha": 0.6})
            else:
                ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
            labels = [_label(c) for c in cells]
            long = max(len(s) for s in labels) > 12 or len(cells) > 6
            ax.set_xticks(range(1, len(cells) + 1), labels, rotation=45 if long else 0,
                          ha="right" if long else "center", fontsize=7)
            ax.set_xlim(0.4, len(cells) + 0.6)
            ax.set_ylabel(ylabel)
            ax.set_title(f"{exp.title}: {metric}", fontsize=9)
            ax.grid(alpha=0.3, axis="y")
            fig.tight_layout()
            fig.savefig(path)
            plt.close(fig)
            lines.append(f"![{metric}](plots/{path.name})")
        except Exception as e:
            plt.close("all")
            lines.append(f"- box plot of `{metric}` failed: {_md(_error_line(e))}")
    lines += _mean_plots(exp, cells, by_cell, plots, plt)
    try:
        lines += exp.figures(outcomes if outcomes is not None else [o for outs in by_cell for o in outs], plots)
    except Exception as e:
        lines.append(f"- figures() raised {_md(_error_line(e))}")
    finally:
        plt.close("all")
    return lines


def mean_ci95(v: np.ndarray) -> tuple[float, float]:
    """The mean of ``v`` and the half-width of its 95 % confidence interval (Student's t; 0 for one value)."""
    from scipy import stats as st

    if len(v) < 2:
        return (float(v[0]) if len(v) else math.nan), 0.0
    return float(np.mean(v)), float(st.t.ppf(0.975, len(v) - 1) * np.std(v, ddof=1) / math.sqrt(len(v)))


def _mean_plots(exp: Experiment, cells: list[dict[str, Any]], by_cell: list[list[Outcome]], plots: Path,
                plt: Any) -> list[str]:
    """``Experiment.means``: per factor, each metric's mean and 95 % CI at each of the factor's levels."""
    lines: list[str] = []
    for factor, metrics, ylabel, where in exp.means:
        path = plots / f"mean-{_file_name('-'.join(metrics))}-by-{_file_name(factor)}.png"
        try:
            chosen = [(c, outs) for c, outs in zip(cells, by_cell, strict=True)
                      if factor in c and all(c.get(k) == v for k, v in where.items())]
            levels = sorted({c[factor] for c, _ in chosen})
            fig, ax = plt.subplots(figsize=(5.5, 4.0), dpi=110)
            for j, metric in enumerate(metrics):
                ms, hs = [], []
                for lv in levels:
                    v = np.concatenate([finite_values(outs, metric) for c, outs in chosen if c[factor] == lv] or
                                       [np.zeros(0)])
                    m, h = mean_ci95(v)
                    ms.append(m)
                    hs.append(h)
                x = np.arange(len(levels)) + (j - (len(metrics) - 1) / 2) * 0.08
                ax.errorbar(x, ms, yerr=hs, marker="o", capsize=4, label=metric)
            ax.set_xticks(range(len(levels)), [f"{lv:g}" if isinstance(lv, int | float) else str(lv)
                                               for lv in levels])
            ax.set_xlabel(factor)
            ax.set_ylabel(ylabel)
            ax.set_title(f"{exp.name}: mean and 95 % CI by {factor}", fontsize=9)
            ax.grid(alpha=0.3, axis="y")
            if len(metrics) > 1:
                ax.legend(fontsize=7)
            fig.tight_layout()
            fig.savefig(path)
            plt.close(fig)
            lines.append(f"![{'/'.join(metrics)} by {factor}](plots/{path.name})")
        except Exception as e:
            plt.close("all")
            lines.append(f"- plot of `{'/'.join(metrics)}` by `{factor}` failed: {_md(_error_line(e))}")
    return lines


def _summary(metric: str, outs: list[Outcome]) -> list[str]:
    vals = [v for o in outs if o.result is not None and (v := o.result.metrics.get(metric)) is not None]
    if not vals:
        return [metric, "", "", "0"]
    if all(isinstance(v, bool) for v in vals):
        return [metric, f"{sum(vals)}/{len(vals)} true", "", str(len(vals))]
    if all(isinstance(v, int | float) for v in vals):
        nums = np.array(vals, dtype=float)
        fin = nums[np.isfinite(nums)]
        if not len(fin):
            return [metric, "not finite", "", f"0 of {len(nums)}"]
        q25, q50, q75 = quartiles(fin)
        n = str(len(fin)) if len(fin) == len(nums) else f"{len(fin)} of {len(nums)} finite"
        return [metric, _num(q50), f"{_num(q25)} to {_num(q75)}", n]
    common = Counter(str(v) for v in vals).most_common(4)
    return [metric, ", ".join(f"{_md(v)} ({n})" for v, n in common), "", str(len(vals))]


@dataclass
class ExperimentRun:
    """What run_experiment did: where, the outcomes in (cell, index) order and the targets' verdicts."""

    out: Path
    outcomes: list[Outcome]
    total: int  # trials planned
    failed: int
    interrupted: bool
    wall_s: float
    verdicts: list[tuple[Target, str, bool | None, str]]


def _command(name: str, trials: int | None, out: str | Path | None, default_out: Path, smoke: bool,
             seed: int, only: dict[str, list[str]] | None = None) -> str:
    cmd = ["swarm-sitl", "experiment", name]
    if smoke:
        cmd.append("--smoke")
    if trials is not None:
        cmd += ["--trials", str(trials)]
    cmd += ["--seed", str(seed)]
    for k, vs in (only or {}).items():
        cmd += ["--only", f"{k}={','.join(vs)}"]
    if out is not None and Path(out) != default_out:
        cmd += ["--out", str(out)]
    return shlex.join(cmd)


def _matches(value: Any, wanted: str) -> bool:
    """Whether a cell's value is the text given on the command line (``15`` matches 15 and 15.0, ``true`` True)."""
    if isinstance(value, bool) or value is None:
        return wanted.lower() == str(value).lower()
    if isinstance(value, int | float):
        try:
            return float(wanted) == float(value)
        except ValueError:
            return False
    return wanted == str(value)


def select_cells(cells: list[dict[str, Any]], only: dict[str, list[str]] | None) -> list[dict[str, Any]]:
    """The cells whose value of every key in `only` is one of the values given for it (all cells if `only` is
    empty). A key no cell has, or a choice that leaves no cell, is an error naming what there is."""
    if not only:
        return cells
    keys = list(dict.fromkeys(k for c in cells for k in c))
    kept = cells
    for key, wanted in only.items():
        if key not in keys:
            raise ValueError(f"--only {key}: no cell has the key {key!r} (the cells' keys: {', '.join(keys)})")
        if not wanted:
            raise ValueError(f"--only {key}: give one or more values, {key}=V1,V2")
        kept = [c for c in kept if key in c and any(_matches(c[key], w) for w in wanted)]
    if not kept:
        have = {k: sorted({str(c[k]) for c in cells if k in c}) for k in only}
        raise ValueError("--only leaves no cell; the values there are: "
                         + "; ".join(f"{k} in {', '.join(v)}" for k, v in have.items()))
    return kept


def execute_experiment(name: str, trials: int | None = None, jobs: int | None = None, out: str | Path | None = None,
                       smoke: bool = False, seed: int = 0, progress: bool = True,
                       only: dict[str, list[str]] | None = None, resume: bool = False, cluster: str | None = None,
                       cluster_timeout_s: float = 30.0) -> ExperimentRun:
    """Run experiment `name` and write its outputs; see run_experiment. Ctrl-C keeps what finished. `only` runs
    the cells whose values match (key to accepted values); a trial's seed does not depend on which cells run.
    `resume` takes each trial an earlier run into the same `out` finished (its results/ file: the same cell, index
    and seed) instead of running it again. `cluster` runs the trials on the Dask cluster whose scheduler is at that
    address instead of `jobs` local processes (``bridge.experiments.cluster``; reached within `cluster_timeout_s`)."""
    t_start = time.monotonic()
    cls = get_experiment(name)
    exp = cls()
    n = trials if trials is not None else (cls.smoke_trials if smoke else cls.trials)
    if cluster is not None and jobs is not None:
        raise ValueError("--jobs and --cluster exclude each other: a cluster's workers are its own "
                         "(dask worker --nworkers N)")
    jobs = jobs if jobs is not None else (os.cpu_count() or 1)
    if n < 1 or jobs < 1:
        raise ValueError(f"trials and jobs must be >= 1 (got {n}, {jobs})")
    all_cells = [dict(c) for c in exp.cells(smoke)]
    _check_cells(all_cells)
    cells = select_cells(all_cells, only)
    default_out = Path("runs/experiments") / (f"{name}-smoke" if smoke else name)
    out_dir = Path(out) if out is not None else default_out
    # a cluster is reached, and refused should it not do, before anything is written
    with contextlib.closing(_workers(jobs, cluster, cluster_timeout_s)) as workers:
        _clear_outputs(out_dir)
        work = (out_dir / "work").absolute()
        if not resume:  # a fresh run: no earlier trial's result stays to be taken for this run's
            shutil.rmtree(out_dir / RESULTS_DIR, ignore_errors=True)
        counts = [exp.cell_trials(c, n) for c in cells]
        plan = [Trial(name, dict(c), i, trial_seed(seed, name, {k: v for k, v in c.items()
                                                                if k not in cls.seed_ignores}, i),
                      smoke, str(work / _slug(c) / str(i)))
                for c, m in zip(cells, counts, strict=True) for i in range(m)]
        cell_of = [j for j, m in enumerate(counts) for _ in range(m)]
        ref = _ref(cls)
        _INSTANCES.setdefault(ref, exp)
        kept = {k: d for k, t in enumerate(plan)
                if resume and (d := _stored(_result_path(out_dir, t), t)) is not None}
        todo = [k for k in range(len(plan)) if k not in kept]
        bar = _Progress(name, len(todo), progress)

        def store(j: int, d: _Done) -> None:
            _store(_result_path(out_dir, plan[todo[j]]), plan[todo[j]], d)

        ran, cut = (_execute_interruptible(ref, [plan[k] for k in todo], workers, bar,
                                           lambda c: int(exp.cell_batch(c)), store)
                    if todo else ({}, None))
    interrupted = cut is not None
    done = {**kept, **{todo[j]: d for j, d in ran.items()}}
    for d in [*work.glob("*"), work]:  # cell directories no trial wrote in
        with contextlib.suppress(OSError):
            d.rmdir()

    outcomes = [Outcome(plan[k], done[k][0], done[k][1]) for k in sorted(done)]
    by_cell: list[list[Outcome]] = [[] for _ in cells]
    for k, o in zip(sorted(done), outcomes, strict=True):
        by_cell[cell_of[k]].append(o)  # plan is cell-major
    metric_keys = _write_tables(out_dir, plan, done, cells, outcomes, by_cell)
    plot_lines: list[str] = []
    if exp.curves or exp.boxes or exp.means or type(exp).figures is not Experiment.figures:
        (out_dir / "plots").mkdir()
        plot_lines = _plots(exp, cells, by_cell, out_dir / "plots", outcomes)
    verdicts, target_error = _judge(exp, outcomes)
    failed = sum(o.error is not None for o in outcomes)
    wall = time.monotonic() - t_start
    chosen = ""
    if only:
        which = "; ".join(f"{k} in {', '.join(v)}" for k, v in only.items())
        chosen = f" (the cells with {which}: {len(cells)} of {len(all_cells)})"
    lines = [f"# {exp.title}", "", " ".join(exp.description.split()), "",
             f"Reproduce: `{_command(name, trials, out, default_out, smoke, seed, only)}` (any `--jobs` gives the "
             f"same trials.csv).", "",
             f"- experiment `{name}`{' (smoke run)' if smoke else ''}: {_count(len(cells), 'cell')} x "
             f"{_count(n, 'trial')}{'' if len(set(counts)) <= 1 else ' (fewer in some: see each cell)'}, seed "
             f"{seed}{chosen}",
             f"- trials: {len(outcomes)} of {len(plan)} ran, {failed} failed"
             + (f" ({len(kept)} taken from an earlier run into this directory: --resume)" if kept else "")]
    if interrupted:
        why = f"({_md(cut)})" if isinstance(cut, WorkersLost) else "(Ctrl-C)"
        lines += ["", f"**Interrupted** {why} after {len(outcomes)} of {len(plan)} trials: the figures below "
                      "cover only the trials that finished."]
    lines += _target_lines(verdicts, target_error)
    try:
        lines += exp.sections(outcomes)
    except Exception as e:
        lines += ["", f"sections() raised {_md(_error_line(e))}"]
    if plot_lines:
        lines += ["", "## Plots", "", *plot_lines]
    lines += _cell_lines(cells, by_cell, metric_keys) + _failure_lines(outcomes, failed)
    walls = [d[2] for d in done.values()]
    lines += ["", "---", "",
              f"Wall time {wall:.1f} s {workers.what}; trials took "
              f"{float(np.median(walls)) if walls else 0:.3g} s median, {sum(walls):.1f} s in all "
              f"(per trial: timings.csv).{' Curves per trial: curves/.' if (out_dir / 'curves').exists() else ''}"]
    (out_dir / "report.md").write_text(re.sub(r"\n{3,}", "\n\n", "\n".join(lines)).rstrip() + "\n")
    if isinstance(cut, WorkersLost):
        raise cut
    return ExperimentRun(out_dir, outcomes, len(plan), failed, interrupted, wall, verdicts)


def _clear_outputs(out_dir: Path) -> None:
    """The output directory, without an earlier run's results (a partial rerun must not mix with them)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for f in _RESULT_FILES:
        (out_dir / f).unlink(missing_ok=True)
    for d in _RESULT_DIRS:
        shutil.rmtree(out_dir / d, ignore_errors=True)


def _execute_interruptible(ref: tuple[str, str, str], plan: list[Trial], workers: Workers, bar: _Progress,
                           batch: int | Callable[[dict[str, Any]], int] = 1,
                           on_done: Callable[[int, _Done], None] = lambda k, d: None
                           ) -> tuple[dict[int, tuple], KeyboardInterrupt | WorkersLost | None]:
    """``_execute`` with SIGTERM ending the run as Ctrl-C does (no orphans), the handlers restored after."""
    old_term = old_int = None
    from bridge.core.launcher import on_main_thread

    _STOP.clear()
    if on_main_thread():
        old_term = signal.signal(signal.SIGTERM, _terminate_as_interrupt)
        old_int = signal.signal(signal.SIGINT, _terminate_as_interrupt)
    try:
        return _execute(ref, plan, workers, bar, batch, on_done)
    finally:
        bar.close()
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
            signal.signal(signal.SIGINT, old_int)


def _write_tables(out_dir: Path, plan: list[Trial], done: dict[int, tuple], cells: list[dict[str, Any]],
                  outcomes: list[Outcome], by_cell: list[list[Outcome]]) -> list[str]:
    """trials.csv, timings.csv and the per-cell curves; returns the metric columns, in first-seen order."""
    cell_keys = list(dict.fromkeys(k for c in cells for k in c))
    metric_keys = list(dict.fromkeys(k for o in outcomes if o.result for k in o.result.metrics))
    _write_csv(out_dir / "trials.csv", [*cell_keys, *RESERVED_COLUMNS, *metric_keys],
               [[*(o.trial.cell.get(k) for k in cell_keys), o.trial.index, o.trial.seed,
                 o.error.splitlines()[0] if o.error else "",
                 *((o.result.metrics.get(k) if o.result else None) for k in metric_keys)] for o in outcomes])
    by_index = {(o.trial.index, _slug(o.trial.cell)): o.result.timings for o in outcomes if o.result}
    timing_keys = list(dict.fromkeys(k for t in by_index.values() for k in t))
    _write_csv(out_dir / "timings.csv", [*cell_keys, "index", "wall_s", *timing_keys],
               [[*(plan[k].cell.get(c) for c in cell_keys), plan[k].index, round(done[k][2], 3),
                 *(by_index.get((plan[k].index, _slug(plan[k].cell)), {}).get(t) for t in timing_keys)]
                for k in sorted(done)])
    for cell, outs in zip(cells, by_cell, strict=True):
        rows = [[o.trial.index, x, curve, v] for o in outs if o.result for curve, ys in o.result.curves.items()
                for x, v in zip(o.result.curve_x.get(curve, range(len(ys))), ys, strict=True)]
        if rows:
            (out_dir / "curves").mkdir(exist_ok=True)
            _write_csv(out_dir / "curves" / f"{_slug(cell)}.csv", ["index", "x", "curve", "value"], rows)
    return metric_keys


def _judge(exp: Experiment, outcomes: list[Outcome]) -> tuple[list[tuple[Target, str, bool | None, str]], str]:
    """Each target's verdict on the outcomes; a target that raises is "not judged" with the reason."""
    verdicts: list[tuple[Target, str, bool | None, str]] = []
    target_error = ""
    try:
        targets = exp.targets()
    except Exception as e:
        targets, target_error = [], _error_line(e)
    for t in targets:
        try:
            ours, ok, note = t.evaluate(outcomes)
        except Exception as e:
            ours, ok, note = "error", None, f"evaluate() raised {_error_line(e)}"
        verdicts.append((t, str(ours), ok, str(note)))
    return verdicts, target_error


def _target_lines(verdicts: list[tuple[Target, str, bool | None, str]], target_error: str) -> list[str]:
    lines = ["", "## Targets", ""]
    if verdicts:
        lines += ["| id | what | thesis | ours | tolerance | result | note |", "|---|---|---|---|---|---|---|"]
        for t, ours, ok, note in verdicts:
            verdict = {True: "pass", False: "fail"}.get(ok, "not judged")
            lines.append(f"| {_md(t.id)} | {_md(t.what)} | {_md(t.thesis)} | {_md(ours)} | {_md(t.tolerance)} "
                         f"| {verdict} | {_md(note)} |")
        counts = Counter({True: "pass", False: "fail"}.get(ok, "not judged") for _, _, ok, _ in verdicts)
        lines += ["", f"{counts['pass']} pass, {counts['fail']} fail, {counts['not judged']} not judged. A target "
                      "that fails is a finding of the experiment, not an error of the run."]
    else:
        lines.append(f"targets() raised {_md(target_error)}" if target_error else "No targets.")
    return lines


def _cell_lines(cells: list[dict[str, Any]], by_cell: list[list[Outcome]], metric_keys: list[str]) -> list[str]:
    lines = ["", "## Results per cell"]
    for cell, outs in zip(cells, by_cell, strict=True):
        bad = sum(o.error is not None for o in outs)
        lines += ["", f"### {_md(_label(cell))}", "", f"{len(outs)} trials, {bad} failed.", ""]
        keys = [k for k in metric_keys if any(o.result and k in o.result.metrics for o in outs)]
        if keys:
            lines += ["| metric | median | IQR (25-75 %) | n |", "|---|---|---|---|"]
            lines += ["| " + " | ".join(_summary(k, outs)) + " |" for k in keys]
    return lines


def _failure_lines(outcomes: list[Outcome], failed: int) -> list[str]:
    if not failed:
        return []
    lines = ["", "## Failures", "", f"{failed} trials raised:", ""]
    for o in outcomes:
        if o.error:
            lines += [f"- {_md(_label(o.trial.cell))}, trial {o.trial.index} (seed {o.trial.seed}):", "",
                      "  ```", *("  " + s for s in o.error.splitlines()), "  ```", ""]
    return lines


def run_experiment(name: str, trials: int | None = None, jobs: int | None = None, out: str | Path | None = None,
                   smoke: bool = False, seed: int = 0, progress: bool = True,
                   only: dict[str, list[str]] | None = None, resume: bool = False, cluster: str | None = None,
                   cluster_timeout_s: float = 30.0) -> Path:
    """Run experiment `name`: `trials` per cell (default its own), on `jobs` processes (default: one per CPU;
    1 runs in this process) or the Dask cluster whose scheduler is at `cluster`, into `out` (default
    runs/experiments/NAME[-smoke]), the cells `only` selects (default all). Returns the output directory;
    execute_experiment() also returns the outcomes, failures and verdicts."""
    return execute_experiment(name, trials, jobs, out, smoke, seed, progress, only, resume, cluster,
                              cluster_timeout_s).out
