"""Run a behaviour on a real robot: ``python -m swarm_logic --hal hil_configs/robots/eswarbot_real.toml``.

This is the program a robot's companion computer runs. It is the same ``run_controller`` loop a SITL
session runs, with the wall clock and the devices the HAL config names (any python-can interface).
"""

from __future__ import annotations

import argparse
import sys
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
    try:
        robot = Robot.open(robot_id, hal, clock or CLOCKS[hal.get("clock", "monotonic")](), seed,
                           hal.get("params", {}))
    except (OSError, ValueError, LookupError, serial.SerialException, can.CanError) as e:
        raise SystemExit(f"{a.hal}: cannot open the robot's devices: {e}") from None
    try:
        run_controller(cls(), robot, a.duration)
    except KeyboardInterrupt:
        pass
    finally:
        robot.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
