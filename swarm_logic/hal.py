"""The devices a controller talks to, as protocols: one per device, several implementations.

``LlcClient`` (python-can, SITL or a real adapter) and the numerical runner's point robot both satisfy
``LowLevel``; ``swarm_logic.drivers.xbee.XBee`` (pyserial, SITL or a real module) and the numerical runner's link model
both satisfy ``Radio``. A controller written against these cannot tell which one drives it.
"""

from __future__ import annotations

from typing import Any, Protocol


class LowLevel(Protocol):
    """The robot's low-level controller: telemetry in ``state`` (``llc_client.LlcState`` fields), commands."""

    state: Any

    def poll(self) -> int: ...

    def drive(self, v: float, w: float) -> None: ...

    def move(self, rot_rad: float, dist_m: float, speed_mps: float) -> int:
        """Rotate in place by ``rot_rad``, then drive ``dist_m`` straight (the thesis' rotate-then-go)."""
        ...

    def stop(self) -> None: ...

    def set_led(self, r: int, g: int, b: int) -> None: ...

    def set_odometry(self, x: float, y: float, theta: float) -> None: ...


class Packet(Protocol):
    src64: int | None
    data: bytes
    rssi_dbm: int | float | None


class Radio(Protocol):
    """A packet radio with broadcast: the XBee driver's face."""

    def send_nowait(self, dest64: int | None, data: bytes, *, options: int = 0, radius: int = 0) -> int:
        """Hand ``data`` over for ``dest64`` (None: broadcast; ``radius`` hops, 0 the radio's default); the frame ID
        whose report ``tx_result`` gives."""
        ...

    def tx_result(self, frame_id: int) -> Any:
        """The delivery report (``.ok``) of a ``send_nowait`` once known (returned once), else None."""
        ...

    def recv(self, timeout: float | None = 0.0) -> Packet | None: ...

    def poll(self) -> None: ...
