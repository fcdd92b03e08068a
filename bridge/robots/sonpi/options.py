"""A SonPI group's options in a session config: the sonar board's firing mode and ranger errors, its motor
watchdog, the colour of the marker the overhead camera finds it by, and the bus on a pseudo-terminal."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

Byte = Annotated[int, Field(ge=0, le=255)]


class SonpiOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    sonar_firing: Literal["sequential", "simultaneous", "ideal"] = Field(
        "sequential",
        description="how the board fires its five HC-SR04s: sequential, one per 60 ms slot (3.3 Hz "
        "each, no cross-talk); simultaneous, all five per 60 ms slot (a sensor may take a "
        "neighbour's echo); ideal, all five every 5 ms without cross-talk (the thesis' 200 "
        "Hz per sensor). The Pi may change it (register FIRING)",
    )
    sonar_noise_m: float = Field(
        0.003, ge=0, le=0.5, description="per-ping range noise, 1 sigma (m): the datasheet's 3 mm accuracy"
    )
    sonar_noise_rel: float = Field(
        0.0, ge=0, le=0.5, description="per-ping range noise growing with the range (1 sigma, relative)"
    )
    sonar_crosstalk: float = Field(
        0.3,
        ge=0,
        le=1,
        description="simultaneous firing: the probability that a "
        "neighbour's echo, arriving first, ends a sensor's "
        "pulse",
    )
    watchdog_ms: int = Field(
        500,
        ge=0,
        le=2550,
        multiple_of=10,
        description="the motors stop when no set-point came for this long (0: never)",
    )
    marker_rgb: tuple[Byte, Byte, Byte] = Field(
        (255, 64, 0), description="the top marker's colour, for the overhead camera"
    )
    i2c_pty: str | None = Field(
        None,
        description="expose the robot's I2C bus (its Arduino board) on a pseudo-terminal as a Devantech USB-ISS "
        "USB-to-I2C adapter, linked at this path (relative to the session's output directory; '{id}' "
        "is replaced by the robot id): swarm_logic's usb-iss:// bus opens it; the robot's own "
        "program then does not open its bus",
    )
