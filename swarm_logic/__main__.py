"""Run a behaviour on a real robot: ``python -m swarm_logic --hal hil_configs/robots/eswarbot_real.toml``.

This is the program a robot's companion computer runs. It is the same ``run_controller`` loop a SITL
session runs, with the wall clock and the devices the HAL config names (any python-can interface).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import tomllib
from pathlib import Path
from typing import Any

import can
import serial

from swarm_logic.behaviours import load_behaviour
from swarm_logic.clock import Clock, RealtimeClock, WallClock
from swarm_logic.devices import BUILT_IN, NOT_DEVICES
from swarm_logic.robot import Robot
from swarm_logic.runner import run_controller


def load_hal(path: str) -> dict[str, Any]:
    p = Path(path)
    try:
        hal = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise SystemExit(f"{p}: no such file") from None
    except tomllib.TOMLDecodeError as e:
        raise SystemExit(f"{p}: not valid TOML: {e}") from None
    if isinstance(hal.get("llc_mavlink"), dict):  # a vehicle that only speaks MAVLink (swarm_logic.mavlink.low_level)
        if "llc_can" in hal:
            raise SystemExit(f"{p}: llc_can and llc_mavlink: name one low level, not both")
    elif ((isinstance(hal.get("llc_can"), dict) or not _own_devices(hal))
          and (not isinstance(hal.get("llc_can"), dict) or "interface" not in hal["llc_can"])):
        raise SystemExit(f"{p}: llc_can.interface: missing (a python-can interface, e.g. 'socketcan' or 'slcan'; "
                         "or llc_mavlink.url for a MAVLink vehicle, or the robot's own locomotion device)")
    if hal.get("clock", "monotonic") not in CLOCKS:
        raise SystemExit(f"{p}: clock: {hal['clock']!r} is not one of {', '.join(CLOCKS)}")
    return hal


def _own_devices(hal: dict[str, Any]) -> list[str]:
    """The HAL tables that are a robot's own devices (a Zebro's legs), not the LLC's or the built-in radios'."""
    return [k for k, v in hal.items() if isinstance(v, dict) and k not in BUILT_IN and k not in NOT_DEVICES]


# monotonic: this computer's own time; realtime: synchronised wall time, for swarms that number their steps by it
CLOCKS = {"monotonic": WallClock, "realtime": RealtimeClock}


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _Stop:
    """Ctrl-C and SIGTERM (a service manager's stop) end the loop alike, whatever disposition the program inherited (a
    program started in the background, or by a test runner, may have SIGINT ignored or blocked, and a SIGTERM would
    otherwise end it without stopping the motors): the first raises KeyboardInterrupt in the loop; one that comes
    while the robot closes (stopping its motors) is let pass, so the close is not cut short. The handlers are the
    main thread's, and put back after."""

    def __init__(self) -> None:
        self.closing = False
        self.old: dict[int, Any] = {}

    def __enter__(self) -> _Stop:
        if threading.current_thread() is threading.main_thread():
            self.old = {s: signal.signal(s, self._raise) for s in STOP_SIGNALS}
            signal.pthread_sigmask(signal.SIG_UNBLOCK, set(STOP_SIGNALS))
        return self

    def _raise(self, signum: int, frame: Any) -> None:
        if not self.closing:
            raise KeyboardInterrupt

    def __exit__(self, *exc: object) -> None:
        for s, h in self.old.items():
            signal.signal(s, h)


def main(argv: list[str] | None = None, clock: Clock | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m swarm_logic", description=__doc__)
    ap.add_argument("--hal", required=True, help="HAL config (TOML) naming the robot's devices")
    ap.add_argument("--behaviour", help="behaviour name or module:Class (default: the HAL config's)")
    ap.add_argument("--robot-id", type=int, help="this robot's id (default: the HAL config's)")
    ap.add_argument("--seed", type=int, default=None, help="seed of the behaviour's random stream")
    ap.add_argument("--duration", type=float, default=None, help="seconds to run (default: until Ctrl-C)")
    a = ap.parse_args(argv)
    hal = load_hal(a.hal)
    robot_id = a.robot_id if a.robot_id is not None else int(hal.get("robot_id", 0))
    behaviour = a.behaviour or hal.get("behaviour", "random_walk")
    seed = a.seed if a.seed is not None else int(hal.get("seed", robot_id))
    cls = load_behaviour(behaviour)
    with _Stop() as stop:
        try:
            robot = Robot.open(robot_id, hal, clock or CLOCKS[hal.get("clock", "monotonic")](), seed,
                               hal.get("params", {}))
        except (OSError, ValueError, LookupError, serial.SerialException, can.CanError) as e:
            raise SystemExit(f"{a.hal}: cannot open the robot's devices: {e}") from None
        except KeyboardInterrupt:  # stopped while its devices opened
            return 0
        try:
            run_controller(cls(), robot, a.duration)
        except KeyboardInterrupt:
            pass
        finally:
            stop.closing = True
            robot.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
