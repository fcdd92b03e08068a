"""Plugins from outside the project: a robot, a behaviour and a study in a package of their own, found by entry point,
run in a whole session with no file of swarm-sitl edited; and the in-process registry calls."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from bridge.core.config import Config, ConfigError, load_config
from bridge.core.recorder import iter_messages
from bridge.core.registry import (
    MEDIA,
    ROBOTS,
    STUDIES,
    RobotSpec,
    register_robot,
    robot_profile,
    robot_spec,
)
from swarm_logic.behaviours import BEHAVIOURS, load_behaviour, register_behaviour
from swarm_logic.controller import Controller
from swarm_logic.plugins import PluginError
from tests.conftest import ROOT

PACKAGE = '''
"""A lab's own swarm-sitl plugins: the minibot robot (with a firmware entity and a device of its own), the circler
behaviour, the laps study."""

from dataclasses import replace
from typing import Any, ClassVar

from bridge.core.loop_functions import LoopFunctions
from bridge.core.recorder import register_schema
from bridge.core.registry import Study, robot_spec
from swarm_logic.controller import Controller

class Beacon:
    """A firmware entity of the minibot's own: it runs twice a second, counts its runs, reads the battery voltage at
    its pin and blinks its lamp."""

    def __init__(self, rp):
        self.counters = {"runs": 0, "robot": rp.id, "min_v": 99.0}

    def run(self, t_ns, inputs):
        self.counters["runs"] += 1
        self.counters["min_v"] = min(self.counters["min_v"], inputs["sens"]["v"])
        return {"out": [], "wake": t_ns + 500_000_000, "wom": False, "pins": {"lamp": self.counters["runs"] % 2}}


class BeaconWiring:
    """What the beacon's pins meet in the world: the battery; its lamp lights nothing the world models."""

    schema = "lab.BeaconPins"

    def sense(self, world, r, media, ideal_pose):
        reading = {"v": world.sensors(r)["battery_v"]}
        return reading, reading

    def valid(self, pins):
        return isinstance(pins, dict) and pins.get("lamp") in (0, 1)

    def actuate(self, world, r, pins):
        pass


register_schema("lab.BeaconPins", {"type": "object", "properties": {"v": {"type": "number"}, "lamp": {}}})


class Odo:
    """A device of the minibot's own on its companion computer (HAL table ``odo``), polled with the robot."""

    def __init__(self, cfg, robot):
        self.scale = cfg["scale"]
        self.polls = 0

    def poll(self):
        self.polls += 1


ESWARBOT = robot_spec("eswarbot")  # its board, wiring and CAN interface; a smaller, lighter body
MINIBOT = replace(ESWARBOT, name="minibot", title="Minibot: a smaller eSwarBot", default=False,
                  profile=ESWARBOT.profile.model_copy(update={"name": "minibot", "radius_m": 0.05, "mass_kg": 0.4}),
                  roles=lambda rp: ("beacon",), modules=lambda rp, cfg: {"beacon": Beacon(rp)},
                  wiring=lambda role: BeaconWiring() if role == "beacon" else None,
                  hal=lambda rp, cfg: {"odo": {"scale": 2}})


class Circler(Controller):
    """Drives in a circle and logs its odometry every step."""

    defaults: ClassVar[dict[str, Any]] = {"speed_mps": 0.1, "turn_rate_rps": 0.5, "period_s": 0.1}
    ranges: ClassVar[dict[str, str]] = {"speed_mps": "[0, 2]", "turn_rate_rps": "[0, 20]", "period_s": "(0, 10]"}

    def init(self, robot):
        super().init(robot)
        self.p = self.with_defaults(robot.params)
        self.period_s = self.p["period_s"]

    def step(self):
        self.robot.llc.drive(self.p["speed_mps"], self.p["turn_rate_rps"])
        odo = self.robot.device("odo")
        self.robot.log("lap", t=self.robot.clock.now(), polls=odo.polls, scale=odo.scale)


