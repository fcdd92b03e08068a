"""Hosts the swarm logic of one or more robots, each in its own robot thread (see ``sim_context``).

The robot program is the same ``swarm_logic.runner.run_controller`` a real robot runs; only the HAL
config (``interface = "sitl"``) and the clock differ.
"""

from __future__ import annotations

from typing import Any

from bridge.plan import Plan, robot_of
from bridge.rng import stream_seed
from bridge.sim_context import RobotRuntime, SessionClock
from swarm_logic.behaviours import load_behaviour
from swarm_logic.robot import Robot
from swarm_logic.runner import run_controller

# ignore_config: python-can must not merge the host's ~/.canrc or CAN_* variables into a simulated bus
SITL_HAL = {"llc_can": {"interface": "sitl", "channel": "can0", "ignore_config": True}}


class LogicHost:
    def __init__(self, plan: Plan, robots: tuple[int, ...]) -> None:
        self.plan = plan
        seed = plan.config["session"]["seed"]
        self.rts: dict[int, RobotRuntime] = {}
        self.reported: set[int] = set()
        for r in robots:
            rp = plan.robots[r]
            rt = RobotRuntime(r)
            cls = load_behaviour(rp.behaviour)

            def program(rt: RobotRuntime = rt, rp=rp, cls=cls) -> None:
                robot = Robot.open(rp.id, SITL_HAL, SessionClock(rt), stream_seed(seed, "robot", rp.id, "logic"),
                                   rp.params)
                try:
                    run_controller(cls(), robot)
                finally:
                    robot.close()

            rt.start(program)
            self.rts[r] = rt

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        r = robot_of(ent)
        rt = self.rts[r]
        for bus, arb_id, data, ext, ts in inputs["in"]:
            rt.deliver(bus, (arb_id, data, ext, ts))
        rt.resume(t_ns)
        out: dict[str, Any] = {"out": rt.outbox, "wake": rt.wake_ns, "wom": rt.wom}
        rt.outbox = []
        if rt.finished and r not in self.reported:
            self.reported.add(r)
            out["wake"] = None
            if rt.error:
                out["err"] = rt.error
        return out

    def stop(self) -> None:
        for rt in self.rts.values():
            rt.stop()
