"""The DeciZebro's radio and IMU as firmware entities of the robot: the DWM1001 UWB radio with data (role
``uwb_radio``, ``firmware_sim.robots.decizebro.uwb_radio``) and the BNO055 IMU (role ``imu``,
``firmware_sim.robots.decizebro.imu``), each on its own serial line to the Raspberry Pi (``sitl://uwb_radio``,
``sitl://imu``), and the HAL tables the robot program opens them with.

The pieces combine with the leg modules' in the robot's ``RobotSpec``: ``RADIO_ROLES`` its roles, ``radio_modules``
its entities, ``RADIO_PORTS`` its serial lines, ``radio_hal`` its HAL tables, ``radio_wiring`` the IMU's wiring, and
``RadioOptions`` / ``radio_configure`` the robot group options (``sensing``, and the pseudo-terminals for a program
outside the session: ``uwb_radio_pty``, ``imu_pty``, the I2C bus's ``i2c_pty`` and the utility board's
``utility_pty``).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from bridge.core.profile import RobotProfile
from bridge.core.registry import robot_spec
from bridge.robots.decizebro.contact_legs import CONTACT_LEGS
from bridge.robots.decizebro.imu import ImuParams, ImuWiring
from bridge.robots.decizebro.legs import LegsParams
from firmware_sim.robots.decizebro.imu import Bno055
from firmware_sim.robots.decizebro.uwb_radio import UwbRadio

RADIO = "uwb_radio"
IMU = "imu"
RADIO_ROLES = (RADIO, IMU)
RADIO_BAUD = 115200  # the DWM1001's UART (DWM1001 datasheet: 115200 8N1)
IMU_BAUD = 115200  # the BNO055's UART default (datasheet section 4.7)
RADIO_PORTS = {RADIO: RADIO_BAUD, IMU: IMU_BAUD}


class RadioOptions(BaseModel):
    """A DeciZebro group's radio and IMU options."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    sensing: Literal["realistic", "faithful"] = Field(
        "realistic", description="realistic: the UWB medium's range errors and losses, PDoA bearing noise and "
                                 "front-back folding, the IMU's heading bias and noise; faithful: error-free ranges, "
                                 "bearings (all round), delivery and heading, as the thesis assumes (section 3.1)")
    body: Literal["gait", "contact"] = Field(
        "gait", description="the body model in the world: gait, a box whose motion the legs in stance impose "
                            "(legs.py); contact, a box on six jointed C-legs that walk by pushing on the floor "
                            "(contact_legs.py: slower to simulate)")
    uwb_radio_pty: str | None = Field(
        None, description="expose the UWB radio's UART on a pseudo-terminal linked at this path (relative to the "
                          "session's output directory; '{id}' is replaced by the robot id); the robot's own program "
                          "then does not open it")
    i2c_pty: str | None = Field(
        None, description="expose the robot's I2C bus (its six leg modules) on a pseudo-terminal as a Devantech "
                          "USB-ISS USB-to-I2C adapter, linked at this path (relative to the session's output "
                          "directory; '{id}' is replaced by the robot id): swarm_logic's usb-iss:// bus opens it; the "
                          "robot's own program then does not open its bus")
    imu_pty: str | None = Field(
        None, description="expose the BNO055 IMU's UART on a pseudo-terminal linked at this path (as uwb_radio_pty); "
                          "the robot's own program then does not open it")
    utility_pty: str | None = Field(
        None, description="expose the utility sensor board's serial line on a pseudo-terminal linked at this path (as "
                          "uwb_radio_pty); the robot's own program then does not open it")


def radio_configure(profile: RobotProfile, options: RadioOptions) -> RobotProfile:
    """The faithful mode's IMU reads the true heading; the contact body walks on jointed legs instead of the
    gait-level model's."""
    if options.body == "contact":
        parts = tuple(CONTACT_LEGS if isinstance(p, LegsParams) else p for p in profile.parts)
        profile = profile.model_copy(update={"parts": parts})
    if options.sensing != "faithful":
        return profile
    parts = tuple(p.model_copy(update={"heading_bias_deg": 0.0, "heading_noise_deg": 0.0,
                                                          "accel_bias_mps2": 0.0, "accel_noise_mps2": 0.0})
                  if isinstance(p, ImuParams) else p for p in profile.parts)
    return profile.model_copy(update={"parts": parts})


