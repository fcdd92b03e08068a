"""A serial line from a robot's computer to one of its modules: bytes leave at the sender's baud rate.

Each byte takes 10 bit times (start, 8 data, stop). Chunks queue behind each other, and at every quantum
boundary the receiver gets the bytes that have fully arrived by then, so a 100-byte API frame at 9600 baud
reaches the module over about 104 ms, as on the wire. When the two ends disagree on the baud rate the
receiver samples garbage: every byte arrives as a framing error and is replaced by what a UART would
latch (modelled as a fixed scrambling), which the module's parser then rejects and counts.
"""

from __future__ import annotations

from collections import deque

BITS_PER_BYTE = 10


def garble(data: bytes) -> bytes:
    """What a UART sampling at the wrong baud rate latches instead of ``data`` (a fixed scrambling)."""
    return bytes(((b * 73 + 41) ^ 0x5A) & 0xFF for b in data)


class SerialLine:
    def __init__(self, baud: int) -> None:
        self.baud = baud  # the receiving end's rate
        self._q: deque[tuple[int, int, bytes]] = deque()  # (start ns, sender baud, data)
        self.busy_until = 0
        self.bytes = 0
        self.garbled = 0

    @property
    def pending(self) -> bool:
        return bool(self._q)

    def offer(self, t_ns: int, data: bytes, baud: int) -> None:
        """``data`` handed to the sender's UART at ``t_ns`` (it starts when the line is free)."""
        start = max(t_ns, self.busy_until)
        self.busy_until = start + len(data) * BITS_PER_BYTE * 1_000_000_000 // baud
        self._q.append((start, baud, data))

    def arrived(self, t_ns: int) -> bytes:
        """The bytes that have fully arrived by ``t_ns`` (and were not taken before)."""
        out = bytearray()
        q = self._q
        while q:
            start, baud, data = q[0]
            done = (t_ns - start) * baud // (BITS_PER_BYTE * 1_000_000_000) if t_ns > start else 0
            if done <= 0:
                break
            chunk = data[:done]
            if baud != self.baud:
                self.garbled += len(chunk)
                chunk = garble(chunk)
            out += chunk
            if done >= len(data):
                q.popleft()
            else:
                q[0] = (start + done * BITS_PER_BYTE * 1_000_000_000 // baud, baud, data[done:])
                break
        self.bytes += len(out)
        return bytes(out)
