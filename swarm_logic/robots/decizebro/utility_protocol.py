"""The Zebro's utility sensor board to its Raspberry Pi: our own protocol (the thesis' sensor is an abstraction, "the
readings are fused, normalised over 100 and rounded", section 3.2; no board exists), framed as the UWB radio's UART
is (``uwb_protocol``: ``A5 LEN TYPE BODY CRC16``), 115200 8N1.

The board streams one ``REPORT`` every ``REPORT_PERIOD_NS`` (10 Hz) and needs no request:

==========  ======================================================================================================
``0x90``    REPORT: utility i16 (the sum in the cone), bearing i16 centidegrees (+ = left, ``NO_BEARING`` when the
            cone sees nothing), eaten u16 (particles eaten since power-up, wrapping), eaten_sum i32 (their utilities'
            sum since power-up), little-endian
==========  ======================================================================================================

A host that misses a report loses nothing of the consumptions: the eaten counters are cumulative.
"""

from __future__ import annotations

import struct

from swarm_logic.robots.decizebro.uwb_protocol import Bad, Parser, frame

REPORT = 0x90
REPORT_BODY = struct.Struct("<hhHi")
NO_BEARING = 0x7FFF
REPORT_PERIOD_NS = 100_000_000
BAUD = 115200

__all__ = ["BAUD", "NO_BEARING", "REPORT", "REPORT_BODY", "REPORT_PERIOD_NS", "Bad", "Parser", "frame"]
