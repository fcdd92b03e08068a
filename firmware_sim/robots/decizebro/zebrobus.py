"""ZebroBus v1 (P. De Vaere, D. Booms, TU Delft 2016-2017): the register map a DeciZebro leg module answers on its I2C
bus, and the slave side of the bus every ZebroBus module shares.

A module has 256 one-byte virtual registers ("vregs"). A write transaction's first byte sets the register pointer;
each further byte is written at the pointer, which then increments (wrapping at 0xFF); a read returns bytes from the
pointer on, incrementing it; after the STOP the pointer goes back to the last register address written. Multi-byte
values are big-endian (left aligned). Bus addresses 0x00-0x0F are multicast (0x00, the I2C general call, reaches
every leg; reads there are refused), 0x10-0x6F devices, 0x70-0x7F reserved.

The register map chosen here (the sources disagree: the spec's table has a hex and a decimal column that differ by
one from 0x10 on; the DeciZebro firmware has no class id, so its 0x01-0x05 are shifted; our choice and why):

======  =====================  =====  ====================================================================
 addr    field                  r/w    notes
======  =====================  =====  ====================================================================
 0x00    ZebroBus version       r      1
 0x01    class id               r      1 = leg module (the spec's table; the firmware lacks it)
 0x02    product id             r      1
 0x03    product version        r      1
 0x04    serial id              r/w*   guarded: write 0x1B, then the new value (two transactions)
 0x05    software version       r      1
 0x06    ZebroBus address       r      own 7-bit bus address, 0x10 + leg position
 0x11    quick status           r      bit 0 emergency stop, 1 moving, 2 timing (a sync within 2 s),
                                       3 an error is recorded, 4 at the target (within 3 degrees)
 0x12    sync counter           r/w    written by the controller once a second, +1 each time, 0xFF -> 0
 0x13    loop counter           r      +1 per control loop (wraps)
 0x14    error counter          r/w    distinct errors recorded; any write clears them
 0x15    last error             r      code of the last error (ERRORS_* below)
 0x16    emergency stop         r/w    1 while stopped; write 0x12 to clear it, anything else stops
 0x20    motion mode            r/w+   0 idle, 1 walk, 2 fixed position, 3 continuous rotation
 0x21    motion speed           r/w+   int8, units of 10 rpm (negative: backwards), clipped to 170 rpm
 0x22    motion phase           r/w+   0-239 (1.5 degrees each); 240-255 is an error and stops the leg
 0x23    motion extra           r/w+   walk: int8 speed trim in 0.1 rpm (fine turning); else unused
 0x24    motion CRC             r/w+   accepted, not checked (the spec names no polynomial)
 0x25    motion update          w      any value activates the buffered 0x20-0x24, which then clear
 0x26    motor voltage          r/w*   guarded: write 67, then the value in volts (default 12)
 0x40    leg phase              r      the leg's angle in phase units (0-239)
 0x41-2  leg angle              r      uint16, centidegrees (0-35999), 0 = pointing down
 0x43-4  leg speed              r      int16, 0.1 rpm
 0x45    H-bridge duty          r      int8, -127..127 (the motor's signed PWM)
 0x46-7  battery                r      uint16, mV, as the module's ADC reads it
 0x48-9  clock                  r      uint16, RTC counts (1.024 kHz) since the last sync write
 0x60    test field             r/w    free to write (the firmware's VREGS_TEST_FIELD)
======  =====================  =====  ====================================================================

(* guarded, + buffered: reads return the active value, not the buffer.) Every other address is reserved or
read-only: a write there is refused and recorded as an error, as are guarded writes without their guard value.

Why: the decimal column is what ran (the DeciZebro firmware and its Arduino test master write the sync counter at
18 = 0x12 and the motion block at 32 = 0x20), and it keeps the spec's own reserved rows consistent (0x07-0x10);
0x00-0x06 follow the spec's table, which the firmware's missing class id breaks; the emergency-stop field (0x16),
its clear value 0x12 and the error codes 1-9 are the firmware's; the codes from 10 on and the device-specific block
0x40-0x49 are ours (the firmware's own device block is debug output of its Hall-sensor walker, which this leg model
does not have: it reads its angle directly).
"""

from __future__ import annotations

# -- bus addresses ------------------------------------------------------------------------------------------
GENERAL_CALL = 0x00
MULTICAST_END = 0x0F  # 0x00-0x0F are multicast: writes only
DEVICE_FIRST, DEVICE_LAST = 0x10, 0x6F
LEG_ADDRESS_BASE = 0x10  # a leg module's address is 0x10 + its position (0-2 left, 3-5 right, front to back)
LEG_CLASS = 1

# -- shared fields (0x00-0x1F) ------------------------------------------------------------------------------
ZEBROBUS_VERSION = 0x00
CLASS_ID = 0x01
PRODUCT_ID = 0x02
PRODUCT_VERSION = 0x03
SERIAL_ID = 0x04
SOFTWARE_VERSION = 0x05
ZEBROBUS_ADDRESS = 0x06
QUICK_STATUS = 0x11
SYNC_COUNTER = 0x12
LOOP_COUNTER = 0x13
ERROR_COUNTER = 0x14
LAST_ERROR = 0x15
EMERGENCY_STOP = 0x16

