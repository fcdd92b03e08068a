"""The experiment machinery, on small real experiments defined here (workers import them from this module)."""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest

from bridge.experiments import runner as ex
from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.tools.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _median_error(outcomes: list[Outcome], n: int) -> float:
    errors = [o.result.metrics["abs_error"] for o in outcomes if o.result and o.trial.cell["n"] == n]
    return float(np.median(errors)) if errors else math.nan


@register
class MonteCarloPi(Experiment):
    name = "test-pi"
    title = "Estimating pi by Monte Carlo"
    description = "Points drawn uniformly in the unit square; 4 x the share inside the quarter circle estimates pi."
    trials = 6
    smoke_trials = 2
    x_label = "points drawn"
    curves = (("estimate", "estimate of pi"),)
    boxes = (("abs_error", "absolute error"),)
    means = (("n", ("abs_error", "estimate"), "error, estimate", {}),)

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"n": 100}, {"n": 1000}]

    def run(self, trial: Trial) -> TrialResult:
        n = trial.cell["n"]
        t0 = time.perf_counter()
        xy = np.random.default_rng(trial.seed).random((n, 2))
        est = 4 * np.cumsum((xy**2).sum(axis=1) <= 1) / np.arange(1, n + 1)
        return TrialResult(metrics={"estimate": est[-1], "abs_error": abs(est[-1] - math.pi),
                                    "close": bool(abs(est[-1] - math.pi) < 0.1), "size": "small" if n < 500 else "big"},
                           curves={"estimate": est.tolist()}, curve_x={"estimate": list(range(1, n + 1))},
                           timings={"draw_s": time.perf_counter() - t0})

    def targets(self) -> list[Target]:
        def loose(outs: list[Outcome]) -> tuple[str, bool | None, str]:
            e = _median_error(outs, 1000)
            return f"{e:.3f}", e < 0.2, "n = 1000"

        def strict(outs: list[Outcome]) -> tuple[str, bool | None, str]:
            e = _median_error(outs, 100)
            if math.isnan(e):
                return "no trials", None, "n = 100 did not run"
            return f"{e:.3f}", e < 1e-9, "n = 100 cannot be that close"

        return [Target("PI1", "median |error|, 1000 points", "0", "< 0.2", loose),
                Target("PI2", "median |error|, 100 points", "0", "< 1e-9", strict),
                Target("PI3", "nothing to compare", "n/a", "n/a", lambda outs: ("-", None, "no thesis figure"))]


@register
class Flaky(Experiment):
    name = "test-flaky"
    title = "Every third trial raises"
    description = "Checks that failures are reported, not dropped."
    trials = 6

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"k": "a"}]

    def run(self, trial: Trial) -> TrialResult:
        if trial.index % 3 == 1:
            raise ValueError(f"trial {trial.index} fails on purpose")
        return TrialResult(metrics={"value": trial.index})


FINISHING = 4  # the interrupted runs' trials that finish; the others only end when the run is interrupted


def _slow_trial(trial: Trial) -> TrialResult:
    """Note the process id; sleep a little (the first ``FINISHING`` trials) or until interrupted (the others), so
    that an interrupt always finds exactly ``FINISHING`` trials finished, however slow the machine."""
    (Path(trial.workdir) / "pid").write_text(str(os.getpid()))
    time.sleep(0.4)
    while trial.index >= FINISHING:
        time.sleep(1.0)
    return TrialResult(metrics={"slept": 0.4})


@register
class Sleepy(Experiment):
    name = "test-sleepy"
    title = "Slow trials that note their process id"
    description = "For interrupting."
    trials = 40

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"s": 1}]

    def run(self, trial: Trial) -> TrialResult:
        return _slow_trial(trial)


@register
class Swallowing(Sleepy):
    name = "test-swallowing"
    title = "Slow trials that catch Ctrl-C themselves, as a session does to shut down cleanly"
    description = "For interrupting in-process."

    def run(self, trial: Trial) -> TrialResult:
        try:
            return _slow_trial(trial)
        except KeyboardInterrupt:
            raise RuntimeError("session interrupted") from None


