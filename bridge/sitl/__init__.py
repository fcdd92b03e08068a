"""pyserial URL handlers of the session: ``serial.serial_for_url("sitl://xbee")`` in a SITL robot program.

pyserial finds a handler for scheme ``X`` as module ``protocol_X`` in the packages listed in
``serial.protocol_handler_packages``; ``register()`` adds this package (the logic host does it at start-up).
"""

from __future__ import annotations

import serial

PACKAGE = __name__


def register() -> None:
    if PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(PACKAGE)
