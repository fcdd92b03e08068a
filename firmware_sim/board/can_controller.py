"""A stand-alone CAN controller (MCP2515 class) with an interrupt-driven receive ring in the driver.

Frames that arrive while the ring is full are dropped and counted, as the real driver would; frames with
a data length the controller cannot hold are counted as errors. Transmit frames wait in ``tx`` until the
host hands them to the bus.

The bus's fault confinement reaches the firmware as the controller's error flag register (EFLG): the
transmit and receive error counters, error-passive and bus-off. While bus-off the controller neither sends
nor receives (a write is dropped and counted); the MCP2515 recovers by itself once the bus allows it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Frame:
    arbitration_id: int
    data: bytes
    timestamp_us: int = 0
    is_extended_id: bool = False


class CanController:
    MAX_DLC = 8

    def __init__(self, rx_depth: int = 8) -> None:
        self.rx_depth = rx_depth
        self.rx: deque[Frame] = deque()
        self.tx: list[Frame] = []
        self.rx_overflows = 0
        self.rx_errors = 0
        self.rx_frames = 0
        self.tx_frames = 0
        self.state = "active"  # "active", "passive" or "bus_off" (EFLG: TXEP/RXEP, TXBO)
        self.tec = 0
        self.rec = 0
        self.bus_off_events = 0
        self.tx_dropped_bus_off = 0

    def set_error_state(self, state: str, tec: int, rec: int) -> None:
        """Called by the host when the bus changed this node's fault-confinement state."""
        if state == "bus_off" and self.state != "bus_off":
            self.bus_off_events += 1
            self.tx.clear()  # the transmit buffers are aborted
        self.state, self.tec, self.rec = state, tec, rec

    @property
    def bus_off(self) -> bool:
        return self.state == "bus_off"

    def on_bus_frame(self, frame: Frame) -> None:
        """Called by the host for every frame the bus delivers to this node."""
        if len(frame.data) > self.MAX_DLC:
            self.rx_errors += 1
            return
        if len(self.rx) >= self.rx_depth:
            self.rx_overflows += 1
            return
        self.rx_frames += 1
        self.rx.append(frame)

    # -- driver API used by the sketch --------------------------------------------------------------
    def available(self) -> bool:
        return bool(self.rx)

    def read(self) -> Frame | None:
        return self.rx.popleft() if self.rx else None

    def write(self, arbitration_id: int, data: bytes, timestamp_us: int = 0) -> None:
        if len(data) > self.MAX_DLC:
            raise ValueError(f"classic CAN frame holds at most 8 bytes, got {len(data)}")
        if self.bus_off:
            self.tx_dropped_bus_off += 1
            return
        self.tx_frames += 1
        self.tx.append(Frame(arbitration_id, bytes(data), timestamp_us))

    def take_tx(self) -> list[Frame]:
        out, self.tx = self.tx, []
        return out
