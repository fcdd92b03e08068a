"""``python -m bridge.hosts.tethered PARENT_PID -- COMMAND...``: run a command that must not outlive the launcher.

A host's ``launch`` command (``ssh ...``, a shell line) is not a Python process of ours that could ask the kernel to
end it with its parent, and the launcher cannot ask for it between fork and exec (zenoh's threads make that unsafe).
This small process can: it asks for SIGTERM when its parent dies, runs the command in its own process group (the
launcher starts it as a group leader), waits for it and exits with its code; should the launcher vanish, it ends the
whole group, the command's children included.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys

from bridge.hosts.parent import die_with_parent


def _end_group(signum: int, frame: object) -> None:
    os.killpg(os.getpgrp(), signal.SIGKILL)  # the command, what it started, and this process


def main(argv: list[str]) -> int:
    if len(argv) < 3 or argv[1] != "--" or not argv[0].isdigit():
        print("usage: python -m bridge.hosts.tethered PARENT_PID -- COMMAND...", file=sys.stderr)
        return 2
    signal.signal(signal.SIGTERM, _end_group)
    die_with_parent(signal.SIGTERM)
    if os.getppid() != int(argv[0]):  # the parent died before the request took effect
        _end_group(signal.SIGTERM, None)
    code = subprocess.Popen(argv[2:]).wait()
    if code < 0:  # the command was killed: so is this process, by the same signal, as if it were the command
        with contextlib.suppress(OSError, ValueError):  # SIGKILL and SIGSTOP have no handler to reset
            signal.signal(-code, signal.SIG_DFL)
        os.kill(os.getpid(), -code)
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
