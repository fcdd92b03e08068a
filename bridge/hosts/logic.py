"""Hosts the swarm logic of one or more robots, each in its own robot thread (see ``sim_context``).

The robot program is the same ``swarm_logic.runner.run_controller`` a real robot runs; only the HAL
config (``interface = "sitl"``, ``sitl://`` serial ports) and the clock differ.
"""

from __future__ import annotations

import urllib.parse
from typing import Any

from bridge import sitl as urlhandler
from bridge.core.config import Config
from bridge.core.entities import entity, robot_of
from bridge.core.plan import Plan, RobotPlan
from bridge.core.registry import robot_spec
from bridge.core.rng import stream_seed
from bridge.hosts.sim_context import RobotRuntime, SessionClock
from swarm_logic.behaviours import load_behaviour
from swarm_logic.log import plain
from swarm_logic.robot import Robot
from swarm_logic.runner import run_controller

# ignore_config: python-can must not merge the host's ~/.canrc or CAN_* variables into a simulated bus
SITL_CAN = {"interface": "sitl", "channel": "can0", "ignore_config": True}


def sitl_hal(rp: RobotPlan, cfg: Config) -> dict[str, Any]:
    """The HAL config of a robot in a session: the devices it carries, on their simulated ports."""
    spec = robot_spec(rp.profile)
    hal: dict[str, Any] = {spec.can_hal: dict(SITL_CAN)} if spec.board is not None or spec.can_roles else {}
    if rp.vehicle is not None:  # a real MAVLink vehicle stands for the robot: the logic drives it over its link
        v = rp.vehicle
        hal = {"llc_mavlink": {"url": v["url"], "baudrate": v["baudrate"], "target_system": v["target_system"],
                               "target_component": v["target_component"], "timeout_s": v["timeout_s"]}}
    if rp.xbee and not rp.xbee.get("pty"):  # an XBee on a pseudo-terminal belongs to whoever opens the pty
        # Series 2 receive frames carry no RSSI: the host asks the module (ATDB) after each packet
        port = "sitl://xbee"
        if rp.xbee.get("device"):  # a real module: reads wait in simulated time, polling the device
            port += "?" + urllib.parse.urlencode({"device": rp.xbee["device"]})
        hal["xbee"] = {"port": port, "baudrate": rp.xbee["baud"], "api_mode": rp.xbee["api_mode"],
                       "rssi_from_db": rp.xbee["series"] == 2}
    if rp.uwb:
        hal["uwb"] = {"port": "sitl://uwb", "baudrate": cfg.uwb.uart_baud}
    m = cfg.mavlink
    if m.endpoint is not None and rp.vehicle is None:  # its face, behind the world's ground-station endpoint
        # (a vehicle has its own MAVLink: a ground station talks to it directly)
        hal["mavlink"] = {"port": "sitl://mavlink", "system_id": m.system_id_base + rp.id, "boot": m.boot}
        if m.rates:
            hal["mavlink"]["rates"] = dict(m.rates)
    if spec.hal is not None:  # the robot model's own devices, on their simulated buses and ports
        hal.update(spec.hal(rp, cfg))
    hal.update({name: dict(table) for name, table in rp.devices.items()})  # the ones the session's config adds
    hal["start_pose"] = list(rp.pose)  # where the robot was put down, as an operator would tell it
    if rp.payload:  # a carrier: who rides on its conveyor, as its operator loaded it
        hal["payload"] = list(rp.payload)
    return hal


class LogicHost:
    def __init__(self, plan: Plan, robots: tuple[int, ...]) -> None:
        urlhandler.register()
        self.plan = plan
        cfg = Config.from_plan(plan.config)
        seed = cfg.session.seed
        self.rts: dict[int, RobotRuntime] = {}
        self.reported: set[int] = set()
        # What robot programs import when they open their devices, imported while the session starts rather than in
        # a robot's first simulated quantum, where it would stall the lock-step: python-can's interface table and
        # the sitl bus, digi-xbee's packets (about 0.1 s together), filterpy with scipy (about a second)
        import can.interfaces  # noqa: F401

        import bridge.sitl.canbus  # noqa: F401
        if any(plan.robots[r].xbee for r in robots):
            import swarm_logic.drivers.xbee  # noqa: F401
        if any(plan.robots[r].uwb for r in robots):
            import filterpy.common
            import filterpy.kalman  # noqa: F401
        for r in robots:
            rp = plan.robots[r]
            rt = RobotRuntime(r)
            cls = load_behaviour(rp.behaviour)
            hal = sitl_hal(rp, cfg)

            def program(rt: RobotRuntime = rt, rp=rp, cls=cls, hal=hal) -> None:
                def sink(topic: str, values: dict, rt: RobotRuntime = rt) -> None:
                    rt.outbox.append(["log", topic, plain(values)])

                robot = Robot.open(rp.id, hal, SessionClock(rt), stream_seed(seed, "robot", rp.id, "logic"),
                                   rp.params, log_sink=sink)
                try:
                    run_controller(cls(), robot)
                finally:
                    robot.close()

            rt.start(program)
            self.rts[r] = rt

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        r = robot_of(ent)
        rt = self.rts[r]
        arrived: set[str] = set()
        for item in inputs["in"]:
            kind = item[0]
            if kind == "can0":  # a frame: [bus, id, data, extended, wire end, (own echo | error frame)]
                rt.deliver(kind, tuple(item[1:]))
            elif kind == "can0_state":  # this node's fault-confinement state changed: [bus, state, TEC, REC]
                rt.bus_state["can0"] = (item[1], item[2], item[3])
                continue
            else:  # ["uart:DEVICE", bytes]
                rt.deliver(kind, item[1])
            arrived.add(kind)
        rt.run_timers(t_ns)  # cyclic CAN sends due by now leave whether or not the thread runs
        if rt.due(t_ns, arrived):
            rt.resume(t_ns)
        out: dict[str, Any] = {"out": rt.outbox, "wake": rt.next_wake(), "wom": rt.wom}
        rt.outbox = []
        if rt.finished and r not in self.reported:
            self.reported.add(r)
            out["wake"] = None
            if rt.error:
                out["err"] = rt.error
        return out

    def stats(self) -> dict[str, dict]:
        return {entity(r, "logic"): {"rx_dropped": rt.rx_dropped, "unrouted": rt.unrouted}
                for r, rt in self.rts.items()}

    def stop(self) -> None:
        for rt in self.rts.values():
            rt.stop()
