"""Iterations on a clock every robot shares: the schedule of the RDPSO and of the baseline swarm algorithms.

Iteration ``k`` starts at ``k * iteration_s`` (so all robots agree on ``k``): phase A senses and prepares this
robot's one frame, which goes out ``U(0, send_jitter_s)`` later (real robots are not synchronised to the
millisecond); phase B, ``comm_window_s`` after the start, reads the frames of iteration ``k`` and moves. A
controller mixes this in and provides ``_phase_a``, ``_send`` and ``_phase_b``; its ``step`` calls ``_iterate``,
which sets ``period_s`` to the time of the next call.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any


class IterationSchedule:
    p: dict[str, Any]
    robot: Any
    period_s: float
    dropped: dict[str, int]

    def _begin(self) -> None:
        """Start on an iteration boundary, after the LLC has taken the start pose (at least 0.3 s from now)."""
        it = self.p["iteration_s"]
        now = self.robot.clock.now()
        self.k = math.ceil((now + 0.3) / it)
        self.phase = "A"
        self.next_t = self.k * it
        self.period_s = self.next_t - now

    def _iterate(self) -> None:
        """Run the phase that is due; a robot without a pose from its LLC yet sits the iteration out."""
        it = self.p["iteration_s"]
        now = self.robot.clock.now()
        if now < self.next_t - 1e-6:  # called early (a runner's first call comes at once)
            self.period_s = self.next_t - now
            return
        if self.phase == "A":
            if self.robot.llc.state.odom_t is None:
                self.k = math.floor(now / it + 1e-9) + 1
            else:
                self._phase_a()
                jitter = self.p["send_jitter_s"]
                if jitter > 0:
                    self.phase = "S"
                    self.next_t = self.k * it + self.robot.rng_py.uniform(0.0, jitter)
                else:
                    self._send()
                    self.phase = "B"
                    self.next_t = self.k * it + self.p["comm_window_s"]
                self.period_s = max(0.0, self.next_t - now)
                return
        elif self.phase == "S":
            self._send()
            self.phase = "B"
            self.next_t = self.k * it + self.p["comm_window_s"]
            self.period_s = self.next_t - now
            return
        else:
            self._phase_b()
            self.phase = "A"
            self.k = max(self.k + 1, math.floor(now / it + 1e-9) + 1)
        self.next_t = self.k * it
        self.period_s = self.next_t - now

    def _frames_of_iteration(self, decode: Callable[[bytes], Any], unknown: str) -> Iterator[tuple[Any, Any]]:
        """Drain the radio: the frames (decoded, and the packet) other robots sent in this iteration. Frames that
        do not decode are counted in ``self.dropped[unknown]``, late ones (or from a robot whose clock disagrees)
        in ``self.dropped["late"]``; both are dropped."""
        r = self.robot
        k16 = self.k & 0xFFFF
        while (pkt := self._receive()) is not None:
            msg = decode(bytes(pkt.data))
            if msg is None:  # another application's frame, or a damaged one
                self.dropped[unknown] += 1
                continue
            if msg.robot == r.id:
                continue
            if msg.k != k16:
                self.dropped["late"] += 1
                continue
            yield msg, pkt

    def _receive(self) -> Any:
        """The next received packet, or None: the radio's, unless a routing layer sits in between."""
        return self.robot.xbee.recv(timeout=0)

    def _phase_a(self) -> None:
        raise NotImplementedError

    def _send(self) -> None:
        raise NotImplementedError

    def _phase_b(self) -> None:
        raise NotImplementedError