class Laps(LoopFunctions):
    """Counts the circlers' log records, and ends the session early once it has enough."""

    @classmethod
    def wanted(cls, cfg):
        return any(g.behaviour == "circler" for g in cfg.robots)

    def __init__(self, hub):
        super().__init__(hub)
        self.records = {}
        self.pre_steps = 0
        self.polls = 0

    def pre_step(self, t):
        self.pre_steps += 1

    def on_log(self, robot, topic, values, t):
        if topic == "lap":
            self.records[robot] = self.records.get(robot, 0) + 1
            self.polls = values["polls"] * values["scale"] // 2
            if sum(self.records.values()) >= 40:
                self.hub.end_ns = min(self.hub.end_ns, t + 1_000_000_000)

    def summary(self):
        return {"laps": {"records": {str(r): n for r, n in sorted(self.records.items())},
                         "pre_steps": self.pre_steps, "device_polls": self.polls}}


LAPS = Study("laps", "Laps: how often the circlers report", loop_functions=Laps, sections=("laps",))
'''

ENTRY_POINTS = '''
[swarm_sitl.robots]
minibot = labplugins:MINIBOT

[swarm_sitl.behaviours]
circler = labplugins:Circler

[swarm_sitl.devices]
odo = labplugins:Odo

[swarm_sitl.studies]
laps = labplugins:LAPS
'''

CONFIG = '''
[session]
name = "outside"
duration_s = 30
seed = 5

[arena]
width_m = 3
length_m = 3

