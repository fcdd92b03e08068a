"""Trials on a Dask cluster (``swarm-sitl experiment --cluster``): the outputs of a local run, workers lost under a
trial, results stored as they arrive, sessions stopped by a cancel, clusters that cannot run the trials, and workers
on other hosts."""

from __future__ import annotations

import asyncio
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import traceback
from pathlib import Path
from typing import Any

import dask
import numpy as np
import pytest
from distributed import Client, LocalCluster

from bridge.core.plan import CODE_PACKAGES, code_fingerprint
from bridge.experiments.cluster import ClusterError, _run_checked, _why
from bridge.experiments.runner import Experiment, Trial, TrialResult, _error_text, _ref, register, run_experiment
from bridge.experiments.sessions import run_config
from bridge.tools.cli import main
from bridge.tools.netns import Lab
from tests.experiments.test_experiment import ROOT, Flaky, MonteCarloPi, _rows, wait_until

assert MonteCarloPi.name == "test-pi"  # registered by importing it, here and in the workers


def _out_of(trial: Trial) -> Path:
    """The run's output directory (a trial's workdir is OUT/work/CELL/INDEX): where these tests' trials leave marks."""
    return Path(trial.workdir).parents[2]


@register
class Crashing(Flaky):
    name = "test-crashing"
    title = "A trial that raises, and one that kills its worker on its first attempt"
    description = "Each attempt of a trial is noted in OUT/attempts/INDEX (the worker's process id)."

    def run(self, trial: Trial) -> TrialResult:
        attempts = _out_of(trial) / "attempts"
        attempts.mkdir(exist_ok=True)
        mark = attempts / str(trial.index)
        first = not mark.exists()
        with open(mark, "a") as f:
            f.write(f"{os.getpid()}\n")
        if trial.index == 1:
            raise ValueError("trial 1 raises on purpose")
        if trial.index == 2 and first:
            os._exit(1)  # the worker process dies under the trial
        return TrialResult(metrics={"value": float(np.random.default_rng(trial.seed).random())})


FINISHING = 3  # the gated runs' trials that finish at once; the others wait for OUT/open


@register
class Gated(Experiment):
    name = "test-gated"
    title = "Trials that wait for a file"
    description = f"The first {FINISHING} finish at once, the others when OUT/open exists."
    trials = 8

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"g": 1}]

    def run(self, trial: Trial) -> TrialResult:
        if trial.index >= FINISHING:
            gate = _out_of(trial) / "open"
            wait_until(gate.exists, f"{gate} did not appear", within_s=600)
        return TrialResult(metrics={"value": float(np.random.default_rng(trial.seed).random())})


class _OneTrial(Experiment):
    """One trial, in one cell: the experiments below differ by what it does."""

    trials = 1

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"k": 1}]


@register
class Killing(_OneTrial):
    name = "test-killing"
    title = "A trial that kills its worker, wherever it runs"
    description = "Each attempt ends the worker process under it."

    def run(self, trial: Trial) -> TrialResult:
        os._exit(1)


# a session that would run for hours of simulated time: two robots walking at random in a small arena
ENDLESS = {
    "session": {"name": "endless", "duration_s": 36000, "seed": 5, "hang_timeout_s": 60},
    "arena": {"width_m": 6, "length_m": 6},
    "robots": [{"count": 2, "behaviour": "random_walk", "placement": {"kind": "random", "min_separation_m": 0.6}}],
}


@register
class Endless(_OneTrial):
    name = "test-endless"
    title = "A session that runs until it is stopped"
    description = "One trial: a session of hours of simulated time."

    def run(self, trial: Trial) -> TrialResult:
        summary, _ = run_config(ENDLESS, Path(trial.workdir))
        return TrialResult(metrics={"robots": len(summary["robots"])})


def _scratch(d: Path) -> dict[str, str]:
    """The environment of a Dask process started here: its scratch files under ``d``, not the system's temporary
    directory."""
    return {**os.environ, "DASK_TEMPORARY_DIRECTORY": str(d)}


def _local_cluster(scratch: Path, n_workers: int) -> LocalCluster:
    """A scheduler and ``n_workers`` single-threaded worker processes (with nannies, which restart a worker that
    died) on this machine, their scratch files in ``scratch``."""
    return LocalCluster(
        processes=True,
        n_workers=n_workers,
        threads_per_worker=1,
        host="127.0.0.1",
        scheduler_port=0,
        dashboard_address=None,
        local_directory=str(scratch),
        # no dashboard; the scheduler's HTTP endpoints (health, metrics) would take port 8787 by default
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
    )