@register
class SessionInWorker(Sleepy):
    name = "test-session-in-worker"
    title = "A long session as a trial, in a worker process"
    description = "For killing its runner."
    trials = 1

    def run(self, trial: Trial) -> TrialResult:
        from bridge.core.launcher import run_session

        (Path(trial.workdir) / "pid").write_text(str(os.getpid()))
        config = ROOT / "hil_configs" / "demos" / "random_walk.toml"  # no radios: the quickest start
        run_session(str(config), {"session.duration_s": 3600}, str(Path(trial.workdir) / "session"), progress=None,
                    plot=False)
        return TrialResult(metrics={})


def wait_until(cond, what: str, within_s: float = 120) -> None:
    """Poll ``cond`` until it holds; ``within_s`` only bounds a hang (generous: the machine may be loaded)."""
    deadline = time.monotonic() + within_s
    while not cond():
        assert time.monotonic() < deadline, f"{what} within {within_s:g} s"
        time.sleep(0.05)


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_results_do_not_depend_on_jobs_and_seeds_are_stable(tmp_path: Path) -> None:
    a = ex.run_experiment("test-pi", trials=4, jobs=1, out=tmp_path / "a", progress=False)
    b = ex.run_experiment("test-pi", trials=4, jobs=2, out=tmp_path / "b", progress=False)
    assert (a / "trials.csv").read_bytes() == (b / "trials.csv").read_bytes()
    for f in (a / "curves").iterdir():
        assert f.read_bytes() == (b / "curves" / f.name).read_bytes()
    rows = _rows(a / "trials.csv")
    assert list(rows[0]) == ["n", "index", "seed", "error", "estimate", "abs_error", "close", "size"]
    assert [(r["n"], r["index"]) for r in rows] == [(n, str(i)) for n in ("100", "1000") for i in range(4)]
    seeds = [int(r["seed"]) for r in rows]
    assert len(set(seeds)) == len(seeds) and all(0 <= s < 2**63 for s in seeds)
    assert seeds[0] == ex.trial_seed(0, "test-pi", {"n": 100}, 0)
    assert ex.trial_seed(0, "x", {"a": 1, "b": 2}, 3) == ex.trial_seed(0, "x", {"b": 2, "a": 1}, 3)
    assert ex.trial_seed(1, "test-pi", {"n": 100}, 0) != seeds[0]
    assert ex.trial_seed(0, "test-pi", {"n": 100}, 0) == 4474581379651440175  # stable across runs and machines
    assert {"index", "x", "curve", "value"} <= set(_rows(a / "curves" / "n-100.csv")[0])
    # a trial's wall-clock figures go to timings.csv, beside its wall time, never to trials.csv
    timings = _rows(a / "timings.csv")
    assert list(timings[0]) == ["n", "index", "wall_s", "draw_s"] and len(timings) == 8
    assert all(float(r["draw_s"]) >= 0 for r in timings)


def test_report_targets_plots_and_clearing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "pi"
    (out / "plots").mkdir(parents=True)
    (out / "plots" / "stale.png").write_bytes(b"")
    (out / "notes.txt").write_text("mine")
    (out / "trials.csv").write_text("stale\n")
    run = ex.execute_experiment("test-pi", trials=4, jobs=2, out=out, progress=True)
    assert run.failed == 0 and not run.interrupted and len(run.outcomes) == 8
    assert "test-pi: 8/8 trials, 0 failed" in capsys.readouterr().err  # plain progress lines off a terminal
    assert (out / "notes.txt").read_text() == "mine" and not (out / "plots" / "stale.png").exists()
    assert not (out / "work").exists()  # no trial wrote in its scratch directory
    report = (out / "report.md").read_text()
    assert report.startswith("# Estimating pi by Monte Carlo")
    assert "`swarm-sitl experiment test-pi --trials 4 --seed 0 --out " in report
    assert "| id | what | thesis | ours | tolerance | result | note |" in report
    lines = report.splitlines()
    assert next(s for s in lines if s.startswith("| PI1 |")).endswith("| pass | n = 1000 |")
    assert "| fail |" in next(s for s in lines if s.startswith("| PI2 |"))
    assert "| not judged |" in next(s for s in lines if s.startswith("| PI3 |"))
    assert "1 pass, 1 fail, 1 not judged" in report
    assert "### n=100" in report and "| abs_error |" in report and "| close |" in report
    for png in ("curve-estimate.png", "box-abs_error.png", "mean-abs_error-estimate-by-n.png"):
        assert (out / "plots" / png).stat().st_size > 1000 and f"(plots/{png})" in report
    assert [ok for _, _, ok, _ in run.verdicts] == [True, False, None]


