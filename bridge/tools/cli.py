"""``swarm-sitl``: run, validate, benchmark and inspect SITL sessions."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from bridge.core.config import ConfigError, load_config
from bridge.tools.argtypes import at_least_one, numbers, positive, speed


def _overrides(a: argparse.Namespace) -> dict[str, Any]:
    return {
        "robots.count": a.robots,
        "session.duration_s": a.duration,
        "session.seed": a.seed,
        "session.speed": a.speed,
        "session.robots_per_process": a.robots_per_process,
        "mavlink.endpoint": a.mavlink,
    }


def cmd_run(a: argparse.Namespace) -> int:
    from bridge.core.launcher import run_session, say

    out = a.out or f"runs/{Path(a.config).stem}"
    res = run_session(a.config, {**_overrides(a), "session.live": a.live,
                                 "session.record_ticks": True if a.record_ticks else None}, out,
                      progress=None if a.quiet else sys.stderr, plot=not a.no_plot)
    if res.summary.get("error"):
        say(sys.stderr, res.summary["error"].strip().splitlines()[-1] + "\n")
    return res.code


def cmd_join(a: argparse.Namespace) -> int:
    import os

    from bridge.hil.join import JoinError, join

    try:
        code = join(a.endpoint, a.session, a.robot, timeout_s=a.timeout, world_timeout_s=a.world_timeout,
                    host=a.host)
    except JoinError as e:
        print(f"swarm-sitl join: {e}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        print("swarm-sitl join: interrupted before joining", file=sys.stderr)
        code = 130
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # zenoh-python can hang in interpreter teardown


def cmd_validate(a: argparse.Namespace) -> int:
    from bridge.core.config import config_warnings
    from bridge.core.plan import make_plan

    cfg = load_config(a.config, _overrides(a))
    plan = make_plan(cfg, a.config)
    for w in config_warnings(cfg):
        print(f"{a.config}: warning: {w}", file=sys.stderr)
    print(f"{a.config}: ok: {len(plan.robots)} robots, {len(plan.procs) + 1} processes, "
          f"{cfg.session.duration_s} s at quantum {cfg.session.quantum_ms} ms, seed {cfg.session.seed}")
    return 0


def cmd_digest(a: argparse.Namespace) -> int:
    from bridge.core.recorder import NotARecording, file_digest

    try:
        d, n = file_digest(a.recording)
    except NotARecording as e:
        print(f"swarm-sitl digest: {e}", file=sys.stderr)
        return 2
    print(json.dumps({"digest": d, "messages": n}))
    return 0


def cmd_recover(a: argparse.Namespace) -> int:
    from bridge.core.recorder import NotARecording, recover_in_place

    rec = Path(a.recording)
    if rec.is_dir():
        rec = rec / "session.mcap"
    try:
        if not rec.is_file():
            raise NotARecording(f"{rec}: no such recording")
        r = recover_in_place(rec)
    except (NotARecording, FileExistsError) as e:
        print(f"swarm-sitl recover: {e}", file=sys.stderr)
        return 2
    if r is None:
        print(f"{rec}: a finished recording, nothing to recover")
    else:
        print(f"{rec}: {r.messages} messages up to simulated t={r.last_time_ns / 1e9:.3f} s, digest {r.digest} "
              f"(the cut file kept as {rec.name}.damaged)")
    return 0


def cmd_plot(a: argparse.Namespace) -> int:
    from bridge.core.plan import Plan
    from bridge.core.plot import plot_session

    rec = Path(a.recording)
    plan = Plan.from_json(json.loads((rec.parent / "plan.json").read_text()))
    out = a.out or str(rec.with_name("trajectories.png"))
    plot_session(rec, plan, out)
    print(out)
    return 0


def cmd_bench(a: argparse.Namespace) -> int:
    from bridge.tools.bench import run_bench, run_study_bench

    study = "rdpso" if a.rdpso else a.study
    if study:
        return run_study_bench(study, quick=a.quick, duration=a.duration, out_dir=a.out)
    if a.hosts:
        from bridge.tools.bench_hosts import run_hosts_bench

        return run_hosts_bench(a.hosts, a.link_delay_ms, robots=a.robots or 10, per_process=a.robots_per_process or 5,
                               duration=a.duration or 10.0, out_dir=a.out if a.out != "runs/bench" else
                               "runs/bench-hosts", config=a.config, markdown=a.markdown)

    return run_bench(quick=a.quick, duration=a.duration, out_dir=a.out, markdown=a.markdown, profile=a.profile,
                     config=a.config, scale=a.scale, cases_file=a.cases)


def cmd_radio_survey(a: argparse.Namespace) -> int:
    from bridge.tools.radio_survey import run_survey

    out = a.out or f"runs/{Path(a.config).stem}-radio-survey"
    cal = run_survey(a.config, out, duration_s=a.duration, interval_s=a.interval, seed=a.seed, series=a.series,
                     progress=None if a.quiet else sys.stderr, aps_retries=a.aps_retries)
    for k, v in cal.items():
        if isinstance(v, dict):
            verdict = {True: "  PASS", False: "  FAIL", None: "  (no data: run longer)"}.get(v.get("pass"), "")
            if "pass" not in v:
                verdict = ""
            print(f"{k}: {json.dumps({kk: vv for kk, vv in v.items() if kk != 'pass'})}{verdict}")
    print(f"wrote {out}/survey.csv, {out}/survey.png, {out}/calibration.json")
    return 0


def cmd_radio_fit(a: argparse.Namespace) -> int:
    from bridge.tools.radio_fit import fit_csv

    try:
        res = fit_csv(a.csv, a.out, tx_power_dbm=a.tx_power, sensitivity_dbm=a.sensitivity, d0_m=a.d0)
    except ValueError as e:
        print(f"swarm-sitl radio-fit: {e}", file=sys.stderr)
        return 2
    print(json.dumps({k: v for k, v in res.items() if k != "radio"}, indent=1, default=float))
    print(f"[radio] fields: {json.dumps(res['radio'])}")
    if a.out:
        print(f"wrote {a.out}")
    return 0


def _cell_choice(text: str) -> tuple[str, list[str]]:
    """``KEY=V1,V2`` of ``experiment --only``."""
    key, sep, values = text.partition("=")
    chosen = [v.strip() for v in values.split(",") if v.strip()]
    if not sep or not key.strip() or not chosen:
        raise argparse.ArgumentTypeError(f"{text!r}: write KEY=V1[,V2...], e.g. n=15,30")
    return key.strip(), chosen


def cmd_experiment(a: argparse.Namespace) -> int:
    from bridge.experiments.cluster import ClusterError
    from bridge.experiments.runner import UnknownExperimentError, execute_experiment, experiments

    if a.list:
        known = experiments()
        width = max((len(n) for n in known), default=0)
        for name, cls in known.items():
            print(f"{name:<{width}}  {cls.title}")
        return 0
    if not a.name:
        print("swarm-sitl experiment: name an experiment (--list shows them)", file=sys.stderr)
        return 2
    only: dict[str, list[str]] = {}
    for key, values in a.only:  # --only n=15 --only n=30 is --only n=15,30
        chosen = only.setdefault(key, [])
        chosen += [v for v in values if v not in chosen]
    try:
        run = execute_experiment(a.name, trials=a.trials, jobs=a.jobs, out=a.out, smoke=a.smoke, seed=a.seed,
                                 progress=not a.quiet, only=only or None, resume=a.resume, cluster=a.cluster,
                                 cluster_timeout_s=a.cluster_timeout)
    except (UnknownExperimentError, ValueError, ClusterError) as e:
        print(f"swarm-sitl experiment: {e}", file=sys.stderr)
        return 2
    for t, ours, ok, _note in run.verdicts:
        verdict = {True: "PASS", False: "FAIL"}.get(ok, "not judged")
        print(f"{t.id}: {ours} (thesis {t.thesis}; {t.tolerance})  {verdict}")
    state = "interrupted: " if run.interrupted else ""
    print(f"{a.name}: {state}{len(run.outcomes)}/{run.total} trials ran, {run.failed} failed, {run.wall_s:.0f} s")
    plots = f", {run.out}/plots/" if (run.out / "plots").is_dir() else ""
    print(f"wrote {run.out}/report.md, {run.out}/trials.csv{plots}")
    return 130 if run.interrupted else 1 if run.failed else 0


def cmd_devices(a: argparse.Namespace) -> int:
    from bridge.hil.devices import session_devices

    cfg = load_config(a.config)
    out = a.out or f"runs/{Path(a.config).stem}"
    found = session_devices(cfg, out)
    if not found:
        print(f"{a.config}: opens nothing to the outside world: a fully simulated session")
        return 0
    bad = 0
    for d in found:
        print(f"{d.field}: {d.target}\n    {d.note}")
        if d.real and not a.no_check:
            rep = d.check()
            bad += not rep.ok
            print(f"    {'answers' if rep.ok else 'FAILED'}: {rep.detail}")
    return 1 if bad else 0


def cmd_canlog(a: argparse.Namespace) -> int:
    from bridge.tools.canlog import export

    rec = Path(a.recording)
    if rec.is_dir():
        rec = rec / "session.mcap"
    try:
        n = export(rec, a.out, set(a.robot) if a.robot else None)
    except ValueError as e:
        print(f"swarm-sitl canlog: {e}", file=sys.stderr)
        return 2
    print(f"wrote {n} frames to {a.out}")
    return 0


def _session_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="session config (TOML), e.g. hil_configs/demo.toml")
    p.add_argument("--robots", type=int, help="robot count (configs with one [[robots]] group)")
    p.add_argument("--duration", type=float, help="simulated seconds")
    p.add_argument("--seed", type=int)
    p.add_argument("--speed", type=speed, help="real-time factor to pace to, or 'max'")
    p.add_argument("--robots-per-process", type=int, help="pack K robots into each firmware/logic process")
    p.add_argument("--mavlink", nargs="?", const="udpout:127.0.0.1:14550", metavar="ENDPOINT",
                   help="give every robot a MAVLink face behind one UDP endpoint (default udpout:127.0.0.1:14550, "
                        "where MAVProxy and QGroundControl listen)")



def _parser_run(sub: Any) -> None:
    p = sub.add_parser("run", help="run one session")
    _session_args(p)
    p.add_argument("--live", nargs="?", const="127.0.0.1:0", metavar="HOST:PORT",
                   help="serve the scene to Foxglove while the session runs (its WebSocket server on loopback; "
                        "default 127.0.0.1 and a free port, printed at the start)")
    p.add_argument("--record-ticks", action="store_true",
                   help="record every run of the robots' processes, for swarm-sitl replay (session.record_ticks)")
    p.add_argument("--out", help="output directory (default runs/<config name>)")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--no-plot", action="store_true",
                   help="do not draw trajectories.png (about a CPU-second a session, for scripts and CI)")
    p.set_defaults(fn=cmd_run)


def _parser_join(sub: Any) -> None:
    p = sub.add_parser("join", help="run a remote robot's swarm logic, or a host's processes, on this computer for a "
                                    "session on another one (its config: session.listen, the robot's logic = "
                                    "\"remote\" or [[hosts]])")
    p.add_argument("endpoint", help="where the session's world listens: its session.listen with that computer's "
                                    "address, e.g. tcp/192.168.1.10:7447")
    p.add_argument("--session", required=True, help="the session's name (session.name in its config)")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--robot", type=int, help="the robot whose logic to run (default: the session's only remote "
                                                 "robot)")
    which.add_argument("--host", help="run all the processes the session places on this host (its [[hosts]] name)")
    p.add_argument("--timeout", type=positive, default=10.0,
                   help="wall seconds to wait for the session to answer (default 10)")
    p.add_argument("--world-timeout", type=positive, default=10.0,
                   help="wall seconds the world may be unreachable before the join gives up (default 10)")
    p.set_defaults(fn=cmd_join)


def _parser_validate(sub: Any) -> None:
    p = sub.add_parser("validate", help="check a config without running it")
    _session_args(p)
    p.set_defaults(fn=cmd_validate)


def _parser_bench(sub: Any) -> None:
    p = sub.add_parser("bench", help="real-time factor and barrier cost at several robot counts and packings")
    p.add_argument("--quick", action="store_true", help="a small smoke subset (for CI)")
    p.add_argument("--duration", type=float, help="simulated seconds per case")
    p.add_argument("--out", default="runs/bench")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--profile", action="store_true", help="profile every process; print the world's hot spots")
    p.add_argument("--config", help="session config to benchmark (default: the demo)")
    p.add_argument("--scale", action="store_true",
                   help="the scale goals' cases (hil_configs/bench/scale.toml): the radio demo at 10 to 50 robots, 10 "
                        "robots without radios, the 60-scout pavilion packed, 200 robots packed; each with its goal")
    p.add_argument("--cases", help="a TOML file of cases ([[cases]]: label, config, robots, per_process, goal)")
    p.add_argument("--study", help="a study's own figures (rdpso: a numerical E9 cell's wall time with 100 and "
                                   "1000 robots and the 12-robot arena's real-time factor; zebro: 20 Zebros' "
                                   "real-time factor by packing and body model, and the numerical 360-run table's "
                                   "wall time; roy: 100 numerical runs of chapter 3's scenario with BAT, wall time "
                                   "and runs/s, the SonPI camera sessions, chapter 6 with 1000 agents and the "
                                   "SonPIs under chapter 6's region planner)")
    p.add_argument("--rdpso", action="store_true", help="the same as --study rdpso")
    p.add_argument("--hosts", type=numbers(int, 1, "1,2"), metavar="N[,N...]",
                   help="the robots' processes on N other hosts (joins on this machine over TCP), against all here: "
                        "RTF and barrier per case")
    p.add_argument("--link-delay-ms", type=numbers(float, 0, "0.2,1"), default=[0.2, 1.0], metavar="D[,D...]",
                   help="with --hosts: one-way delays of the hosts' links (a delay relay each way; default 0.2,1), "
                        "besides loopback without a relay")
    p.add_argument("--robots", type=at_least_one, help="with --hosts: robot count (default 10)")
    p.add_argument("--robots-per-process", type=at_least_one, help="with --hosts: packing (default 5)")
    p.set_defaults(fn=cmd_bench)


def _parser_radio_survey(sub: Any) -> None:
    p = sub.add_parser("radio-survey", help="the thesis' RSSI-vs-distance survey (Fig. 3.7) in a config's arena")
    p.add_argument("config", help="session config whose arena (and robots' XBee settings) to survey in")
    p.add_argument("--duration", type=float, default=3600.0, help="simulated seconds (default 3600)")
    p.add_argument("--interval", type=float, default=2.0, help="seconds between messages (default 2, as the thesis)")
    p.add_argument("--seed", type=int)
    p.add_argument("--series", type=int, choices=[1, 2], help="XBee series (default: the config's, else 2)")
    p.add_argument("--aps-retries", action="store_true",
                   help="Series 2: let the module re-send a lost packet (ZigBee APS retries); rows become messages")
    p.add_argument("--out", help="output directory (default runs/<config>-radio-survey)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(fn=cmd_radio_survey)


def _parser_radio_fit(sub: Any) -> None:
    p = sub.add_parser("radio-fit", help="fit path loss and shadowing to RSSI-vs-distance pairs (a CSV)")
    p.add_argument("csv", help="columns distance_m, rssi_dbm (empty: lost), optional walls")
    p.add_argument("--out", help="write the fitted [radio] config fragment (TOML) here")
    p.add_argument("--tx-power", type=float, default=3.0, help="transmit power, dBm (XBee S2 at PL 4: +3)")
    p.add_argument("--sensitivity", type=float, default=-94.0, help="receiver sensitivity, dBm")
    p.add_argument("--d0", type=float, default=1.0, help="reference distance, m")
    p.set_defaults(fn=cmd_radio_fit)


def _parser_experiment(sub: Any) -> None:
    p = sub.add_parser("experiment", help="run a named, seeded experiment: many trials in parallel, CSV, plots and a "
                                          "report against the thesis' figures")
    p.add_argument("name", nargs="?", help="experiment name (--list shows them)")
    p.add_argument("--list", action="store_true", help="list the experiments and exit")
    p.add_argument("--trials", type=at_least_one, help="trials per cell (default: the experiment's own)")
    p.add_argument("--jobs", type=at_least_one, help="worker processes (default: one per CPU; 1 runs in-process)")
    p.add_argument("--out", help="output directory (default runs/experiments/<name>, with --smoke <name>-smoke)")
    p.add_argument("--smoke", action="store_true", help="a few short trials per cell (for CI)")
    p.add_argument("--seed", type=int, default=0, help="base seed; each trial's seed derives from it (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--only", type=_cell_choice, action="append", default=[], metavar="KEY=V1[,V2...]",
                   help="run only the cells whose KEY is one of the values (repeat for more keys; e.g. "
                        "--only n=15,30); trial seeds stay those of the full run")
    p.add_argument("--resume", action="store_true",
                   help="take the trials an earlier run into the same --out finished (same cell, index and seed) "
                        "instead of running them again: an interrupted run goes on, added cells run alone")
    p.add_argument("--cluster", metavar="ADDRESS",
                   help="run the trials on the Dask cluster whose scheduler is at ADDRESS (tcp://HOST:PORT; its "
                        "workers run this swarm-sitl) instead of local worker processes; the same outputs")
    p.add_argument("--cluster-timeout", type=positive, default=30.0, metavar="SECONDS",
                   help="how long to wait for the cluster's scheduler and a first worker (default 30)")
    p.set_defaults(fn=cmd_experiment)


def _parser_digest(sub: Any) -> None:
    p = sub.add_parser("digest", help="recompute the digest of a recording")
    p.add_argument("recording")
    p.set_defaults(fn=cmd_digest)


def _parser_recover(sub: Any) -> None:
    p = sub.add_parser("recover", help="rewrite a recording whose writer died (no footer) as a finished one, up to "
                                       "where it was cut")
    p.add_argument("recording", help="session.mcap, or the session's output directory")
    p.set_defaults(fn=cmd_recover)


def _parser_devices(sub: Any) -> None:
    p = sub.add_parser("devices", help="what a config would open to the outside world (pseudo-terminals, real "
                                       "devices, the MAVLink endpoint); checks that each real device answers")
    p.add_argument("config")
    p.add_argument("--out", help="the session's output directory, where its pseudo-terminal links go")
    p.add_argument("--no-check", action="store_true", help="only list; do not open the real devices")
    p.set_defaults(fn=cmd_devices)


def _parser_canlog(sub: Any) -> None:
    p = sub.add_parser("canlog", help="a session's CAN traffic as a python-can log (ASC, BLF, candump .log, CSV, "
                                      "TRC): for cantools, SavvyCAN, Vector tools")
    p.add_argument("recording", help="session.mcap, or the session's output directory")
    p.add_argument("out", help="log file; the format follows the suffix: .asc .blf .log .csv .trc")
    p.add_argument("--robot", type=int, action="append", help="only this robot's bus (repeat for more; default all)")
    p.set_defaults(fn=cmd_canlog)


def cmd_replay(a: argparse.Namespace) -> int:
    from bridge.tools.replay import ReplayError, replay

    try:
        out = replay(a.run, a.robot, a.role, stop_in_pdb=a.pdb)
    except ReplayError as e:
        print(f"swarm-sitl replay: {e}", file=sys.stderr)
        return 2
    if out.divergence is None:
        print(f"identical: robot {a.robot}'s {a.role}, {out.runs} runs")
        return 0
    print(f"robot {a.robot}'s {a.role}, run {out.runs}: {out.divergence}")
    return 1


def _parser_replay(sub: Any) -> None:
    p = sub.add_parser("replay", help="re-run one robot's logic or firmware against its recorded inputs and compare "
                                      "its answers (a run recorded with session.record_ticks = true)")
    p.add_argument("run", help="the session's output directory (or its session.mcap)")
    p.add_argument("--robot", type=int, required=True)
    p.add_argument("--role", choices=["logic", "firmware"], required=True)
    p.add_argument("--pdb", action="store_true", help="stop in the debugger at the first divergence")
    p.set_defaults(fn=cmd_replay)


def cmd_report(a: argparse.Namespace) -> int:
    from bridge.tools.browser import BrowserError, render
    from bridge.tools.report import ReportError, write_report

    try:
        page = write_report(a.run, a.out)
    except ReportError as e:
        print(f"swarm-sitl report: {e}", file=sys.stderr)
        return 2
    print(page)
    if a.screenshot:
        try:
            shown = render(page, a.screenshot, width=a.width, section=a.section, max_height=a.height)
        except BrowserError as e:
            print(f"swarm-sitl report: --screenshot: {e}", file=sys.stderr)
            return 1
        w, h = shown.png_size or (0, 0)
        what = (f"section {a.section}" if a.section else "the whole page" if h >= shown.height else
                f"the top {h} px of {shown.height}")
        print(f"{a.screenshot} ({w}x{h}, {what})")
    return 0


def _parser_report(sub: Any) -> None:
    p = sub.add_parser("report", help="one HTML page about a session: figures, plots, robots, failures, config")
    p.add_argument("run", help="the session's output directory")
    p.add_argument("--out", help="the page (default RUN/report.html)")
    p.add_argument("--screenshot", metavar="PNG", help="also render the page in a headless browser (Qt WebEngine) "
                                                        "and save it as a PNG")
    p.add_argument("--section", help="with --screenshot: only this section (figures, trajectories, connectivity, "
                                     "rssi, robots, failures, events, config)")
    p.add_argument("--width", type=int, default=1100, help="with --screenshot: the browser's width in pixels")
    p.add_argument("--height", type=int, default=12000, help="with --screenshot: at most this many pixels from the "
                                                               "top of the page")
    p.set_defaults(fn=cmd_report)


def cmd_layout(a: argparse.Namespace) -> int:
    from bridge.tools.foxglove_layout import layout_json

    text = layout_json()
    if a.out:
        Path(a.out).write_text(text)
        print(a.out)
    else:
        sys.stdout.write(text)
    return 0


def _parser_layout(sub: Any) -> None:
    p = sub.add_parser("layout", help="the Foxglove layout that opens a recording or the live scene ready to watch "
                                      "(docs/foxglove-layout.json)")
    p.add_argument("--out", help="write it to this file (default: standard output)")
    p.set_defaults(fn=cmd_layout)


def _parser_plot(sub: Any) -> None:
    p = sub.add_parser("plot", help="draw trajectories.png from a recording (plan.json beside it)")
    p.add_argument("recording")
    p.add_argument("--out")
    p.set_defaults(fn=cmd_plot)


def build_parser() -> argparse.ArgumentParser:
    """The ``swarm-sitl`` command line: one parser per subcommand, each beside its ``cmd_*``."""
    from bridge.tools.campaign import add_parser as add_campaign
    from bridge.tools.catalogue import add_parser as add_list
    from bridge.tools.fuzz import add_parser as add_fuzz

    ap = argparse.ArgumentParser(prog="swarm-sitl", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    for add in (_parser_run, _parser_join, _parser_validate, _parser_bench, _parser_radio_survey, _parser_radio_fit,
                _parser_experiment, _parser_digest, _parser_devices, _parser_canlog, add_list, _parser_plot,
                _parser_layout, _parser_replay, _parser_report, _parser_recover, add_campaign, add_fuzz):
        add(sub)
    return ap


def main(argv: list[str] | None = None) -> None:
    ap = build_parser()
    a = ap.parse_args(argv)
    try:
        code = a.fn(a)
    except ConfigError as e:
        print(f"config error: {e}", file=sys.stderr)
        code = 2
    except FileNotFoundError as e:
        print(f"swarm-sitl {a.cmd}: no such file: {e.filename}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:  # Ctrl-C outside a session (which handles its own): before it starts, or after
        code = 130
    except BrokenPipeError:  # the reader of our output went away (`| head`)
        code = 1
        _drop_output()
    try:  # what is still buffered, now: at exit Python would report a failed flush as an error of its own
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        code = code or 1
        _drop_output()
    sys.exit(code)


def _drop_output() -> None:
    """stdout and stderr are gone (a closed pipe): send whatever is left of them to /dev/null."""
    from bridge.core.launcher import output_gone

    for stream in (sys.stdout, sys.stderr):
        output_gone(stream)


if __name__ == "__main__":
    main()
