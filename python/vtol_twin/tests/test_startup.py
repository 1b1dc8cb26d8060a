"""The start-line reader the plugin and the pymavlink suite share, on real child processes."""

import subprocess
import sys
import time

import pytest

from vtol_twin.startup import ExitedAtStart, StartTimeout, read_start_lines


def child(script: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE)


def test_reads_until_started_and_returns_what_follows():
    p = child("import sys; sys.stdout.write('a\\n  b  \\nc\\npartial'); sys.stdout.flush(); import signal; signal.pause()")
    seen: list[str] = []
    try:
        rest = read_start_lines(p, seen.append, lambda: "b" in seen, time.monotonic() + 30)
    finally:
        p.kill()
        p.wait()
    # Every full line of the chunk that held the last start line is read; the partial one is not.
    assert seen[:2] == ["a", "b"]
    assert rest in (b"", b"partial") and "partial" not in seen


def test_a_process_that_exits_first_is_named():
    p = child("print('only'); raise SystemExit(3)")
    seen: list[str] = []
    with pytest.raises(ExitedAtStart) as e:
        read_start_lines(p, seen.append, lambda: False, time.monotonic() + 30)
    assert e.value.returncode == 3 and seen == ["only"]


def test_the_deadline_bounds_the_wait():
    p = child("import signal; signal.pause()")  # silent until killed
    try:
        with pytest.raises(StartTimeout):
            read_start_lines(p, lambda _: None, lambda: False, time.monotonic() + 0.2)
    finally:
        p.kill()
        p.wait()
