"""``sitl://i2c``: a robot's simulated I2C bus as an ``smbus2.SMBus``, for the robot program's thread in a session.

The swarm logic opens its bus by name (``swarm_logic.drivers.i2c.open_smbus``): ``1`` is ``smbus2.SMBus(1)`` on the
robot (``/dev/i2c-1``), ``"sitl://i2c"`` this class in a session (entry point group ``swarm_sitl.i2c``, name
``sitl``). What smbus2 users call works as it does on a Raspberry Pi, whose ``i2c-bcm2835`` adapter is plain I2C with
the kernel's SMBus emulation: every call is one I2C transaction (``i2c_rdwr`` as given; ``read_i2c_block_data`` a
write of the register then a read after a repeated START; ``write_i2c_block_data`` one write), sent on the session's
I2C medium (``bridge.media.i2c``) and timed there at ``scl_hz``. The call blocks in simulated time until the
transaction has ended; an address nobody ACKs raises ``OSError(EREMOTEIO)`` as the driver does, a transaction the
adapter refuses ``OSError(EINVAL)``, one that gets no answer within the adapter's 1 s ``OSError(ETIMEDOUT)``. SMBus
block reads (a count byte first) and PEC are not offered, as that adapter does not offer them.
"""

from __future__ import annotations

import itertools
import os
import threading
import weakref
from collections import deque
from collections.abc import Iterator
from typing import Any

from smbus2 import I2cFunc, i2c_msg

from bridge.hosts import sim_context
from bridge.media.i2c import EINVAL, EREMOTEIO, ETIMEDOUT, SIM_URL, check_transaction
from swarm_logic.drivers.i2c import Message, PlainI2cSMBus

ADAPTER_TIMEOUT_NS = 1_000_000_000  # i2c-bcm2835 gives up on a transaction after 1 s
EBADF = 9
FUNCS = I2cFunc.I2C | (I2cFunc.SMBUS_EMUL & ~I2cFunc.SMBUS_PEC)  # what i2c-bcm2835 offers, less PEC

# per robot: how many SMBus objects have its bus open, and its transactions' numbers (each robot counts its own, so
# the recording does not depend on which robots share a process)
_users: weakref.WeakKeyDictionary[sim_context.RobotRuntime, int] = weakref.WeakKeyDictionary()
_seqs: weakref.WeakKeyDictionary[sim_context.RobotRuntime, Iterator[int]] = weakref.WeakKeyDictionary()


def _error(code: int) -> OSError:
    return OSError(code, os.strerror(code))


class SMBus(PlainI2cSMBus):
    """``SMBus("sitl://i2c", scl_hz=100_000)``: the robot's simulated bus (``scl_hz`` stands for the Pi's
    ``i2c_arm_baudrate`` boot setting: 100 kHz by default, 400 kHz fast mode)."""

    def __init__(self, bus: Any = None, force: bool = False, *, scl_hz: int = 100_000) -> None:
        self.scl_hz = int(scl_hz)
        self._rt: sim_context.RobotRuntime | None = None
        self._rx: deque | None = None
        super().__init__(bus, force)

    # -- opening and closing ----------------------------------------------------------------------------------
    def open(self, bus: Any) -> None:
        if bus != SIM_URL:
            raise TypeError(f"the simulated I2C bus is {SIM_URL!r}, got {bus!r} (a real bus: smbus2.SMBus(1))")
        if self._rt is not None:
            self.close()
        try:
            rt = sim_context.current()
        except sim_context.NotInSession as e:
            raise FileNotFoundError(2, f"{SIM_URL}: {e}") from None
        rx = rt.rx.get("i2c")
        if rx is None:  # several SMBus objects of one robot share its bus, as several opens of /dev/i2c-1 do
            rx = rt.open_bus("i2c")
        _users[rt] = _users.get(rt, 0) + 1
        self._rt, self._rx = rt, rx
        self.fd = -1  # open (smbus2 looks at fd)
        self.funcs = FUNCS

    def close(self) -> None:
        rt = self._rt
        if rt is not None:
            left = _users.get(rt, 1) - 1
            if left <= 0:
                _users.pop(rt, None)
                rt.close_bus("i2c")
            else:
                _users[rt] = left
        self._rt = self._rx = None
        self.fd = None
        self.address = None
        self._force_last = None

    # -- one transaction ---------------------------------------------------------------------------------------
    def _transfer(self, msgs: list[Message]) -> list[bytes]:
        """Send one transaction and wait in simulated time for its end; the bytes its reads got."""
        rt, rx = self._rt, self._rx
        if rt is None or rx is None:
            raise _error(EBADF)
        if threading.current_thread() is not rt.thread:
            raise RuntimeError("a sitl I2C bus is used from its robot's own thread only (simulated time)")
        try:
            check_transaction(msgs, self.scl_hz)
        except (ValueError, TypeError):
            raise _error(EINVAL) from None
        seq = next(_seqs.setdefault(rt, itertools.count(1)))
        rt.outbox.append(["i2c", seq, [list(m) for m in msgs], self.scl_hz])
        deadline = rt.t_ns + ADAPTER_TIMEOUT_NS
        while True:
            while rx:
                got = rx.popleft()
                if isinstance(got, list | tuple) and len(got) == 4 and got[0] == seq:
                    _, errno_, reads, _end = got
                    if errno_:
                        raise _error(int(errno_))
                    return [bytes(b) for b in reads]
                # a late answer to a transaction this bus gave up on: dropped
            if rt.t_ns >= deadline:
                raise _error(ETIMEDOUT)
            rt.block(deadline, "i2c")


__all__ = ["EREMOTEIO", "ETIMEDOUT", "SMBus", "i2c_msg"]
