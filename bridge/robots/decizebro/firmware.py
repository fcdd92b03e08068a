"""The DeciZebro's own firmware entities in a session, and what its robot program is given for them: six ZebroBus
leg modules (``firmware_sim.robots.decizebro.leg_module``) as I2C slaves at 0x10-0x15 on the robot's bus, and the
HAL table ``legs`` that puts the program's locomotion layer on that simulated bus; or, with the group's ``i2c_pty``,
a USB-ISS adapter on the bus (``bridge.hil.usb_iss``) for a program outside the session instead of that table."""

from __future__ import annotations

from typing import Any

from bridge.core.registry import robot_profile
from bridge.media.i2c import ADAPTER, SIM_URL
from firmware_sim.robots.decizebro.leg_module import LegModule

LEG_ROLES = tuple(f"leg{i}" for i in range(6))  # 0-2 left front to back, 3-5 right front to back
I2C_HZ = 100_000  # the Pi's default i2c_arm_baudrate (standard mode); 400 kHz is fast mode


def _i2c_pty(rp: Any) -> str | None:
    """The group's ``i2c_pty`` (a ``RadioOptions`` field), if it exposes the bus."""
    pty = (rp.options or {}).get("i2c_pty")
    return pty if isinstance(pty, str) and pty else None


def roles(rp: Any) -> tuple[str, ...]:
    """The leg modules' roles, and the USB-ISS adapter's when the bus is exposed."""
    return LEG_ROLES + ((ADAPTER,) if _i2c_pty(rp) else ())


def modules(rp: Any, cfg: Any) -> dict[str, Any]:
    """The six leg modules of robot ``rp``, each with a serial id of its own, looping at the profile's rate; and the
    adapter that exposes the bus."""
    hz = robot_profile(rp.profile, rp.options).llc_loop_hz
    out: dict[str, Any] = {role: LegModule(i, serial_id=(rp.id * 6 + i) % 255 + 1, loop_hz=hz)
                           for i, role in enumerate(LEG_ROLES)}
    if pty := _i2c_pty(rp):
        from bridge.hil.usb_iss import UsbIssEntity

        out[ADAPTER] = UsbIssEntity(rp.id, pty)
    return out


def hal(rp: Any, cfg: Any) -> dict[str, Any]:
    """The robot program's ``legs`` device: the locomotion layer on the simulated I2C bus (none when the bus is a
    program's outside the session)."""
    return {} if _i2c_pty(rp) else {"legs": {"bus": SIM_URL, "scl_hz": I2C_HZ}}
