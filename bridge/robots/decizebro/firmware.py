"""The DeciZebro's own firmware entities in a session, and what its robot program is given for them: six ZebroBus
leg modules (``firmware_sim.robots.decizebro.leg_module``) as I2C slaves at 0x10-0x15 on the robot's bus, and the
HAL table ``legs`` that puts the program's locomotion layer on that simulated bus."""

from __future__ import annotations

from typing import Any

from bridge.core.registry import robot_profile
from bridge.media.i2c import SIM_URL
from firmware_sim.robots.decizebro.leg_module import LegModule

LEG_ROLES = tuple(f"leg{i}" for i in range(6))  # 0-2 left front to back, 3-5 right front to back
I2C_HZ = 100_000  # the Pi's default i2c_arm_baudrate (standard mode); 400 kHz is fast mode


def roles(rp: Any) -> tuple[str, ...]:
    """The leg modules' roles."""
    return LEG_ROLES


def modules(rp: Any, cfg: Any) -> dict[str, Any]:
    """The six leg modules of robot ``rp``, each with a serial id of its own, looping at the profile's rate."""
    hz = robot_profile(rp.profile, rp.options).llc_loop_hz
    return {role: LegModule(i, serial_id=(rp.id * 6 + i) % 255 + 1, loop_hz=hz) for i, role in enumerate(LEG_ROLES)}


def hal(rp: Any, cfg: Any) -> dict[str, Any]:
    """The robot program's ``legs`` device: the locomotion layer on the simulated I2C bus."""
    return {"legs": {"bus": SIM_URL, "scl_hz": I2C_HZ}}
