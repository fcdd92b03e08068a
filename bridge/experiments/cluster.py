"""An experiment's trials on a Dask distributed cluster: ``swarm-sitl experiment NAME --cluster ADDRESS``.

The runner hands the cluster the same tasks it would give its local workers (batches of one cell's trials) and
stores each result as it arrives, so which worker ran a trial changes none of its bytes. The scheduler gives the
task of a worker that died to another worker (until the task has seen more than its ``allowed-failures`` workers die
under it: then those trials fail); a trial that raises is a failed trial, as on this machine, and is not retried.
Workers must run the same code: the client compares every worker's code fingerprint with its own on connecting, and
each task again (a worker may join later). Cancelling the run stops the sessions its running tasks run.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

from bridge.core.plan import code_fingerprint
from bridge.experiments.runner import (
    Trial,
    WorkersLost,
    _Done,
    _error_line,
    _failed,
    _no_interrupts,
    _Ref,
    _run_trials,
    _task_results,
)

if TYPE_CHECKING:
    from distributed import Client

STOP_POLL_S = 0.25  # how often a running task asks whether the run was cancelled


class ClusterError(Exception):
    """The cluster cannot run the trials: it cannot be reached, has no worker, or runs other code."""


class SchedulerLost(ClusterError, WorkersLost):
    """The scheduler went away during the run (the runner writes what finished, then says this)."""


def _run_checked(fingerprint: str, stop_event: str, ref: _Ref, trials: list[Trial]) -> list[_Done]:
    """``_run_trials`` on a worker, after checking that it runs the client's code (a worker that joined after the
    check on connecting; a mismatch fails the task's trials with the reason). The sessions the trials run stop once
    the client sets the Dask event ``stop_event`` (the run was cancelled)."""
    mine = code_fingerprint()
    if mine != fingerprint:
        raise ClusterError(
            f"this worker's swarm-sitl code differs from the client's ({mine}, the client {fingerprint})"
        )
    from bridge.core.launcher import stopping_when

    with stopping_when(_cancelled(stop_event)):
        return _run_trials(ref, trials)


def _cancelled(name: str) -> Callable[[], bool]:
    """Whether the client set the Dask event ``name``, asked at most every ``STOP_POLL_S`` (the launcher polls often);
    a scheduler that does not answer (or no worker around: the call did not come from the cluster) is no cancel."""
    from distributed import Event, get_worker

    state = {"next": 0.0, "set": False}

    def check() -> bool:
        now = time.monotonic()
        if not state["set"] and now >= state["next"]:
            state["next"] = now + STOP_POLL_S
            with contextlib.suppress(Exception):
                state["set"] = bool(Event(name, client=get_worker().client).is_set())
        return state["set"]

    return check


def _off_loop(fn: Callable[[], Any]) -> Any:
    """``fn()`` on a helper thread: it may run an event loop of its own even when the caller runs one (Jupyter)."""
    with ThreadPoolExecutor(1) as pool:
        return pool.submit(fn).result()


def _reach(address: str, timeout_s: float) -> None:
    """Connect to the scheduler and take its handshake within ``timeout_s``, or raise. (distributed's own connect
    retries until its timeout, but then waits for the handshake without one: a port that accepts and never answers
    would hang the client.)"""
    import asyncio

    from distributed.comm import connect

    async def probe() -> None:
        comm = await asyncio.wait_for(connect(address, timeout=timeout_s), timeout_s)
        await comm.close()

    _off_loop(lambda: asyncio.run(probe()))


class ClusterWorkers:
    """The workers of the Dask cluster whose scheduler listens at ``address`` (a ``runner.Workers``)."""

    def __init__(self, address: str, timeout_s: float = 30.0) -> None:
        from distributed import Client

        self.address, self.timeout_s = address, timeout_s
        deadline = time.monotonic() + timeout_s  # one for reaching the scheduler, a worker and their answers

        def left() -> float:
            return max(0.001, deadline - time.monotonic())

        # what goes wrong is said once, by ClusterError: not also as the client's logged tracebacks (a lost
        # scheduler), written by the handlers distributed gives its loggers
        names = [n for n in list(logging.root.manager.loggerDict) if n.split(".")[0] == "distributed"]
        self.quieted = list({id(h): (h, h.level) for n in names for h in logging.getLogger(n).handlers}.values())
        for h, _ in self.quieted:
            h.setLevel(logging.CRITICAL)
        self.fingerprint = code_fingerprint()
        self.pending: dict[Any, int] = {}
        self.client: Client | None = None
        try:
            try:
                _reach(address, left())
                self.client = _off_loop(lambda: Client(address, timeout=left(), set_as_default=False))
            except Exception as e:  # refused, timed out, not an address
                why = f"no answer within {timeout_s:g} s" if isinstance(e, TimeoutError) else _error_line(e)
                raise ClusterError(f"cannot reach the Dask scheduler at {address}: {why}") from None
            try:
                self.client.wait_for_workers(1, timeout=left())
            except TimeoutError:
                raise ClusterError(
                    f"the Dask scheduler at {address} has no worker (waited {timeout_s:g} s): "
                    f"start some with `dask worker {address}`"
                ) from None
            self._check_code(left())
        except BaseException:
            self.close()
            raise
        self.stop_event = f"swarm-sitl-stop-{self.client.id}"  # set by abort(): the running tasks' sessions stop
        n = len(self.client.scheduler_info().get("workers", {}))
        self.what = f"on the Dask cluster at {address} ({n} worker{'s' if n != 1 else ''} when it started)"

    def _check_code(self, timeout_s: float) -> None:
        """Refuse a cluster with a worker whose code differs from this process's, that does not have swarm-sitl, or
        that does not answer within ``timeout_s``."""
        try:
            found = self.client.sync(self.client._run, code_fingerprint, on_error="return", callback_timeout=timeout_s)
        except TimeoutError:
            raise ClusterError(
                f"the workers of the Dask cluster at {self.address} did not answer the code check within "
                f"{self.timeout_s:g} s"
            ) from None
        except Exception as e:
            raise ClusterError(
                f"the workers of the Dask cluster at {self.address} could not be asked for their code: {_error_line(e)}"
            ) from None
        wrong = {w: _why(v) for w, v in sorted(found.items()) if v != self.fingerprint}
        if wrong:
            listed = ", ".join(f"{w} {v}" for w, v in wrong.items())
            raise ClusterError(
                f"the Dask cluster at {self.address} runs other swarm-sitl code than this one "
                f"({self.fingerprint}): {listed}; install this checkout on every worker"
            )

    def run(self, ref: _Ref, tasks: list[list[Trial]]) -> Iterator[tuple[int, list[_Done]]]:
        from distributed import as_completed

        self.pending = {
            self.client.submit(_run_checked, self.fingerprint, self.stop_event, ref, t, pure=False): j
            for j, t in enumerate(tasks)
        }
        for f in as_completed(list(self.pending), loop=self.client.loop):
            j = self.pending.pop(f)
            if f.status == "cancelled":  # not by us: the scheduler went away, or dropped this client
                raise SchedulerLost(
                    f"lost the Dask scheduler at {self.address} (what finished is written, and kept in "
                    "the output's results/: run again with --resume to go on)"
                )
            res = _cluster_results(f, len(tasks[j]))
            f.release()
            yield j, res

    def abort(self) -> list[tuple[int, list[_Done]]]:
        """Fetch what had finished, stop the sessions of the running tasks (their results are dropped; a trial that
        runs no session runs on to its end: Dask cannot stop a running task), cancel the rest and disconnect."""
        with _no_interrupts():
            late = []
            for f, j in self.pending.items():
                if f.status == "finished":
                    with contextlib.suppress(Exception):
                        late.append((j, f.result(timeout=self.timeout_s)))
            with contextlib.suppress(Exception):
                s = self.client.scheduler
                self.client.sync(s.event_set, name=self.stop_event, callback_timeout=self.timeout_s)
            with contextlib.suppress(Exception):
                self.client.cancel(list(self.pending), force=True)
            self.pending = {}
            self.close()
        return late

    def close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.client.close(timeout=self.timeout_s)
        for h, level in self.quieted:
            h.setLevel(level)


def _why(answer: Any) -> str:
    """What a worker's answer to the code check says, for the refusal."""
    if isinstance(answer, str):
        return f"has other code ({answer})"
    if isinstance(answer, ImportError):  # it could not even load the check
        return "does not have swarm-sitl installed"
    return f"did not answer: {_error_line(answer) if isinstance(answer, BaseException) else repr(answer)}"


def _cluster_results(f: Any, n: int) -> list[_Done]:
    """``_task_results``, with a task the cluster gave up on (its workers died) failed in words that do not depend on
    the run (Dask's own name the task's random key and the last worker's address)."""
    from distributed import KilledWorker

    try:
        return f.result()
    except KilledWorker as e:
        return _failed(n, f"worker: KilledWorker: its worker died {e.allowed_failures + 1} times")
    except Exception:
        return _task_results(f, n)
