"""The DeciZebro (TU Delft; Agrawal 2019, appendix B): an A4-sized hexapod with six C-shaped legs, RHex-style, each
driven by its own ZebroBus leg module on the robot's I2C bus, a Raspberry Pi Zero W as main computer, and a DWM1001
UWB radio that ranges and carries messages.

Figures (``docs/zebro.md``): 268 x 210 x 160 mm, 1.8 kg, leg radius 50 mm, six 170 rpm 12 V motors, walking 1-2 km/h
(0.28-0.56 m/s) forward, battery 14.4 V 4000 mAh for about 3 h of walking, a front ultrasound of about one body
length. The body is a box; walking emerges from the legs' phases, in one of two body models a robot group chooses
(``body``): the gait-level one imposes the body's motion from the legs in stance (``legs.py``, the default), the
contact-level one puts the box on six jointed C-legs whose motors push it along the floor (``contact_legs.py``).
"""

from __future__ import annotations

import math
from typing import Any

from bridge.core.profile import RobotProfile
from bridge.core.registry import RobotSpec
from bridge.models.sonar import SonarParams
from bridge.robots.decizebro import firmware, radio, utility
from bridge.robots.decizebro.imu import ImuParams
from bridge.robots.decizebro.legs import LegsParams
from bridge.robots.decizebro.utility import UtilityParams
from bridge.robots.decizebro.wiring import LEG_WIRING

DECIZEBRO = RobotProfile(
    name="decizebro",
    radius_m=0.171,  # half the footprint's diagonal: placements keep robots this far apart
    length_m=0.268,
    width_m=0.210,
    height_m=0.160,
    mass_kg=1.8,
    battery_capacity_mah=4000.0,  # 14.4 V, 4000 mAh (appendix B.7)
    battery_cells=4,
    battery_internal_ohm=0.08,
    current_idle_ma=250.0,  # the Pi Zero W, the radio and the leg modules' logic (assumed)
    llc_loop_hz=100.0,  # the leg modules' control loop (assumed)
    parts=(
        LegsParams(
            leg_radius_m=0.05,  # appendix B.4
            track_m=0.21,  # the body's width: the legs sit at its sides
            max_rad_s=170 * 2 * math.pi / 60,  # 170 rpm at 12 V (appendix B.3)
            nominal_v=12.0,
            time_constant_s=0.08,  # assumed
            stance_half_rad=1.6,  # a leg is on the ground a little over half its turn (double support; assumed)
            traction_spread=0.03,  # assumed
            # 3 h of walking from 4 Ah is about 1.3 A in all; a leg at full duty draws 0.35 A walking (assumed;
            # stall is 3.8 A)
            current_per_leg_ma=350.0,
        ),
        SonarParams(  # the front ultrasound: "myopic", about one body length (section 2.2.1)
            max_range_m=0.30,
            min_range_m=0.02,
            half_beam_deg=15.0,
            rays=5,
            rate_hz=10.0,
            noise_m=0.005,
            noise_rel=0.01,
            outlier_p=0.02,
        ),
        UtilityParams(cone_deg=60.0, range_m=3 * 0.268),  # 60 degrees, three body lengths (section 4.2.1)
        ImuParams(),  # the BNO055's fused heading (imu.py)
    ),
)

NO_LLC = "a decizebro has no LLC on CAN: its legs are ZebroBus modules on I2C"
def _roles(rp: Any) -> tuple[str, ...]:
    """Its firmware entities: the six leg modules on the I2C bus, the UWB radio, the IMU, the utility sensor board."""
    return (*firmware.roles(rp), *radio.RADIO_ROLES, utility.UTILITY)


def _modules(rp: Any, cfg: Any) -> dict[str, Any]:
    return {**firmware.modules(rp, cfg), **radio.radio_modules(rp, cfg),
            utility.UTILITY: utility.UtilityEntity(rp, cfg)}


def _wiring(role: str) -> Any:
    if role == utility.UTILITY:
        return utility.UtilityWiring()
    return LEG_WIRING(role) or radio.radio_wiring(role)


def _hal(rp: Any, cfg: Any) -> dict[str, Any]:
    return {**firmware.hal(rp, cfg), **radio.radio_hal(rp, cfg), **utility.utility_hal(rp, cfg)}


# a program outside the session is the robot's logic through these (hil_configs/robots/decizebro_sitl_ports.toml)
EXTERNAL_PORTS = {
    "i2c_pty": "an external logic walks the robot through its leg modules on the I2C bus: expose it, e.g. "
               "i2c_pty = \"r{id}-i2c\" (a USB-ISS adapter: usb-iss://PATH)",
    "uwb_radio_pty": "an external logic reaches the robot's UWB radio through its UART: expose it, e.g. "
                     "uwb_radio_pty = \"r{id}-uwb\"",
    "imu_pty": "an external logic reads the robot's heading from its IMU's UART: expose it, e.g. "
               "imu_pty = \"r{id}-imu\"",
    "utility_pty": "an external logic reads the utility sensor board's serial line: expose it, e.g. "
                   "utility_pty = \"r{id}-utility\"",
}

SPEC = RobotSpec(
    "decizebro", DECIZEBRO, title="DeciZebro: hexapod, six ZebroBus leg modules on I2C, DWM1001 UWB radio",
    roles=_roles, modules=_modules, wiring=_wiring, hal=_hal,
    ports={**radio.RADIO_PORTS, **utility.UTILITY_PORTS}, options=radio.RadioOptions, configure=radio.radio_configure,
    refuses={"xbee": "a decizebro has no XBee: its radio is the DWM1001 UWB module, which carries its messages",
             "uwb": "a decizebro always has its DWM1001 UWB radio; the eSwarBot's ranging-only module does not fit",
             "can": NO_LLC, "vehicle": NO_LLC,
             "pose_source": "a decizebro has no LLC to report a pose (no odometry on legs, thesis section 1.1)"},
    external_ports=EXTERNAL_PORTS)
