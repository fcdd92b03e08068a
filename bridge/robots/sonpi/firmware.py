"""The SonPI's own firmware entities in a session, and what its robot program is given for them: the Arduino board
(``firmware_sim.robots.sonpi.sonar_board``) as an I2C slave at 0x20 on the robot's bus, and the HAL table
``sonpi_board`` that puts the Pi's driver on that simulated bus; or, with the group's ``i2c_pty``, a USB-ISS adapter
on the bus (``bridge.hil.usb_iss``) for a program outside the session instead of that table."""

from __future__ import annotations

from typing import Any

from bridge.core.registry import robot_profile
from bridge.core.rng import stream
from bridge.media.i2c import ADAPTER, SIM_URL
from bridge.models.differential_drive import DriveParams
from bridge.robots.sonpi.options import SonpiOptions
from bridge.robots.sonpi.wiring import ROLE
from firmware_sim.robots.sonpi.hcsr04 import RangerParams, Rangers
from firmware_sim.robots.sonpi.sonar_board import MotorParams, SonarBoard
from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi.interfaces import SONAR_ANGLES_RAD

I2C_HZ = 100_000  # the Pi's default i2c_arm_baudrate (standard mode)
MAX_SPEED_MPS = 0.2  # what the tracking layer follows at most (the motors make 0.3 m/s at full PWM)


def options(rp: Any) -> SonpiOptions:
    return SonpiOptions.model_validate(rp.options or {})


def roles(rp: Any) -> tuple[str, ...]:
    """The Arduino board's role, and the USB-ISS adapter's when the bus is exposed."""
    return (ROLE,) + ((ADAPTER,) if options(rp).i2c_pty else ())


def modules(rp: Any, cfg: Any) -> dict[str, Any]:
    """Robot ``rp``'s Arduino board with its group's firing mode, ranger errors and watchdog; and the adapter that
    exposes the bus."""
    o = options(rp)
    prof = robot_profile(rp.profile, rp.options)
    d = prof.part(DriveParams)
    rangers = Rangers(
        RangerParams(SONAR_ANGLES_RAD, prof.radius_m, o.sonar_noise_m, o.sonar_noise_rel, o.sonar_crosstalk)
    )
    motors = MotorParams(
        d.wheel_radius_m, d.encoder_cpr, d.motor_max_wheel_rad_s, d.motor_deadband_pwm, d.motor_time_constant_s
    )
    board = SonarBoard(
        rangers,
        motors,
        stream(cfg.session.seed, "robot", rp.id, "sonpi_rangers"),
        firing=P.FIRING_NAMES.index(o.sonar_firing),
        watchdog_ms=o.watchdog_ms,
        loop_hz=prof.llc_loop_hz,
    )
    out: dict[str, Any] = {ROLE: board}
    if o.i2c_pty:
        from bridge.hil.usb_iss import UsbIssEntity

        out[ADAPTER] = UsbIssEntity(rp.id, o.i2c_pty)
    return out


def hal(rp: Any, cfg: Any) -> dict[str, Any]:
    """The robot program's ``sonpi_board`` device on the simulated bus, with the robot's geometry (none when the bus
    is a program's outside the session)."""
    if options(rp).i2c_pty:
        return {}
    d = robot_profile(rp.profile, rp.options).part(DriveParams)
    return {
        "sonpi_board": {
            "bus": SIM_URL,
            "scl_hz": I2C_HZ,
            "wheel_radius_m": d.wheel_radius_m,
            "half_track_m": d.half_track_m,
            "encoder_cpr": d.encoder_cpr,
            "max_speed_mps": MAX_SPEED_MPS,
        }
    }
