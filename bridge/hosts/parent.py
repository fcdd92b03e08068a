"""A child process dies with its parent: the kernel's parent-death signal (Linux), asked for before anything slow, so a
launcher killed at any moment leaves no orphan."""

from __future__ import annotations

import ctypes
import signal

PR_SET_PDEATHSIG = 1


def die_with_parent(sig: int = signal.SIGKILL) -> None:
    """Ask the kernel to send ``sig`` to this process when its parent dies (Linux); no orphans, ever. The caller
    checks afterwards that its parent is still the one it expects (it may have died before the request)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, sig, 0, 0, 0)
    except (OSError, AttributeError):
        pass