def radio_team(cfg: Any) -> list[int]:
    """The robots carrying a UWB radio, in robot order: their TDMA slots (ids as the plan numbers the groups)."""
    team, first = [], 0
    for g in cfg.robots:
        if RADIO in robot_spec(g.profile).ports:
            team += range(first, first + g.count)
        first += g.count
    return team


class RadioEntity:
    """The UWB radio as the firmware host runs it: the host's bytes and the medium's frames in, its frames on the air
    and its bytes to the host (or to its pseudo-terminal) out; it wakes on either."""

    def __init__(self, rp: Any, cfg: Any) -> None:
        team = radio_team(cfg)
        u = cfg.uwb
        opts = RadioOptions.model_validate(rp.options)
        self.module = UwbRadio(robot=rp.id, slot=team.index(rp.id), n_slots=len(team), frames_per_s=u.frames_per_s,
                               update_rate_hz=u.update_rate_hz, uart_baud=RADIO_BAUD, fov_deg=u.pdoa_fov_deg,
                               ideal=opts.sensing == "faithful", queue_frames=u.radio_queue_frames,
                               nlos_fp_gap_db=u.nlos_fp_gap_db)
        self.counters = self.module.counters
        self.link: Any = None
        if opts.uwb_radio_pty:
            from bridge.hosts.firmware import PtyLink

            self.link = PtyLink(opts.uwb_radio_pty, "uwb_radio_pty")

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        uart = b"".join(item[1] for item in inputs["in"] if item[0] == "uart")
        if self.link is not None:
            uart += self.link.read()
        events = [item[1] for item in inputs["in"] if item[0] == RADIO]
        res = self.module.step(t_ns, uart, events)
        out: list[list] = [[RADIO, a] for a in res.air]
        if res.uart_tx:
            if self.link is not None:
                self.link.write(res.uart_tx)
            else:
                out.append(["uart", RADIO, res.uart_tx, RADIO_BAUD])
        wake = self.module.next_wake()
        if self.link is not None:  # poll the pseudo-terminal every quantum
            wake = t_ns + 1 if wake is None else min(wake, t_ns + 1)
        return {"out": out, "wake": wake, "wom": ["uart", RADIO]}

    def close(self) -> None:
        if self.link is not None:
            self.link.close()


class ImuEntity:
    """The BNO055 as the firmware host runs it: it answers the host's requests (from its serial line, or from its
    pseudo-terminal) with the heading and accelerations its pins sense."""

    def __init__(self, rp: Any, cfg: Any) -> None:
        self.chip = Bno055(IMU_BAUD)
        self.counters = self.chip.counters
        self.link: Any = None
        if pty := RadioOptions.model_validate(rp.options).imu_pty:
            from bridge.hosts.firmware import PtyLink

            self.link = PtyLink(pty, "imu_pty")

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        uart = b"".join(item[1] for item in inputs["in"] if item[0] == "uart")
        if self.link is not None:
            uart += self.link.read()
        sens = inputs.get("sens") or {}
        tx = self.chip.step(t_ns, uart, sens.get("heading_rad"), sens.get("accel_mps2"), sens.get("gravity_mps2"))
        out: list[list] = []
        if tx and self.link is not None:
            self.link.write(tx)
        elif tx:
            out.append(["uart", IMU, tx, IMU_BAUD])
        wake = self.chip.next_wake()
        if self.link is not None:  # poll the pseudo-terminal every quantum
            wake = t_ns + 1 if wake is None else min(wake, t_ns + 1)
        return {"out": out, "wake": wake, "wom": ["uart"]}

    def close(self) -> None:
        if self.link is not None:
            self.link.close()


def radio_modules(rp: Any, cfg: Any) -> dict[str, Any]:
    """Robot ``rp``'s radio and IMU entities."""
    return {RADIO: RadioEntity(rp, cfg), IMU: ImuEntity(rp, cfg)}


def radio_wiring(role: str) -> Any:
    """The IMU's wiring (its heading); the radio has no pins."""
    return ImuWiring() if role == IMU else None


def radio_hal(rp: Any, cfg: Any) -> dict[str, Any]:
    """The HAL tables of the robot program: the IMU first (the radio's driver sends its heading to the module), then
    the radio, each unless its UART is on a pseudo-terminal for a program outside the session."""
    opts = RadioOptions.model_validate(rp.options)
    hal: dict[str, Any] = {} if opts.imu_pty else {IMU: {"port": "sitl://imu", "baudrate": IMU_BAUD}}
    if not opts.uwb_radio_pty:
        hal[RADIO] = {"port": "sitl://uwb_radio", "baudrate": RADIO_BAUD}
    return hal