def test_a_failing_trial_is_reported_and_the_others_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = ex.execute_experiment("test-flaky", jobs=2, out=tmp_path / "f", progress=False)
    assert run.failed == 2 and len(run.outcomes) == 6
    rows = _rows(tmp_path / "f" / "trials.csv")
    assert [r["error"] for r in rows] == ["", "ValueError: trial 1 fails on purpose", "", "",
                                         "ValueError: trial 4 fails on purpose", ""]
    assert [r["value"] for r in rows] == ["0", "", "2", "3", "", "5"]
    report = (tmp_path / "f" / "report.md").read_text()
    assert "## Failures" in report and "trial 4 (seed" in report and "in run" in report
    with pytest.raises(SystemExit) as e:
        main(["experiment", "test-flaky", "--jobs", "1", "--quiet", "--out", str(tmp_path / "g")])
    assert e.value.code == 1
    assert "6/6 trials ran, 2 failed" in capsys.readouterr().out


def test_only_runs_the_chosen_cells_with_the_full_runs_seeds(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    full = _rows(ex.run_experiment("test-pi", trials=2, jobs=1, out=tmp_path / "all", progress=False) / "trials.csv")
    with pytest.raises(SystemExit) as e:
        main(["experiment", "test-pi", "--trials", "2", "--jobs", "1", "--quiet", "--out", str(tmp_path / "some"),
              "--only", "n=1000"])
    assert e.value.code == 0
    some = _rows(tmp_path / "some" / "trials.csv")
    assert some == [r for r in full if r["n"] == "1000"]  # the same trials, seeds and figures as in the full run
    report = (tmp_path / "some" / "report.md").read_text()
    assert "--only n=1000" in report and "(the cells with n in 1000: 1 of 2)" in report
    assert "### n=100\n" not in report and "### n=1000" in report
    assert "| no trials |" in next(s for s in report.splitlines() if s.startswith("| PI2 |"))  # its cell did not run
    assert ex.select_cells([{"n": 100}, {"n": 1000}], {"n": ["100.0", "1000"]}) == [{"n": 100}, {"n": 1000}]
    assert ex.select_cells([{"d": "est", "k": 1}, {"d": "est", "k": 2}, {"d": "random", "k": 1}],
                           {"d": ["est"], "k": ["1"]}) == [{"d": "est", "k": 1}]
    assert ex.select_cells([{"on": True}, {"on": False}], {"on": ["true"]}) == [{"on": True}]
    capsys.readouterr()
    for bad, says in ((["--only", "m=5"], "no cell has the key 'm' (the cells' keys: n)"),
                      (["--only", "n=7"], "--only leaves no cell; the values there are: n in 100, 1000")):
        with pytest.raises(SystemExit) as e:
            main(["experiment", "test-pi", "--out", str(tmp_path / "bad"), *bad])
        assert e.value.code == 2 and says in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["experiment", "test-pi", "--only", "n"])
    assert e.value.code == 2 and "write KEY=V1[,V2...]" in capsys.readouterr().err