# -- leg-class fields (0x20-0x3F) ---------------------------------------------------------------------------
MOTION_MODE = 0x20
MOTION_SPEED = 0x21
MOTION_PHASE = 0x22
MOTION_EXTRA = 0x23
MOTION_CRC = 0x24
MOTION_UPDATE = 0x25
MOTOR_VOLTAGE = 0x26
MOTION_FIELDS = (MOTION_MODE, MOTION_SPEED, MOTION_PHASE, MOTION_EXTRA, MOTION_CRC)  # buffered until the update

# -- device-specific fields (0x40-0xEF) ---------------------------------------------------------------------
LEG_PHASE = 0x40
LEG_ANGLE = 0x41  # 2 bytes
LEG_SPEED = 0x43  # 2 bytes
HBRIDGE_DUTY = 0x45
BATTERY_MV = 0x46  # 2 bytes
CLOCK = 0x48  # 2 bytes
TEST_FIELD = 0x60

# -- values -------------------------------------------------------------------------------------------------
MODE_IDLE, MODE_WALK, MODE_FIXED, MODE_ROTATE = 0, 1, 2, 3
PHASE_STEPS = 240  # motion phase units per turn
SPEED_UNIT_RPM = 10.0  # motion speed units
TRIM_UNIT_RPM = 0.1  # motion extra in walk mode
SERIAL_GUARD = 0x1B
MOTOR_VOLTAGE_GUARD = 67
ESTOP_CLEAR = 0x12  # ERRORS_EMERGENCY_STOP_SAFETY
WRITE_QUEUE = 50  # the firmware's ring buffer of write requests (holds 49)
RTC_HZ = 1024
SYNC_TIMEOUT_COUNTS = 2048  # TIME_ZEBROBUS_TIMEOUT_PERIOD: no sync write for 2048 / 1024 Hz = 2 s -> emergency stop

# quick status bits
QS_ESTOP, QS_MOVING, QS_TIMING, QS_ERROR, QS_AT_TARGET = 0x01, 0x02, 0x04, 0x08, 0x10

# -- error codes (last error) -------------------------------------------------------------------------------
ERR_MOTOR_OVERCURRENT = 6
ERR_ZEBROBUS_NO_TIMING_INFO = 7  # no sync write for 2 s: emergency stop
ERR_EMERGENCY_STOP_RESET = 8  # the emergency stop field written with another value than 0x12
ERR_READ_ONLY = 10  # a write to a read-only or reserved register
ERR_WRITE_GUARD = 11  # a guarded register written without its guard value first
ERR_MOTION_PHASE = 12  # motion phase 240-255 activated: the leg stops
ERR_MOTION_MODE = 13  # an unknown motion mode activated: refused
ERR_WRITE_QUEUE_FULL = 14  # more written bytes than the write queue holds: the rest is lost
ERR_COUNT = 14

ERROR_NAMES = {
    ERR_MOTOR_OVERCURRENT: "MOTOR_OVERCURRENT", ERR_ZEBROBUS_NO_TIMING_INFO: "ZEBROBUS_NO_TIMING_INFO",
    ERR_EMERGENCY_STOP_RESET: "EMERGENCY_STOP_RESET_ERROR", ERR_READ_ONLY: "ZEBROBUS_READ_ONLY",
    ERR_WRITE_GUARD: "ZEBROBUS_WRITE_GUARD", ERR_MOTION_PHASE: "MOTION_PHASE_OUT_OF_RANGE",
    ERR_MOTION_MODE: "MOTION_MODE_UNKNOWN", ERR_WRITE_QUEUE_FULL: "ZEBROBUS_WRITE_QUEUE_FULL",
}

# what the controller may write; everything else is read-only (guarded ones need their guard value first)
WRITABLE = frozenset({SERIAL_ID, SYNC_COUNTER, ERROR_COUNTER, EMERGENCY_STOP, *MOTION_FIELDS, MOTION_UPDATE,
                      MOTOR_VOLTAGE, TEST_FIELD})
GUARDS = {SERIAL_ID: SERIAL_GUARD, MOTOR_VOLTAGE: MOTOR_VOLTAGE_GUARD}


def leg_address(position: int) -> int:
    """The bus address of the leg module at ``position`` (0-2 left, 3-5 right, front to back)."""
    if not 0 <= position < 6:
        raise ValueError(f"leg position must be 0-5, got {position}")
    return LEG_ADDRESS_BASE + position


def is_multicast(addr: int) -> bool:
    return 0 <= addr <= MULTICAST_END


