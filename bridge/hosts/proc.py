"""Entry point of every child process of a session: ``python -m bridge.hosts.proc ROLE ...``.

Roles: ``world`` (the hub: clock, physics, router, recorder), ``firmware``, ``logic`` and ``service``
(participants, started by the launcher, or on another computer by ``swarm-sitl join --host``, with ``--endpoint``).
Children never read the terminal's signals (the launcher owns Ctrl-C); they die with the launcher.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sys
import traceback
from pathlib import Path

from bridge.hosts.parent import die_with_parent


def _world(args: argparse.Namespace, plan) -> int:
    from bridge.core.hub import Hub

    hub = Hub(plan, args.session_dir, args.out, args.namespace)
    hub.parent_pid = args.parent_pid  # (the launcher may have died meanwhile: its pid, not whoever adopted us)

    def on_term(signum, frame):
        hub.stop_reason = hub.stop_reason or f"signal {signal.Signals(signum).name}"
        hub.abort = True  # SIGTERM comes from a vanished launcher: its other children are gone too

    signal.signal(signal.SIGTERM, on_term)
    result: dict = {}
    code = 0
    try:
        hub.open()
        hub.wait_for_participants()
        result = hub.run()
        code = 1 if hub.failed_stop else 0
    except KeyboardInterrupt:
        hub.sim_end_ns, hub.wall_s = hub.k * hub.q_ns, 0.0
        result = hub.result()
        result["error"] = "stopped during start-up"
        code = 130
    except Exception:
        err = traceback.format_exc()
        print(err, file=sys.stderr)
        hub.sim_end_ns, hub.wall_s = hub.k * hub.q_ns, getattr(hub, "wall_s", 0.0)
        result = hub.result()
        result["error"] = err
        code = 1
    finally:
        try:
            if hasattr(hub, "session"):
                hub.shutdown()
            result["radio"] = hub.radio_report()
            hub.firmware_report(result.get("robots", []))
            if hub.service_entities:
                result["services"] = hub.service_report()
        finally:
            hub.close()
    result["digest"] = hub.rec.digest
    result["messages"] = hub.rec.count
    tmp = Path(args.out) / "world_result.json.tmp"
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(Path(args.out) / "world_result.json")
    if hasattr(hub, "session"):
        hub.status(op="end", code=code)
        hub.session.close()
    shutil.rmtree(args.session_dir, ignore_errors=True)  # the socket's directory, if the launcher could not
    return code


def _participant(args: argparse.Namespace, plan) -> int:
    from bridge.core.transport import endpoint_for
    from bridge.hosts.participant import serve

    proc = next(p for p in plan.procs if p.name == args.proc)
    if proc.kind == "firmware":
        from bridge.hosts.firmware import FirmwareHost

        host = FirmwareHost(plan, proc.robots)
    elif proc.kind == "service":
        from bridge.hosts.service import ServiceHost

        host = ServiceHost(plan, str(proc.service))
    else:
        from bridge.hosts.logic import LogicHost

        host = LogicHost(plan, proc.robots)
    endpoint = args.endpoint or endpoint_for(args.session_dir)  # a host's process: the world's TCP endpoint
    return serve(args.proc, endpoint, args.namespace, host, args.parent_pid)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bridge.hosts.proc")
    ap.add_argument("role", choices=["world", "firmware", "logic", "service"])
    ap.add_argument("--plan", required=True)
    where = ap.add_mutually_exclusive_group(required=True)
    where.add_argument("--session-dir")
    where.add_argument("--endpoint", help="a participant on another computer (swarm-sitl join --host): the world's "
                                          "endpoint")
    ap.add_argument("--namespace", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--proc", default="world")
    ap.add_argument("--parent-pid", type=int, required=True)
    args = ap.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # first of all (before seconds of imports): die with the launcher, then check it was still there when asked
    die_with_parent(signal.SIGTERM if args.role == "world" else signal.SIGKILL)
    if os.getppid() != args.parent_pid:  # the launcher is already gone
        os._exit(3)
    from bridge.core.plan import Plan

    plan = Plan.from_json(json.loads(Path(args.plan).read_text()))
    prof_dir = os.environ.get("SWARM_SITL_PROFILE")  # write cProfile stats per process, for `bench`
    prof = None
    if prof_dir:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    try:
        code = _world(args, plan) if args.role == "world" else _participant(args, plan)
    except Exception:
        traceback.print_exc()
        code = 1
    if prof is not None:
        prof.disable()
        prof.dump_stats(str(Path(prof_dir) / f"{args.proc}.prof"))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # zenoh-python can hang in interpreter teardown


if __name__ == "__main__":
    main()