def test_resume_takes_the_finished_trials_and_runs_the_rest(tmp_path: Path) -> None:
    fresh = ex.run_experiment("test-pi", trials=3, jobs=1, out=tmp_path / "fresh", progress=False)
    out = tmp_path / "pi"
    ex.run_experiment("test-pi", trials=3, jobs=1, out=out, progress=False, only={"n": ["100"]})
    stored = sorted(p.relative_to(out / "results").as_posix() for p in (out / "results").rglob("*.json"))
    assert stored == ["n-100/0.json", "n-100/1.json", "n-100/2.json"]
    # a stored result is taken as it is: mark one to see it come back, and spoil another's key to see it rerun
    one = out / "results" / "n-100" / "1.json"
    body = json.loads(one.read_text())
    body["metrics"]["size"] = "taken"
    one.write_text(json.dumps(body))
    two = out / "results" / "n-100" / "2.json"
    body = json.loads(two.read_text())
    body["key"]["seed"] = "1"
    two.write_text(json.dumps(body))
    run = ex.execute_experiment("test-pi", trials=3, jobs=2, out=out, progress=False, resume=True)
    assert len(run.outcomes) == 6 and run.failed == 0
    rows, want = _rows(out / "trials.csv"), _rows(fresh / "trials.csv")
    assert rows[1]["size"] == "taken" and [r for i, r in enumerate(rows) if i != 1] == [
        r for i, r in enumerate(want) if i != 1]
    for f in (fresh / "curves").iterdir():
        assert f.read_bytes() == (out / "curves" / f.name).read_bytes()
    assert "(2 taken from an earlier run into this directory: --resume)" in (out / "report.md").read_text()
    # without --resume nothing earlier is taken
    run = ex.execute_experiment("test-pi", trials=3, jobs=1, out=out, progress=False)
    assert (out / "trials.csv").read_bytes() == (fresh / "trials.csv").read_bytes()
    assert "--resume" not in (out / "report.md").read_text()


def test_unknown_names_and_listing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ex.UnknownExperimentError, match="test-pi"):
        ex.run_experiment("no-such-thing", out=tmp_path)
    with pytest.raises(SystemExit) as e:
        main(["experiment", "no-such-thing"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "unknown experiment 'no-such-thing'" in err and "test-flaky" in err and "test-pi" in err
    with pytest.raises(SystemExit) as e:
        main(["experiment", "--list"])
    assert e.value.code == 0
    assert re.search(r"^test-pi +Estimating pi by Monte Carlo$", capsys.readouterr().out, re.MULTILINE)
    for bad in (["--trials", "0"], ["--jobs", "-1"]):
        with pytest.raises(SystemExit) as e:
            main(["experiment", "test-pi", *bad])
        assert e.value.code == 2


def test_missing_experiment_module_is_skipped_but_broken_one_raises(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ex, "experiment_modules", lambda: ["bridge.no_such_experiments"])
    assert "test-pi" in ex.experiments()  # not written yet: skipped
    (tmp_path / "half_written_experiments.py").write_text("import no_such_dependency_at_all\n")
    (tmp_path / "raising_experiments.py").write_text("raise RuntimeError('broken')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for module, error in (("half_written_experiments", ModuleNotFoundError), ("raising_experiments", RuntimeError)):
        monkeypatch.setattr(ex, "experiment_modules", lambda module=module: [module])
        with pytest.raises(error):
            ex.experiments()


def test_ctrl_c_keeps_what_finished_and_leaves_no_process(tmp_path: Path) -> None:
    out = tmp_path / "sleepy"
    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); import tests.experiments.test_experiment; "
            f"from bridge.tools.cli import main; main(['experiment', 'test-sleepy', '--jobs', '2', '--out', "
            f"{str(out)!r}])")
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, start_new_session=True, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    for line in p.stderr:  # the progress line once the run has the finishing trials' results (then none comes)
        if f"test-sleepy: {FINISHING}/40 trials" in line:
            break
    os.killpg(p.pid, signal.SIGINT)  # as a terminal's Ctrl-C: to the whole process group
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, stderr
    done = _rows(out / "trials.csv")
    assert len(done) == FINISHING and "interrupted" in stdout
    assert not [r for r in done if r["error"]]  # trials cut short are not reported as failures
    assert "**Interrupted**" in (out / "report.md").read_text()
    pids = {int(f.read_text()) for f in out.glob("work/*/*/pid")}
    wait_until(lambda: not any(psutil.pid_exists(pid) for pid in pids), "the workers did not go")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_in_process_interrupt_ends_the_run_even_when_a_trial_catches_it(tmp_path: Path, sig: int) -> None:
    out = tmp_path / "swallowing"
    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); import tests.experiments.test_experiment; "
            f"from bridge.tools.cli import main; main(['experiment', 'test-swallowing', '--jobs', '1', '--quiet', "
            f"'--out', {str(out)!r}])")
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, start_new_session=True, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    # in-process, trials run one after the other: once the first that waits started, the finishing ones are done
    wait_until(lambda: len(list(out.glob("work/*/*/pid"))) > FINISHING, "the trials did not start")
    os.kill(p.pid, sig)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, stderr
    done = _rows(out / "trials.csv")
    assert len(done) == FINISHING and "interrupted" in stdout
    assert not [r for r in done if r["error"]]  # the trial cut short is not reported as a failure