def _two_workers(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """Two worker processes on this machine; a task is given up after the third worker died under it."""
    scratch = tmp_path_factory.mktemp("dask")
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 2, "temporary-directory": str(scratch)}),
        _local_cluster(scratch, 2) as c,
    ):
        yield c


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """The module's shared cluster. The tests that share it kill no worker: on a loaded machine a nanny may not bring
    one back before the next test."""
    yield from _two_workers(tmp_path_factory)


@pytest.fixture
def killable_cluster(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A cluster of this test's own, for a test whose trials kill their workers."""
    yield from _two_workers(tmp_path_factory)


def _experiment(*args: str) -> int:
    with pytest.raises(SystemExit) as e:
        main(["experiment", *args, "--quiet"])
    return int(e.value.code)


def test_a_cluster_run_writes_what_a_local_run_writes(tmp_path: Path, cluster: LocalCluster) -> None:
    out = tmp_path / "pi"
    assert _experiment("test-pi", "--trials", "3", "--jobs", "1", "--out", str(out)) == 0
    local = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file() and p.suffix != ".png"}
    assert _experiment("test-pi", "--trials", "3", "--cluster", cluster.scheduler_address, "--out", str(out)) == 0
    remote = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file() and p.suffix != ".png"}
    assert set(remote) == set(local)
    for name in ("trials.csv", "curves/n-100.csv", "curves/n-1000.csv"):
        assert remote[Path(name)] == local[Path(name)], name
    # the report too, but for its last line: the wall time, and where the trials ran
    report, local_report = (r[Path("report.md")].decode().splitlines() for r in (remote, local))
    assert report[:-1] == local_report[:-1]
    # (as many workers as had joined: a test before this one may have left one restarting)
    assert re.search(rf"on the Dask cluster at {re.escape(cluster.scheduler_address)} \([12] workers? when", report[-1])
    assert "with 1 job (in-process)" in local_report[-1]
    for p in remote:  # each trial's stored result, as --resume takes it (its wall time aside)
        if p.parts[0] == "results":
            a, b = json.loads(remote[p]), json.loads(local[p])
            assert {**a, "wall_s": 0, "timings": {}} == {**b, "wall_s": 0, "timings": {}}


def test_a_lost_worker_s_trial_runs_on_another_and_a_raising_trial_fails_once(
    tmp_path: Path, killable_cluster: LocalCluster
) -> None:
    cluster = killable_cluster
    local, remote = tmp_path / "local", tmp_path / "remote"
    (local / "attempts").mkdir(parents=True)
    (local / "attempts" / "2").write_text("a worker died here before\n")  # so that this process does not exit
    assert _experiment("test-crashing", "--jobs", "1", "--out", str(local)) == 1
    assert _experiment("test-crashing", "--cluster", cluster.scheduler_address, "--out", str(remote)) == 1
    assert (remote / "trials.csv").read_bytes() == (local / "trials.csv").read_bytes()
    rows = _rows(remote / "trials.csv")
    assert [r["error"] for r in rows] == ["", "ValueError: trial 1 raises on purpose", "", "", "", ""]
    pids = {i: (remote / "attempts" / str(i)).read_text().split() for i in range(6)}
    assert len(pids[1]) == 1  # a trial that raises is a failed trial, not retried
    assert len(pids[2]) == 2 and pids[2][0] != pids[2][1]  # its first worker died: it ran again, elsewhere
    # (a trial whose result the dead worker held, not yet fetched, may have run again too: the scheduler recomputes
    # it, to the same result)


