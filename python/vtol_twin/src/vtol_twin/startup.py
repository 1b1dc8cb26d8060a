"""Reading a process's start lines: the twin (and the suite's other binaries) print one line per
ready endpoint on stdout before anything else. `read_start_lines` reads stdout until the caller
has seen what it waits for, with a deadline as the upper bound (never a sleep), and hands back
the bytes read past the last full line, so a reader that takes over stdout afterwards loses
nothing.
"""

from __future__ import annotations

import os
import select
import subprocess
import time
from typing import Callable


class StartTimeout(RuntimeError):
    """The deadline passed before the start lines were all read."""


class ExitedAtStart(RuntimeError):
    """The process closed its stdout (exited) before the start lines were all read."""

    def __init__(self, returncode: int | None):
        super().__init__(f"exited ({returncode}) at start")
        self.returncode = returncode


def read_start_lines(proc: subprocess.Popen, on_line: Callable[[str], None], started: Callable[[], bool],
                     deadline: float) -> bytes:
    """Reads `proc`'s stdout line by line (each stripped, to `on_line`) until `started()` holds;
    returns the bytes read past the last full line. `deadline` is a `time.monotonic()` time.

    Raises `StartTimeout` at the deadline and `ExitedAtStart` when stdout ends first."""
    fd = proc.stdout.fileno()
    buf = b""
    while not started():
        left = deadline - time.monotonic()
        if left <= 0:
            raise StartTimeout("no start lines in time")
        ready, _, _ = select.select([fd], [], [], min(left, 0.5))
        if not ready:
            continue
        chunk = os.read(fd, 4096)
        if not chunk:
            proc.wait(timeout=5)
            raise ExitedAtStart(proc.returncode)
        buf += chunk
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            on_line(line.decode(errors="replace").strip())
    return buf