@pytest.mark.session
def test_a_runner_killed_while_a_worker_runs_a_session_takes_the_worker_and_the_session_with_it(
        tmp_path: Path) -> None:
    # SIGKILL leaves the runner no say: the kernel sends its workers SIGTERM (PR_SET_PDEATHSIG); the session in the
    # worker takes that signal to stop its processes, then hands it on, and the worker ends too
    out = tmp_path / "killed"
    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); import tests.experiments.test_experiment; "
            f"from bridge.tools.cli import main; main(['experiment', 'test-session-in-worker', '--jobs', '2', "
            f"'--quiet', '--out', {str(out)!r}])")
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    pid_file = out / "work" / "s-1" / "0" / "pid"
    wait_until(pid_file.exists, "the trial did not start")
    worker = psutil.Process(int(pid_file.read_text()))
    wait_until(lambda: len(worker.children()) > 1, "the session did not start its processes")
    procs = [worker, *worker.children(recursive=True)]
    p.kill()
    p.wait()
    try:
        wait_until(lambda: not any(q.is_running() and q.status() != psutil.STATUS_ZOMBIE for q in procs),
                   "the worker and its session's processes did not go")
    finally:  # a failing run leaves nothing behind either
        for q in procs:
            with contextlib.suppress(psutil.Error):
                q.kill()