def _start_gated(address: str, out: Path, *extra: str, name: str = "test-gated") -> subprocess.Popen:
    """``swarm-sitl experiment NAME --cluster ADDRESS`` in a process of its own, as a user runs it."""
    code = (
        f"import sys; sys.path.insert(0, {str(ROOT)!r}); import tests.experiments.test_cluster; "
        f"from bridge.tools.cli import main; main(['experiment', {name!r}, '--cluster', {address!r}, '--out', "
        f"{str(out)!r}, *{list(extra)!r}])"
    )
    return subprocess.Popen(
        [sys.executable, "-c", code],
        cwd=ROOT,
        start_new_session=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _stored(out: Path) -> list[str]:
    return sorted(f.name for f in out.glob("results/*/*.json"))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_results_are_stored_as_they_arrive_and_resume_goes_on(tmp_path: Path, cluster: LocalCluster, sig: int) -> None:
    out, whole = tmp_path / "gated", tmp_path / "whole"
    p = _start_gated(cluster.scheduler_address, out)
    try:
        # the finishing trials' results are in results/ while the run goes on (the others wait for the gate)
        wait_until(lambda: len(_stored(out)) == FINISHING, "the first results were not stored")
        p.send_signal(sig)  # Ctrl-C, or a kill
        stdout, stderr = p.communicate(timeout=120)
    finally:
        (out / "open").touch()  # the trials the interrupt left running on the workers end
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, stderr
    assert "Traceback" not in stderr and "interrupted: 3/8 trials ran" in stdout
    assert _stored(out) == [f"{i}.json" for i in range(FINISHING)]
    assert len(_rows(out / "trials.csv")) == FINISHING and "**Interrupted**" in (out / "report.md").read_text()
    assert _experiment("test-gated", "--resume", "--cluster", cluster.scheduler_address, "--out", str(out)) == 0
    whole.mkdir()
    (whole / "open").touch()
    assert _experiment("test-gated", "--jobs", "2", "--out", str(whole)) == 0
    assert (out / "trials.csv").read_bytes() == (whole / "trials.csv").read_bytes()
    assert "(3 taken from an earlier run into this directory: --resume)" in (out / "report.md").read_text()


def test_a_cluster_that_cannot_be_reached_is_a_usage_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as mute:  # listens, never answers: the client's handshake times out
        mute.bind(("127.0.0.1", 0))
        mute.listen()
        address = f"tcp://127.0.0.1:{mute.getsockname()[1]}"
        out = tmp_path / "never"
        assert _experiment("test-pi", "--cluster", address, "--cluster-timeout", "1", "--out", str(out)) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"swarm-sitl experiment: cannot reach the Dask scheduler at {address}: no answer within 1 s"
    assert len(err.splitlines()) == 1 and not out.exists()  # nothing written
    assert _experiment("test-pi", "--cluster", address, "--jobs", "2") == 2
    assert "--jobs and --cluster exclude each other" in capsys.readouterr().err
    with dask.config.set({"temporary-directory": str(tmp_path)}), _local_cluster(tmp_path, 0) as idle:
        assert (
            _experiment("test-pi", "--cluster", idle.scheduler_address, "--cluster-timeout", "5", "--out", str(out))
            == 2
        )
    assert capsys.readouterr().err == (
        f"swarm-sitl experiment: the Dask scheduler at {idle.scheduler_address} has no "
        f"worker (waited 5 s): start some with `dask worker {idle.scheduler_address}`\n"
    )
    assert not out.exists()


def _start_worker(address: str, name: str, path: Path, scratch: Path) -> subprocess.Popen:
    """``dask worker ADDRESS`` as a user starts it, importing packages from ``path`` first, its files in
    ``scratch``."""
    return subprocess.Popen(
        [
            *(sys.executable, "-m", "dask", "worker", address, "--name", name, "--nthreads", "1", "--no-nanny"),
            *("--host", "127.0.0.1", "--no-dashboard", "--dashboard-address", "127.0.0.1:0"),
            *("--local-directory", str(scratch)),
        ],
        cwd=scratch,  # not the checkout: its packages would come first
        env={**_scratch(scratch), "PYTHONPATH": str(path)},
        start_new_session=True,
        stderr=subprocess.DEVNULL,
    )


def _fingerprint_of(path: Path) -> str:
    """``code_fingerprint()`` in a process that imports the packages from ``path``."""
    code = "from bridge.core.plan import code_fingerprint; print(code_fingerprint())"
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=path, env={**os.environ, "PYTHONPATH": str(path)}, capture_output=True
    )
    return run.stdout.decode().strip()


def test_a_cluster_with_other_code_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    edited = tmp_path / "edited"
    for package in CODE_PACKAGES:  # this checkout, one file changed by a comment
        shutil.copytree(ROOT / package, edited / package, ignore=shutil.ignore_patterns("__pycache__"))
    with open(edited / "swarm_logic" / "geometry.py", "a") as f:
        f.write("# a change the version number does not show\n")
    started = []
    try:
        with dask.config.set({"temporary-directory": str(tmp_path)}), _local_cluster(tmp_path, 1) as c:
            (edited / "scratch").mkdir()
            started.append(_start_worker(c.scheduler_address, "edited", edited, edited / "scratch"))
            with Client(c.scheduler_address, set_as_default=False) as client:
                client.wait_for_workers(2, timeout=600)  # bounds a hang only
                by_name = {w["name"]: a for a, w in client.scheduler_info()["workers"].items()}
            out = tmp_path / "x"
            assert _experiment("test-pi", "--cluster", c.scheduler_address, "--out", str(out)) == 2
    finally:
        for p in started:
            p.kill()
            p.wait()
    err = capsys.readouterr().err
    assert err.startswith(
        f"swarm-sitl experiment: the Dask cluster at {c.scheduler_address} runs other swarm-sitl code than this one "
        f"({code_fingerprint()}): "
    )
    assert err.endswith(
        f": {by_name['edited']} has other code ({_fingerprint_of(edited)}); install this checkout on every worker\n"
    )
    assert len(err.splitlines()) == 1 and not out.exists()  # the worker of this checkout is not named
    # each task checks again, for a worker that joins once the run is going
    trial = Trial("test-pi", {"n": 100}, 0, 1, False, str(tmp_path / "w"))
    with pytest.raises(ClusterError, match=r"this worker's swarm-sitl code differs from the client's"):
        _run_checked("0.1.0+other", "unused", _ref(MonteCarloPi), [trial])
    assert _run_checked(code_fingerprint(), "unused", _ref(MonteCarloPi), [trial])[0][1] is None


