"""``sitl://DEVICE``: a robot's simulated serial line to one of its modules (``sitl://xbee``, ``sitl://uwb``, a robot
model's own: ``RobotSpec.ports``), or
its MAVLink link to the ground stations (``sitl://mavlink``: the robot's face writes there; it is a network link,
so it has no baud rate: bytes leave at the end of the quantum).

``sitl://xbee?device=/dev/ttyUSB0`` is a real module on a real serial port, used by a robot in a session: bytes go
to and come from the device as they do, while reads wait in simulated time, polling the device every
``POLL_NS`` (a session with a real device runs paced to wall time, so this is about as often in wall time). A
device that fails or disappears raises ``SerialException`` in the robot program, which fails that robot.

A pyserial port like any other, so the swarm logic opens ``sitl://xbee`` in a session and
``/dev/ttyUSB0`` on the robot with the same code. Bytes written leave at the end of the current quantum and
reach the module as the line clocks them out at the port's baud rate (10 bits a byte); bytes from the module
arrive as it sends them. ``read`` with a timeout waits in simulated time. The baud rate is sent along with
the data: a host and a module that disagree on it garble each other's bytes, as real ones do.
"""

from __future__ import annotations

import numbers
import threading
import urllib.parse
from collections import deque

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException, to_bytes

from bridge.core.registry import ROBOTS
from bridge.hosts import sim_context

DEVICES = ("xbee", "uwb", "mavlink")


def model_ports() -> tuple[str, ...]:
    """The serial ports installed robot models give their own modules (``RobotSpec.ports``: a hexapod's
    ``uwb_radio``)."""
    return tuple(sorted({p for _, spec in ROBOTS.items() for p in spec.ports} - set(DEVICES)))

POLL_NS = 10_000_000  # how often a read waiting on a real device looks at it, in simulated time


class Serial(SerialBase):
    BAUDRATES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)

    def __init__(self, *args, **kwargs) -> None:
        self._rt: sim_context.RobotRuntime | None = None
        self._rx: deque | None = None
        self._buf = bytearray()
        self.device = ""
        self._real: SerialBase | None = None  # a real device behind this port (``?device=``)
        self._gone = False  # its module was unplugged: every use raises, as a disconnected USB device's does
        super().__init__(*args, **kwargs)

    # -- SerialBase ------------------------------------------------------------------------------------
    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        self.device, real = self._parse(self.port)
        try:
            self._rt = sim_context.current()
        except sim_context.NotInSession as e:
            raise SerialException(str(e)) from None
        if real is not None:
            self._real = serial.serial_for_url(real, baudrate=self._baudrate, timeout=0, exclusive=True)
            self.is_open = True
            return
        try:
            self._rx = self._rt.open_bus(f"uart:{self.device}")
        except OSError as e:
            raise SerialException(str(e)) from None
        self._reconfigure_port()
        self.is_open = True

    def close(self) -> None:
        if self.is_open and self._rt is not None and self._real is None:
            self._rt.close_bus(f"uart:{self.device}")
        if self._real is not None:
            self._real.close()
            self._real = None
        self.is_open = False
        self._rx = None
        self._buf.clear()

    def _reconfigure_port(self) -> None:
        if not isinstance(self._baudrate, numbers.Integral) or not 0 < self._baudrate < 2**32:
            raise ValueError(f"invalid baudrate: {self._baudrate!r}")
        if self.is_open and self._real is not None:
            self._real.baudrate = self._baudrate
        elif self.is_open and self._rt is not None:  # the line now samples the module's bytes at the new rate
            self._check()
            self._rt.outbox.append(["baud", self.device, int(self._baudrate)])

    @staticmethod
    def _parse(url: str) -> tuple[str, str | None]:
        """The device name and, for ``?device=PATH``, the real device's path or URL."""
        parts = urllib.parse.urlsplit(url)
        device = parts.netloc or parts.path.lstrip("/")
        query = urllib.parse.parse_qs(parts.query, strict_parsing=False) if parts.query else {}
        real = query.get("device", [None])[0]
        # the common devices without loading every installed robot model (each imports its boards' firmware)
        if (parts.scheme != "sitl" or (device not in DEVICES and device not in model_ports())
                or set(query) - {"device"} or (real is not None and device == "mavlink")):
            known = (*DEVICES, *model_ports())
            raise SerialException(f"expected sitl://DEVICE with DEVICE one of {', '.join(known)} (optionally "
                                  f"?device=PATH for a real module), got {url!r}")
        return device, real

    def _check(self) -> sim_context.RobotRuntime:
        if not self.is_open or self._rt is None:
            raise PortNotOpenError()
        if threading.current_thread() is not self._rt.thread:
            raise SerialException("a sitl:// port is used from its robot's own thread only (simulated time)")
        return self._rt

    def _pull(self) -> None:
        if self._real is not None:
            try:
                n = self._real.in_waiting
                if n:
                    self._buf += self._real.read(n)
            except (OSError, SerialException) as e:
                raise SerialException(f"{self._real.port}: the device failed or disappeared: {e}") from e
            return
        rx = self._rx
        while rx:
            data = rx.popleft()
            if data is None:  # the module was unplugged (an ``unplugged`` fault)
                self._gone = True
                break
            self._buf += data
        if self._gone:
            raise SerialException(f"sitl://{self.device}: device reports readiness to read but returned no data "
                                  "(device disconnected or multiple access on port?)")

    @property
    def in_waiting(self) -> int:
        self._check()
        self._pull()
        return len(self._buf)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes; blocks up to ``timeout`` simulated seconds (forever if None, not at all if 0)."""
        rt = self._check()
        timeout = self._timeout
        deadline = None if timeout is None else rt.t_ns + max(0, round(timeout * 1e9))
        while True:
            self._pull()
            if len(self._buf) >= size or (deadline is not None and rt.t_ns >= deadline):
                break
            if self._real is not None:  # nothing tells the session when a real device has bytes: look again soon
                rt.block(rt.t_ns + POLL_NS if deadline is None else min(deadline, rt.t_ns + POLL_NS), False)
            else:
                rt.block(deadline, f"uart:{self.device}")
        out = bytes(self._buf[:size])
        del self._buf[:size]
        return out

    def write(self, data) -> int:
        rt = self._check()
        data = to_bytes(data)
        if data and self._real is not None:
            try:
                return self._real.write(data) or 0
            except (OSError, SerialException) as e:
                raise SerialException(f"{self._real.port}: the device failed or disappeared: {e}") from e
        if data:
            self._pull()  # raises once the module is gone
            rt.outbox.append(["uart", self.device, bytes(data), int(self._baudrate)])
        return len(data)

    def flush(self) -> None:
        self._check()

    def reset_input_buffer(self) -> None:
        self._check()
        self._pull()
        self._buf.clear()

    def reset_output_buffer(self) -> None:
        self._check()

    @property
    def out_waiting(self) -> int:
        self._check()
        return 0

    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True