def test_a_second_interrupt_cannot_cut_the_shutdown_short() -> None:
    # the runner's handlers turn Ctrl-C and SIGTERM into KeyboardInterrupt; were one to raise inside the shutdown,
    # the workers would be left running (a user pressing Ctrl-C twice, a supervisor sending TERM again)
    got: list[int] = []
    old = {s: signal.signal(s, lambda n, f: got.append(n)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with ex._no_interrupts():
            for s in old:
                assert signal.getsignal(s) == signal.SIG_IGN
                signal.pthread_kill(threading.main_thread().ident, s)
        assert got == []
        assert all(signal.getsignal(s) not in (signal.SIG_IGN, signal.SIG_DFL) for s in old)  # restored
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def test_a_session_hands_a_caught_signal_on_to_the_program_that_ran_it() -> None:
    from bridge.core.launcher import _pass_on

    got = []
    _pass_on(signal.SIGTERM, {signal.SIGTERM: lambda s, f: got.append(s)})
    assert got == [signal.SIGTERM]
    _pass_on(signal.SIGINT, {signal.SIGINT: signal.default_int_handler})  # the command line: nothing raised here
    _pass_on(signal.SIGTERM, {signal.SIGTERM: signal.SIG_DFL})
    _pass_on(None, {signal.SIGTERM: lambda s, f: got.append(s)})
    assert got == [signal.SIGTERM]


def test_a_mean_and_its_95_percent_confidence_interval() -> None:
    """Student's t with n - 1 degrees of freedom: for 1, 2, 3 the half-width is t(0.975, 2) x 1 / sqrt(3)."""
    m, h = ex.mean_ci95(np.array([1.0, 2.0, 3.0]))
    assert m == 2.0 and h == pytest.approx(4.302653 / math.sqrt(3), rel=1e-6)
    assert ex.mean_ci95(np.array([5.0])) == (5.0, 0.0) and math.isnan(ex.mean_ci95(np.zeros(0))[0])


BATCH_CALLS: list[int] = []


@register
class Batched(Experiment):
    name = "test-batched"
    title = "batched"
    description = "batched trials"
    trials = 5
    batch = 3

    def cells(self, smoke: bool) -> list[dict]:
        return [{"c": 1}, {"c": 2}]

    def cell_trials(self, cell: dict, n: int) -> int:
        return n if cell["c"] == 1 else 2

    def run(self, trial: Trial) -> TrialResult:
        return TrialResult({"v": trial.seed % 1000 + trial.cell["c"]})

    def run_batch(self, trials: list[Trial]) -> list[TrialResult]:
        BATCH_CALLS.append(len(trials))
        return [self.run(t) for t in trials]


def test_batched_trials_and_per_cell_counts_keep_the_rows_and_seeds(tmp_path: Path) -> None:
    """``batch`` hands a cell's trials to a worker together (``run_batch``) and ``cell_trials`` lets a cell run
    fewer: trials.csv holds the same rows, seeds and results whatever the jobs."""
    import csv as _csv

    from bridge.experiments.runner import execute_experiment

    rows = []
    for jobs in (1, 2):
        run = execute_experiment("test-batched", jobs=jobs, out=tmp_path / str(jobs), progress=False)
        assert run.total == 7 and run.failed == 0
        with open(tmp_path / str(jobs) / "trials.csv") as f:
            rows.append(list(_csv.reader(f)))
    assert rows[0] == rows[1] and len(rows[0]) == 8
    assert BATCH_CALLS == [3, 2, 2]  # in-process: cell 1 in batches of 3 and 2, cell 2's two trials together
    BATCH_CALLS.clear()
    Batched.cell_batch = lambda self, cell: 1 if cell["c"] == 2 else self.batch  # type: ignore[method-assign]
    try:
        run = execute_experiment("test-batched", jobs=1, out=tmp_path / "per-cell", progress=False)
    finally:
        del Batched.cell_batch
    with open(tmp_path / "per-cell" / "trials.csv") as f:
        assert list(_csv.reader(f)) == rows[0]
    assert BATCH_CALLS == [3, 2]  # cell_batch: cell 2's trials one at a time (each through run), the same rows


@register
class OwnFigure(Experiment):
    name = "test-figures"
    title = "An experiment drawing its own figure"
    description = "y = k x index; figures() draws y against the index per cell."
    trials = 3

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"k": 1}, {"k": 2}]

    def run(self, trial: Trial) -> TrialResult:
        return TrialResult({"y": trial.cell["k"] * trial.index})

    def figures(self, outcomes: list[Outcome], plots: Path) -> list[str]:
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots()
        for k in (1, 2):
            pts = [(o.trial.index, o.result.metrics["y"]) for o in outcomes if o.result and o.trial.cell["k"] == k]
            ax.plot(*zip(*pts, strict=True), marker="o")
        fig.savefig(plots / "y.png")
        return ["![y](plots/y.png)"]


def test_an_experiments_own_figures_are_drawn_and_one_that_raises_is_reported(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = ex.execute_experiment("test-figures", jobs=1, out=tmp_path / "a", progress=False)
    report = (run.out / "report.md").read_text()
    assert (run.out / "plots" / "y.png").stat().st_size > 1000 and "![y](plots/y.png)" in report

    def broken(self: Experiment, outcomes: list[Outcome], plots: Path) -> list[str]:
        raise RuntimeError("no axes today")

    monkeypatch.setattr(OwnFigure, "figures", broken)
    run = ex.execute_experiment("test-figures", jobs=1, out=tmp_path / "b", progress=False)
    report = (run.out / "report.md").read_text()
    assert "figures() raised RuntimeError: no axes today" in report and "| y |" in report