def test_a_worker_that_does_not_answer_the_code_check_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with dask.config.set({"temporary-directory": str(tmp_path)}), _local_cluster(tmp_path, 0) as c:
        worker = _start_worker(c.scheduler_address, "stopped", ROOT, tmp_path)
        try:
            with Client(c.scheduler_address, set_as_default=False) as client:
                client.wait_for_workers(1, timeout=600)  # bounds a hang only
            worker.send_signal(signal.SIGSTOP)  # registered, then answers nothing
            out = tmp_path / "x"
            assert (
                _experiment("test-pi", "--cluster", c.scheduler_address, "--cluster-timeout", "10", "--out", str(out))
                == 2
            )
        finally:
            worker.kill()
            worker.wait()
    assert capsys.readouterr().err == (
        f"swarm-sitl experiment: the workers of the Dask cluster at {c.scheduler_address} did not answer the code "
        "check within 10 s\n"
    )
    assert not out.exists()


def test_a_worker_that_fails_the_code_check_did_not_answer() -> None:
    assert _why(ModuleNotFoundError("No module named 'bridge.experiments'")) == "does not have swarm-sitl installed"
    assert _why(OSError("connection reset")) == "did not answer: OSError: connection reset"
    assert _why("0.1.0+abc") == "has other code (0.1.0+abc)"


def test_a_trial_that_kills_every_worker_fails_in_the_same_words_each_run(
    tmp_path: Path, killable_cluster: LocalCluster
) -> None:
    cluster = killable_cluster
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        assert _experiment("test-killing", "--cluster", cluster.scheduler_address, "--out", str(out)) == 1
    assert (a / "trials.csv").read_bytes() == (b / "trials.csv").read_bytes()
    assert [r["error"] for r in _rows(a / "trials.csv")] == ["worker: KilledWorker: its worker died 3 times"]


