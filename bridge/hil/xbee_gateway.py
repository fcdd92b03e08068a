"""An XBee gateway: a real XBee on this machine joined to the simulated radio channel.

A real radio cannot be put inside the simulation, so the gateway is built as one would build it from parts: a
simulated XBee module at a stated pose in the arena (the firmware host runs it like a robot's), wired back to
back through a relay to the real module on a serial port. The relay reads both with the swarm logic's own XBee
driver (``swarm_logic.drivers.xbee``): every packet the simulated module receives is sent by the real one (to ``peer``,
or broadcast), and every packet the real one receives is broadcast by the simulated one. So a program on the
desk with its own XBee hears the swarm, and the swarm hears it, at the gateway's pose.

What this cannot do, by construction: the desk radio sees every swarm packet coming from the real module's
address (and the swarm sees the desk's from the simulated module's); the RSSI the desk radio measures is that of
the real link on the desk, not the simulated distance; packets cross in both directions as broadcasts unless
``peer`` names the desk radio.

The relay is the link of the simulated module's UART (``read``/``write``, as ``firmware_host.PtyLink``), polled
once per quantum; a real device that fails or disappears raises ``GatewayError`` and the gateway fails.
"""

from __future__ import annotations

from typing import Any

import serial

from swarm_logic.clock import SteppedClock
from swarm_logic.drivers.xbee import XBee

TWIN_API_MODE = 1  # the simulated module's UART, internal to the gateway (bridge.core.plan sets it up so)
RESULTS_KEPT = 64  # transmit requests whose status is still counted


class GatewayError(RuntimeError):
    """The real module of a gateway failed or disappeared."""


class _TwinLine:
    """The wires between the relay and the simulated module's UART, as a pyserial-like port for the driver."""

    def __init__(self) -> None:
        self.from_module = bytearray()
        self.to_module = bytearray()
        self.timeout: float | None = 0

    @property
    def in_waiting(self) -> int:
        return len(self.from_module)

    def read(self, size: int = 1) -> bytes:
        out = bytes(self.from_module[:size])
        del self.from_module[:size]
        return out

    def write(self, data: bytes) -> int:
        self.to_module += data
        return len(data)


class _RealLine:
    """The real module's serial port; any failure is the device's, named."""

    def __init__(self, device: str, baud: int) -> None:
        self.device = device
        try:
            self.port = serial.serial_for_url(device, baudrate=baud, timeout=0, exclusive=True)
        except (OSError, serial.SerialException, ValueError) as e:
            raise GatewayError(f"{device}: cannot open the gateway's XBee: {e}") from None

    def _failed(self, e: Exception) -> GatewayError:
        return GatewayError(f"{self.device}: the gateway's XBee failed or disappeared: {e}")

    @property
    def timeout(self) -> float | None:
        return self.port.timeout

    @timeout.setter
    def timeout(self, t: float | None) -> None:
        self.port.timeout = t

    @property
    def in_waiting(self) -> int:
        try:
            return self.port.in_waiting
        except (OSError, serial.SerialException) as e:
            raise self._failed(e) from e

    def read(self, size: int = 1) -> bytes:
        try:
            return self.port.read(size)
        except (OSError, serial.SerialException) as e:
            raise self._failed(e) from e

    def write(self, data: bytes) -> int:
        try:
            return self.port.write(data) or 0
        except (OSError, serial.SerialException) as e:
            raise self._failed(e) from e

    def close(self) -> None:
        self.port.close()


class XBeeGateway:
    """The relay between a simulated module (its UART: ``write`` what it sent, ``read`` what to give it) and a
    real module on ``gw["device"]`` (``config.XBeeGatewayCfg`` as a dict)."""

    def __init__(self, gw: dict[str, Any]) -> None:
        self.clock = SteppedClock("the gateway relay is polled once per quantum; it never waits")
        self.twin_line = _TwinLine()
        self.real_line = _RealLine(gw["device"], gw["baud"])
        series = gw["series"]
        self.twin = XBee(self.twin_line, self.clock, api_mode=TWIN_API_MODE, series=series)
        self.real = XBee(self.real_line, self.clock, api_mode=gw["api_mode"], series=series)
        self.peer = int(gw["peer"], 16) if gw.get("peer") else None
        self.counters = {"to_air": 0, "to_swarm": 0, "to_air_ok": 0, "to_air_failed": 0, "to_swarm_ok": 0,
                         "to_swarm_failed": 0}
        self._sent: dict[str, list[int]] = {"to_air": [], "to_swarm": []}  # frame ids awaiting their status

    def set_time(self, t_ns: int) -> None:
        self.clock.t = t_ns / 1e9

    def write(self, data: bytes) -> None:
        """Bytes the simulated module sent on its UART."""
        self.twin_line.from_module += data
        self._relay()

    def read(self) -> bytes:
        """Bytes for the simulated module's UART: transmit requests for what the real module heard."""
        self._relay()
        out = bytes(self.twin_line.to_module)
        self.twin_line.to_module.clear()
        return out

    def _relay(self) -> None:
        while (p := self.twin.recv(0)) is not None:
            self._sent["to_air"].append(self.real.send_nowait(self.peer, p.data))
            self.counters["to_air"] += 1
        while (p := self.real.recv(0)) is not None:
            self._sent["to_swarm"].append(self.twin.send_nowait(None, p.data))
            self.counters["to_swarm"] += 1
        for way, drv in (("to_air", self.real), ("to_swarm", self.twin)):
            waiting = []
            for fid in self._sent[way]:
                st = drv.tx_result(fid)
                if st is None:
                    waiting.append(fid)
                else:
                    self.counters[f"{way}_{'ok' if st.ok else 'failed'}"] += 1
            self._sent[way] = waiting[-RESULTS_KEPT:]

    def stats(self) -> dict[str, Any]:
        """What crossed, and each side's driver counters (malformed frames, checksum errors, ...)."""
        return {**self.counters, "real_module": dict(self.real.counters), "twin_module": dict(self.twin.counters)}

    def close(self) -> None:
        self.real_line.close()