[[robots]]
count = 2
profile = "minibot"
behaviour = "circler"
placement = { kind = "grid", origin = [1.0, 1.0], spacing_m = 0.8 }
'''


@pytest.fixture
def lab_package(tmp_path: Path) -> Path:
    """An installed package outside the project's folders: its module and its dist-info with entry points."""
    site = tmp_path / "site"
    (site / "labplugins").mkdir(parents=True)
    (site / "labplugins" / "__init__.py").write_text(textwrap.dedent(PACKAGE))
    info = site / "labplugins-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: labplugins\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    return site


def _env(site: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}


def test_a_robot_behaviour_and_study_from_outside_run_a_session(lab_package: Path, tmp_path: Path) -> None:
    cfg = tmp_path / "outside.toml"
    cfg.write_text(CONFIG)
    listed = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "list", "--json"], env=_env(lab_package),
                            capture_output=True, text=True, timeout=600)
    assert listed.returncode == 0, listed.stderr
    found = {kind: {row["name"]: row["from"] for row in rows} for kind, rows in json.loads(listed.stdout).items()}
    assert found["robots"]["minibot"] == "labplugins:MINIBOT" and "eswarbot" in found["robots"]
    assert found["behaviours"]["circler"] == "labplugins:Circler" and "rdpso" in found["behaviours"]
    assert found["studies"]["laps"] == "labplugins:LAPS" and "rdpso" in found["studies"]
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "run", str(cfg), "--out", str(out), "--quiet"],
                       env=_env(lab_package), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert [rr["profile"] for rr in s["per_robot"]] == ["minibot", "minibot"]
    assert all(rr["distance_m"] > 0.1 for rr in s["per_robot"])  # the circlers drove
    laps = s["laps"]  # the study's section, written by its loop functions
    assert sum(laps["records"].values()) >= 40 and set(laps["records"]) == {"0", "1"}
    assert s["sim_time_s"] < 30  # its end condition stopped the session before duration_s
    assert laps["pre_steps"] == s["quanta"]
    assert s["deployment"] is None and s["comm"] is None  # the RDPSO study's sections, not measured here
    # the minibot's own firmware entity ran on its schedule (twice a simulated second), its own device was polled
    runs = [rr["firmware"]["beacon"]["runs"] for rr in s["per_robot"]]
    assert all(abs(n - 2 * s["sim_time_s"]) <= 2 for n in runs), (runs, s["sim_time_s"])
    assert all(7.0 < rr["firmware"]["beacon"]["min_v"] < 8.5 for rr in s["per_robot"])  # its pin read the battery
    lamp = [json.loads(data) for topic, _t, data in iter_messages(out / "session.mcap") if topic == "/r001/beacon/pins"]
    assert len(lamp) == runs[1] and {m["lamp"] for m in lamp[1:]} == {0, 1}  # one record per run, as a board's
    assert laps["device_polls"] > 10
    assert found["devices"]["odo"] == "labplugins:Odo"


def test_plugins_not_installed_are_unknown(tmp_path: Path) -> None:
    cfg = tmp_path / "outside.toml"
    cfg.write_text(CONFIG)
    r = subprocess.run([sys.executable, "-m", "bridge.tools.cli", "validate", str(cfg)], capture_output=True,
                       text=True, timeout=600, cwd=ROOT)
    assert r.returncode == 2
    known = "known: decizebro, eswarbot, footbot, sonpi, traxbot"
    assert f"robots[0].profile: unknown robot profile 'minibot'; {known}" in r.stderr, r.stderr


def test_the_registry_calls(monkeypatch: pytest.MonkeyPatch) -> None:
    class Still(Controller):
        """Stays where it is."""

        def step(self) -> None:
            self.robot.llc.stop()

    spec = RobotSpec("stillbot", robot_profile("eswarbot").model_copy(update={"name": "stillbot"}))
    with pytest.raises(PluginError, match="go together"):
        RobotSpec("halfbot", spec.profile, board=lambda profile, rp: None)
    try:
        assert register_robot(spec) is spec and ROBOTS.get("stillbot") is spec
        assert register_behaviour("still", Still) is Still and load_behaviour("still") is Still
        assert ROBOTS.origin("stillbot") == "registered" and "still" in BEHAVIOURS.names()
        with pytest.raises(PluginError, match="registered already"):
            register_behaviour("still", type("Other", (Still,), {}))
        with pytest.raises(PluginError, match="is not a robot"):
            ROBOTS.register("notaspec", object())  # type: ignore[arg-type]
        with pytest.raises(ValueError, match=r"is not a swarm_logic\.controller\.Controller subclass"):
            load_behaviour("json:dumps")
    finally:
        ROBOTS.unregister("stillbot")
        BEHAVIOURS.unregister("still")
    assert "still" not in BEHAVIOURS.names()
    assert {"can", "uart", "radio", "uwb", "mavlink"} <= set(MEDIA.names()) and "rdpso" in STUDIES.names()


def test_a_robot_model_names_the_ports_an_external_logic_needs(tmp_path: Path) -> None:
    """``RobotSpec.external_ports``: the core demands the ports the robot model names, no other."""
    base = robot_spec("decizebro")
    spec = dataclasses.replace(base, name="portbot", external_ports={
        "uwb_radio_pty": "its program reaches the radio through its UART: expose it"})
    p = tmp_path / "external.toml"
    try:
        register_robot(spec)
        p.write_text('[session]\nspeed = 1\n[[robots]]\nprofile = "portbot"\nlogic = "external"\n')
        with pytest.raises(ConfigError, match=r"robots\[0\]: uwb_radio_pty: its program reaches the radio through"):
            load_config(p)
        p.write_text('[session]\nspeed = 1\n[[robots]]\nprofile = "portbot"\nlogic = "external"\n'
                     'uwb_radio_pty = "r{id}-uwb"\n')
        assert load_config(p).robots[0].logic == "external"  # no CAN bus asked of a robot that has none
    finally:
        ROBOTS.unregister("portbot")


def test_a_robot_models_own_boards_can_be_nodes_on_its_can_bus() -> None:
    """``RobotSpec.can_roles``: an own firmware entity named there is a node of the robot's CAN bus, beside the LLC
    and the companion computer; the others (a radio on a UART) are not."""
    from bridge.core.plan import RobotPlan

    base = robot_spec("decizebro")
    with pytest.raises(PluginError, match="CAN nodes of its own are its own firmware entities"):
        dataclasses.replace(base, name="nobot", roles=None, modules=None, wiring=None, ports={}, can_roles=("x",))
    spec = dataclasses.replace(base, name="canbot", can_roles=("imu",))
    try:
        register_robot(spec)
        rp = RobotPlan(0, "r000", "canbot", "zebro_silent", {}, (0.0, 0.0, 0.0))
        assert spec.has_can and "imu" in rp.modules()
        assert rp.can_nodes() == ("imu", "logic")
        assert RobotPlan(0, "r000", "decizebro", "zebro_silent", {}, (0.0, 0.0, 0.0)).can_nodes() == ()
    finally:
        ROBOTS.unregister("canbot")


def test_a_robot_model_names_the_hal_table_its_program_opens_its_can_bus_with() -> None:
    """``RobotSpec.can_hal``: the eSwarBot's program gets its LLC client (``llc_can``); a model whose boards speak
    another protocol has its program open the bus through a device of its own."""
    from bridge.core.config import Config
    from bridge.core.plan import RobotPlan
    from bridge.hosts.logic import SITL_CAN, sitl_hal

    cfg = Config.model_validate({"robots": [{"count": 1}]})
    assert sitl_hal(RobotPlan(0, "r000", "eswarbot", "random_walk", {}, (1.0, 1.0, 0.0)), cfg)["llc_can"] == SITL_CAN
    spec = dataclasses.replace(robot_spec("eswarbot"), name="otherbot", default=False, can_hal="other_can")
    try:
        register_robot(spec)
        hal = sitl_hal(RobotPlan(0, "r000", "otherbot", "random_walk", {}, (1.0, 1.0, 0.0)), cfg)
        assert hal["other_can"] == SITL_CAN and "llc_can" not in hal
    finally:
        ROBOTS.unregister("otherbot")


def test_a_session_s_other_processes_do_not_import_the_studies_loop_functions() -> None:
    """Every process of a session reads the config (and so every study's config sections); only the world runs loop
    functions. Named by reference ("module:Class"), they and their metrics (scipy) stay out of the participants,
    which start a quarter faster for it."""
    code = ("import sys, bridge.core.plan, bridge.hosts.logic, bridge.hosts.firmware; "
            "print(sorted(m for m in sys.modules if m.endswith('.loop_functions') or m == 'scipy'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    from bridge.core.loop_functions import LoopFunctions
    from bridge.core.registry import STUDIES

    for name, study in STUDIES.items():
        lf = study.loop_functions_class()
        assert lf is not None and issubclass(lf, LoopFunctions), name
    # the world imports every study's loop functions to ask each whether it is wanted: none imports scipy for that
    code = ("import sys; from bridge.core.registry import STUDIES; "
            "[st.loop_functions_class() for _, st in STUDIES.items()]; print('scipy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_session_s_processes_do_not_run_the_launcher_s_checks_again(tmp_path: Path) -> None:
    """The launcher checks the whole config (each service's and study's checks, which load plugin classes: a region
    controller's planners, scipy); a session's processes validate the plan's copy without them (``from_plan``)."""
    from bridge.core.plan import make_plan

    cfg_path = Path(__file__).resolve().parents[2] / "hil_configs" / "sonpi" / "regions_ch6.toml"
    plan = make_plan(load_config(cfg_path))
    (tmp_path / "plan.json").write_text(json.dumps(plan.to_json()))
    code = ("import json, sys; from bridge.core.config import Config; "
            f"c = Config.from_plan(json.load(open({str(tmp_path / 'plan.json')!r}))['config']); "
            "print(c.services[1].kind, 'scipy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["global_controller", "False"]
    bad = json.loads((tmp_path / "plan.json").read_text())["config"]
    bad["services"][1]["options"]["target"] = [99.0, 0.5]  # outside the arena: the launcher's check refuses it
    with pytest.raises(ValueError, match=r"services\[1\]\.options\.target"):
        Config.model_validate(bad)
    assert Config.from_plan(bad).services[1].options["target"] == [99.0, 0.5]  # (the launcher's to refuse, not theirs)