def test_cancelling_a_run_stops_the_session_a_worker_runs(tmp_path: Path, cluster: LocalCluster) -> None:
    out = tmp_path / "endless"
    p = _start_gated(cluster.scheduler_address, out, "--quiet", name="test-endless")
    session = out / "work" / "k-1" / "0" / "session"
    try:
        wait_until((session / "plan.json").exists, "the trial's session did not start", within_s=600)
        p.send_signal(signal.SIGINT)  # Ctrl-C on the client
        _, stderr = p.communicate(timeout=120)
        assert p.returncode == 130, stderr
        # the session, told by the cancelled task, stops as at a Ctrl-C and writes its summary: long before the
        # hours of simulated time it was given
        wait_until((session / "summary.json").exists, "the session on the worker did not stop")
    finally:
        if p.poll() is None:
            p.kill()
    summary = json.loads((session / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["sim_time_s"] < ENDLESS["session"]["duration_s"]


def _raise_here() -> None:
    raise ValueError("here")


def test_error_texts_name_files_relative_to_the_checkout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # a worker started elsewhere than in the checkout
    try:
        _raise_here()
    except ValueError as e:
        text = _error_text(e)
    assert 'File "tests/experiments/test_cluster.py", line' in text, traceback.format_exc()
    assert str(ROOT) not in text


def _start_cluster(popen: Any, scheduler: tuple[Any, str], workers: list[tuple[Any, str]], tmp_path: Path) -> str:
    """A scheduler and single-threaded workers, each started as a user does (``dask scheduler``, ``dask worker``;
    ``popen(host, argv, **kwargs)``, each given (host, its address)); the scheduler's address once every worker
    joined."""
    env = {**_scratch(tmp_path), "PYTHONPATH": str(ROOT), "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "2"}
    dask_cmd = [sys.executable, "-m", "dask"]
    host, at = scheduler
    info = tmp_path / "scheduler.json"
    no_dashboard = ["--no-dashboard", "--dashboard-address"]
    scratch = ["--local-directory", str(tmp_path)]  # and the HTTP endpoints on a port of the system's
    popen(
        host,
        [*dask_cmd, "scheduler", "--host", at, "--port", "0", *no_dashboard, f"{at}:0", "--scheduler-file", str(info)],
        cwd=ROOT,
        env=env,
        stderr=subprocess.DEVNULL,
    )
    wait_until(lambda: info.exists() and info.stat().st_size > 0, "the scheduler did not start")
    address = json.loads(info.read_text())["address"]
    assert address.startswith(f"tcp://{at}:")
    logs = []
    for n, (host, at) in enumerate(workers):
        logs.append(tmp_path / f"worker-{n}.log")
        with open(logs[-1], "w") as f:
            popen(
                host,
                [*dask_cmd, "worker", address, "--host", at, "--nthreads", "1", *no_dashboard, f"{at}:0", *scratch],
                cwd=ROOT,
                env=env,
                stderr=f,
            )
    for log in logs:  # until each says it joined
        wait_until(lambda log=log: "Registered to:" in log.read_text(), f"the worker of {log.name} did not join")
    return address


def test_a_lost_scheduler_ends_the_run_and_keeps_what_finished(tmp_path: Path) -> None:
    started: list[subprocess.Popen] = []

    def popen(host: Any, argv: list[str], **kwargs: Any) -> subprocess.Popen:
        started.append(subprocess.Popen(argv, start_new_session=True, **kwargs))
        return started[-1]

    out = tmp_path / "gated"
    p = None
    try:
        address = _start_cluster(popen, (None, "127.0.0.1"), [(None, "127.0.0.1")], tmp_path)
        p = _start_gated(address, out, "--quiet", "--cluster-timeout", "10")
        wait_until(lambda: len(_stored(out)) == FINISHING, "the first results were not stored")
        started[0].kill()  # the scheduler
        _, stderr = p.communicate(timeout=120)
    finally:
        (out / "open").touch()
        for q in [*started, *([p] if p else [])]:
            if q.poll() is None:
                os.killpg(q.pid, signal.SIGKILL)
                q.wait()
    assert p.returncode == 2
    assert stderr == (
        f"swarm-sitl experiment: lost the Dask scheduler at {address} (what finished is written, and kept in the "
        "output's results/: run again with --resume to go on)\n"
    )
    assert _stored(out) == [f"{i}.json" for i in range(FINISHING)]
    assert len(_rows(out / "trials.csv")) == FINISHING  # written, as a Ctrl-C writes it
    assert f"**Interrupted** (lost the Dask scheduler at {address}" in (out / "report.md").read_text()
    assert _experiment("test-gated", "--resume", "--jobs", "2", "--out", str(out)) == 0
    assert "(3 taken from an earlier run" in (out / "report.md").read_text()


@pytest.mark.skipif(Lab.unavailable() is not None, reason=str(Lab.unavailable()))
def test_workers_on_other_hosts(tmp_path: Path) -> None:
    """The scheduler and the client on one host (the lab's hub), a worker on each of two others."""
    out, local = tmp_path / "pi", tmp_path / "local"
    assert _experiment("test-pi", "--trials", "3", "--jobs", "1", "--out", str(local)) == 0
    with Lab() as lab:
        hosts = [lab.add_host("w1"), lab.add_host("w2")]
        address = _start_cluster(lab.popen, (lab.hub, lab.hub.address), [(h, h.address) for h in hosts], tmp_path)
        code = (
            f"import sys; sys.path.insert(0, {str(ROOT)!r}); import tests.experiments.test_experiment; "
            f"from bridge.tools.cli import main; main(['experiment', 'test-pi', '--trials', '3', '--quiet', "
            f"'--cluster', {address!r}, '--out', {str(out)!r}])"
        )
        client = lab.popen(
            lab.hub,
            [sys.executable, "-c", code],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        _, stderr = client.communicate(timeout=600)
    assert client.returncode == 0, stderr
    assert (out / "trials.csv").read_bytes() == (local / "trials.csv").read_bytes()
    assert f"on the Dask cluster at {address} (2 workers when it started)" in (out / "report.md").read_text()


def test_a_cluster_run_from_code_that_runs_an_event_loop(tmp_path: Path, cluster: LocalCluster) -> None:
    async def in_a_notebook() -> Path:  # as a Jupyter cell runs: inside the kernel's event loop
        return run_experiment("test-pi", trials=1, cluster=cluster.scheduler_address, out=tmp_path, progress=False)

    assert len(_rows(asyncio.run(in_a_notebook()) / "trials.csv")) == 2
