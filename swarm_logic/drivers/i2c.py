"""The robot's I2C bus as an ``smbus2.SMBus``: ``1`` (or ``/dev/i2c-1``) is the real bus on the robot's computer; a URL
``SCHEME://...`` is a bus another package offers under that scheme (entry point group ``swarm_sitl.i2c``, as
python-can finds its interfaces), such as ``sitl://i2c``, a robot's simulated bus in a session. The robot code is the
same either way."""

from __future__ import annotations

import ctypes
import errno
import os
from typing import Any

from smbus2 import SMBus

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
    return SMBus(bus)


Message = tuple[int, bool, "bytes | int"]  # one I2C message: address, read?, the bytes written or the count read
BLOCK_MAX = 32  # I2C_SMBUS_BLOCK_MAX
I2C_M_RD, I2C_M_TEN = 0x0001, 0x0010


class PlainI2cSMBus(SMBus):
    """An ``smbus2.SMBus`` over an adapter that does plain I2C transactions only, with the SMBus calls as the Linux
    kernel emulates them there (``i2c-core-smbus``): every call is one transaction (a register read is a write, a
    repeated START, a read). A subclass opens its adapter (``open``/``close``, setting ``fd`` and ``funcs``) and
    carries one transaction in ``_transfer(msgs) -> the bytes each read got``, raising smbus2's ``OSError``s. SMBus
    block reads (a count byte first) and PEC are refused, as such adapters refuse them."""

    def enable_pec(self, enable: bool = True) -> None:
        raise OSError("SMBUS_PEC is not a feature")

    def _set_address(self, address: int, force: bool | None = None) -> None:
        self.address = address
        self._force_last = force if force is not None else self.force

    def _transfer(self, msgs: list[Message]) -> list[bytes]:
        raise NotImplementedError

    def _write(self, addr: int, data: bytes) -> None:
        self._transfer([(addr, False, bytes(data))])

    def _write_read(self, addr: int, data: bytes, n: int) -> bytes:
        return self._transfer([(addr, False, bytes(data)), (addr, True, n)])[0]

    def write_quick(self, i2c_addr: int, force: bool | None = None) -> None:
        self._set_address(i2c_addr, force)
        self._write(i2c_addr, b"")

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int:
        self._set_address(i2c_addr, force)
        return self._transfer([(i2c_addr, True, 1)])[0][0]

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None:
        self._set_address(i2c_addr, force)
        self._write(i2c_addr, bytes([value & 0xFF]))

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        self._set_address(i2c_addr, force)
        return self._write_read(i2c_addr, bytes([register & 0xFF]), 1)[0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int, force: bool | None = None) -> None:
        self._set_address(i2c_addr, force)
        self._write(i2c_addr, bytes([register & 0xFF, value & 0xFF]))

    def read_word_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        """SMBus words are little-endian (low byte first)."""
        self._set_address(i2c_addr, force)
        return int.from_bytes(self._write_read(i2c_addr, bytes([register & 0xFF]), 2), "little")

    def write_word_data(self, i2c_addr: int, register: int, value: int, force: bool | None = None) -> None:
        self._set_address(i2c_addr, force)
        self._write(i2c_addr, bytes([register & 0xFF]) + (value & 0xFFFF).to_bytes(2, "little"))

    def process_call(self, i2c_addr: int, register: int, value: int, force: bool | None = None) -> int:
        self._set_address(i2c_addr, force)
        out = bytes([register & 0xFF]) + (value & 0xFFFF).to_bytes(2, "little")
        return int.from_bytes(self._write_read(i2c_addr, out, 2), "little")

    def read_block_data(self, i2c_addr: int, register: int, force: bool | None = None) -> list[int]:
        raise OSError(errno.EOPNOTSUPP, os.strerror(errno.EOPNOTSUPP))  # needs a count byte read first

    def block_process_call(self, i2c_addr: int, register: int, data: Any, force: bool | None = None) -> list[int]:
        raise OSError(errno.EOPNOTSUPP, os.strerror(errno.EOPNOTSUPP))

    def write_block_data(self, i2c_addr: int, register: int, data: Any, force: bool | None = None) -> None:
        """SMBus block write: the register, a count byte, the data."""
        data = bytes(data)
        if len(data) > BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {BLOCK_MAX} bytes")
        self._set_address(i2c_addr, force)
        self._write(i2c_addr, bytes([register & 0xFF, len(data)]) + data)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int, force: bool | None = None) -> list[int]:
        if length > BLOCK_MAX:
            raise ValueError(f"Desired block length over {BLOCK_MAX} bytes")
        self._set_address(i2c_addr, force)
        return list(self._write_read(i2c_addr, bytes([register & 0xFF]), length))

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Any, force: bool | None = None) -> None:
        data = bytes(data)
        if len(data) > BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {BLOCK_MAX} bytes")
        self._set_address(i2c_addr, force)
        self._write(i2c_addr, bytes([register & 0xFF]) + data)

    def i2c_rdwr(self, *i2c_msgs: Any) -> None:
        """One combined transaction (repeated STARTs, one STOP); read messages' buffers are filled in place."""
        msgs: list[Message] = []
        for m in i2c_msgs:
            if m.flags & I2C_M_TEN:
                raise OSError(errno.EINVAL, os.strerror(errno.EINVAL))  # 7-bit addresses only
            read = bool(m.flags & I2C_M_RD)
            msgs.append((int(m.addr), read, int(m.len) if read else bytes(m)))
        reads = iter(self._transfer(msgs))
        for m in i2c_msgs:
            if m.flags & I2C_M_RD:
                data = next(reads)
                ctypes.memmove(m.buf, data, min(len(data), m.len))
