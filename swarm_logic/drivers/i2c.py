"""The robot's I2C bus as an ``smbus2.SMBus``: ``1`` (or ``/dev/i2c-1``) is the real bus on the robot's computer; a URL
``SCHEME://...`` is a bus another package offers under that scheme (entry point group ``swarm_sitl.i2c``, as
python-can finds its interfaces), such as ``sitl://i2c``, a robot's simulated bus in a session. The robot code is the
same either way."""

from __future__ import annotations

from typing import Any

from swarm_logic.plugins import Registry

I2C_BUSES: Registry[Any] = Registry("swarm_sitl.i2c", "I2C bus", callable)


def open_smbus(bus: int | str, **options: Any) -> Any:
    """An open ``smbus2.SMBus`` on ``bus``: an adapter number or device path (the real one: ``options`` such as the
    bus speed are the boot configuration's there, and ignored), or ``SCHEME://...`` of a registered bus class, which
    gets ``options``."""
    if isinstance(bus, str) and "://" in bus:
        cls = I2C_BUSES.get(bus.split("://", 1)[0])
        return cls(bus, **options)
    if isinstance(bus, bool) or not isinstance(bus, int | str):
        raise ValueError(f"an I2C bus is an adapter number, a device path or a URL, got {bus!r}")
    import smbus2

    return smbus2.SMBus(bus)
