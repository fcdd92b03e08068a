"""An experiment's trials on a Dask distributed cluster: ``swarm-sitl experiment NAME --cluster ADDRESS``.

The runner hands the cluster the same tasks it would give its local workers (batches of one cell's trials) and
stores each result as it arrives, so which worker ran a trial changes none of its bytes. The scheduler gives the
task of a worker that died to another worker (until the task has seen more than its ``allowed-failures`` workers die
under it: then those trials fail); a trial that raises is a failed trial, as on this machine, and is not retried.
Workers must run the same swarm-sitl: the client checks every worker's version on connecting, and each task again
(a worker may join later).
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import logging
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from bridge.experiments.runner import Trial, _Done, _no_interrupts, _Ref, _run_trials, _task_results

if TYPE_CHECKING:
    from distributed import Client

PACKAGE = "swarm-sitl"


class ClusterError(Exception):
    """The cluster cannot run the trials: it cannot be reached, has no worker, or runs another swarm-sitl."""


def _first_line(e: BaseException) -> str:
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__


def installed_version() -> str:
    return importlib.metadata.version(PACKAGE)


def _run_checked(version: str, ref: _Ref, trials: list[Trial]) -> list[_Done]:
    """``_run_trials`` on a worker, after checking that it runs the client's swarm-sitl (a worker that joined after
    the check on connecting); a mismatch fails the task's trials with the reason."""
    mine = installed_version()
    if mine != version:
        raise ClusterError(f"this worker runs swarm-sitl {mine}, the client {version}")
    return _run_trials(ref, trials)


def _reach(address: str, timeout_s: float) -> None:
    """Connect to the scheduler and take its handshake within ``timeout_s``, or raise. (distributed's own connect
    retries until its timeout, but then waits for the handshake without one: a port that accepts and never answers
    would hang the client.)"""
    import asyncio

    from distributed.comm import connect

    async def probe() -> None:
        comm = await asyncio.wait_for(connect(address, timeout=timeout_s), timeout_s)
        await comm.close()

    asyncio.run(probe())


class ClusterWorkers:
    """The workers of the Dask cluster whose scheduler listens at ``address`` (a ``runner.Workers``)."""

    def __init__(self, address: str, timeout_s: float = 30.0) -> None:
        from distributed import Client

        self.address, self.timeout_s = address, timeout_s
        # what goes wrong is said once, by ClusterError: not also as the client's logged tracebacks (a lost
        # scheduler), written by the handlers distributed gives its loggers
        names = [n for n in list(logging.root.manager.loggerDict) if n.split(".")[0] == "distributed"]
        self.quieted = list({id(h): (h, h.level) for n in names for h in logging.getLogger(n).handlers}.values())
        for h, _ in self.quieted:
            h.setLevel(logging.CRITICAL)
        self.version = installed_version()
        self.pending: dict[Any, int] = {}
        self.client: Client | None = None
        try:
            try:
                _reach(address, timeout_s)
                self.client = Client(address, timeout=timeout_s, set_as_default=False)
            except Exception as e:  # refused, timed out, not an address
                why = f"no answer within {timeout_s:g} s" if isinstance(e, TimeoutError) else _first_line(e)
                raise ClusterError(f"cannot reach the Dask scheduler at {address}: {why}") from None
            try:
                self.client.wait_for_workers(1, timeout=timeout_s)
            except TimeoutError:
                raise ClusterError(
                    f"the Dask scheduler at {address} has no worker (waited {timeout_s:g} s): "
                    f"start some with `dask worker {address}`"
                ) from None
            self._check_versions()
        except BaseException:
            self.close()
            raise
        n = len(self.client.scheduler_info().get("workers", {}))
        self.what = f"on the Dask cluster at {address} ({n} worker{'s' if n != 1 else ''} when it started)"

    def _check_versions(self) -> None:
        """Refuse a cluster with a worker that does not run this swarm-sitl (or none at all)."""
        found = self.client.run(importlib.metadata.version, PACKAGE, on_error="return")
        wrong = {
            w: (v if isinstance(v, str) else "not installed") for w, v in sorted(found.items()) if v != self.version
        }
        if wrong:
            listed = ", ".join(f"{w} has {v}" for w, v in wrong.items())
            raise ClusterError(
                f"the Dask cluster at {self.address} runs another swarm-sitl than this one "
                f"({self.version}): {listed}; install this version on every worker"
            )

    def run(self, ref: _Ref, tasks: list[list[Trial]]) -> Iterator[tuple[int, list[_Done]]]:
        from distributed import as_completed

        self.pending = {
            self.client.submit(_run_checked, self.version, ref, t, pure=False): j for j, t in enumerate(tasks)
        }
        for f in as_completed(list(self.pending), loop=self.client.loop):
            j = self.pending.pop(f)
            if f.status == "cancelled":  # not by us: the scheduler went away, or dropped this client
                raise ClusterError(
                    f"lost the Dask scheduler at {self.address} (the trials that finished are kept "
                    "in the output's results/: run again with --resume to go on)"
                )
            res = _task_results(f, len(tasks[j]))
            f.release()
            yield j, res

    def abort(self) -> list[tuple[int, list[_Done]]]:
        """Fetch what had finished, cancel the rest (a trial already running on a worker runs on there: Dask cannot
        stop a running task; its result is dropped) and disconnect."""
        with _no_interrupts():
            late = []
            for f, j in self.pending.items():
                if f.status == "finished":
                    with contextlib.suppress(Exception):
                        late.append((j, f.result(timeout=self.timeout_s)))
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