class ZebroBusSlave:
    """The slave side of ZebroBus every module shares: 256 vregs, the TWI slave's register pointer, the write queue
    (filled as bytes arrive, emptied by the module's main loop) and the shared fields' error bookkeeping.

    ``receive(segments)`` is one I2C transaction as it reached this module (each segment after a START or repeated
    START addressed to it: ``(addr, read, data_or_length)``), and returns what it sent for the read segments. Writes
    are queued; ``process_writes()`` applies them (the main loop calls it), through ``write_field`` for the fields a
    module class handles itself.
    """

    def __init__(self, address: int, class_id: int, serial_id: int) -> None:
        if not DEVICE_FIRST <= address <= DEVICE_LAST:
            raise ValueError(f"a ZebroBus device address is 0x10-0x6F, got 0x{address:02X}")
        self.address = address
        self.vregs = bytearray(256)
        self.vregs[ZEBROBUS_VERSION] = 1
        self.vregs[CLASS_ID] = class_id
        self.vregs[PRODUCT_ID] = 1
        self.vregs[PRODUCT_VERSION] = 1
        self.vregs[SERIAL_ID] = serial_id & 0xFF
        self.vregs[SOFTWARE_VERSION] = 1
        self.vregs[ZEBROBUS_ADDRESS] = address
        self.pointer_base = 0
        self.queue: list[tuple[int, int]] = []
        self.armed: dict[int, bool] = dict.fromkeys(GUARDS, False)
        self.errors: set[int] = set()
        self.counters: dict[str, int] = {"transactions": 0, "bytes_written": 0, "bytes_read": 0,
                                         "general_calls": 0, "refused_writes": 0, "reads_refused": 0,
                                         "queue_overflows": 0, "errors": 0}

    # -- the TWI slave (its interrupt) -----------------------------------------------------------------------
    def receive(self, segments: list[tuple[int, bool, bytes | int]]) -> list[bytes]:
        """One transaction's segments addressed to this module (or to the general call), then its STOP."""
        self.counters["transactions"] += 1
        pointer = self.pointer_base
        replies: list[bytes] = []
        for addr, read, data in segments:
            if read:
                n = int(data)  # type: ignore[arg-type]
                if is_multicast(addr):  # the spec: read requests on a multicast address are ignored
                    self.counters["reads_refused"] += 1
                    replies.append(bytes(n))
                    continue
                out = bytes(self.read_reg((pointer + i) & 0xFF) for i in range(n))
                pointer = (pointer + n) & 0xFF
                self.counters["bytes_read"] += n
                replies.append(out)
                continue
            if addr == GENERAL_CALL:
                self.counters["general_calls"] += 1
            buf = bytes(data)  # type: ignore[arg-type]
            if not buf:  # address only (a quick write): nothing for the vregs
                continue
            self.pointer_base = pointer = buf[0]
            for b in buf[1:]:
                if len(self.queue) >= WRITE_QUEUE - 1:
                    self.counters["queue_overflows"] += 1
                    self.report(ERR_WRITE_QUEUE_FULL)
                    break
                self.queue.append((pointer, b))
                pointer = (pointer + 1) & 0xFF
            self.counters["bytes_written"] += len(buf) - 1
        self.process_writes()  # the main loop runs right after the interrupt in this model
        return replies

    def read_reg(self, reg: int) -> int:
        """What a read of ``reg`` returns (the active values)."""
        return self.vregs[reg]

    # -- the main loop's part --------------------------------------------------------------------------------
    def process_writes(self) -> None:
        queue, self.queue = self.queue, []
        for reg, value in queue:
            if reg not in WRITABLE:
                self.refuse(ERR_READ_ONLY)
            elif reg in GUARDS:
                if self.armed[reg]:
                    self.armed[reg] = False
                    self.vregs[reg] = value
                    self.guarded_written(reg, value)
                elif value == GUARDS[reg]:
                    self.armed[reg] = True
                else:
                    self.refuse(ERR_WRITE_GUARD)
            elif reg == ERROR_COUNTER:  # any write clears the errors
                self.errors.clear()
                self.vregs[ERROR_COUNTER] = 0
                self.vregs[LAST_ERROR] = 0
            else:
                self.write_field(reg, value)

    def guarded_written(self, reg: int, value: int) -> None:
        """A guarded field took a new value (a module class acts on it)."""

    def write_field(self, reg: int, value: int) -> None:
        """A write to a writable field other than the guarded ones and the error counter."""
        self.vregs[reg] = value

    def refuse(self, code: int) -> None:
        self.counters["refused_writes"] += 1
        self.report(code)

    def report(self, code: int) -> None:
        """Record an error: the error counter counts distinct errors, last error names the latest."""
        self.counters["errors"] += 1
        self.errors.add(code)
        self.vregs[ERROR_COUNTER] = min(len(self.errors), 255)
        self.vregs[LAST_ERROR] = code

    def put16(self, reg: int, value: int) -> None:
        """A 16-bit field, big-endian, as two's complement when negative."""
        v = int(value) & 0xFFFF
        self.vregs[reg] = v >> 8
        self.vregs[reg + 1] = v & 0xFF
