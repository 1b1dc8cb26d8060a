"""Serial transport over a pseudo-terminal pair made by socat: the twin on one end, pymavlink on
the other."""

import os
import re
import select
import shutil
import subprocess
import time

import pytest

from conftest import FLAG_CUSTOM_MODE, MAV_TYPE_FIXED_WING, Gcs

PTY_RE = re.compile(r"PTY is (/dev/pts/\d+)")


@pytest.fixture
def pty_pair():
    assert shutil.which("socat"), "socat missing (tests/run.sh installs it)"
    proc = subprocess.Popen(
        ["socat", "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    ptys: list[str] = []
    text = ""
    deadline = time.monotonic() + 10
    fd = proc.stderr.fileno()
    try:
        # raw reads: a buffered readline() would hide lines from select()
        while "starting data transfer loop" not in text:
            left = deadline - time.monotonic()
            assert left > 0, f"socat did not come up: {text!r}"
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(fd, 4096)
            assert chunk, f"socat exited: {text!r}"
            text += chunk.decode(errors="replace")
        ptys = PTY_RE.findall(text)
        assert len(ptys) == 2, text
        yield ptys[0], ptys[1]
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_serial_heartbeat_and_param(twin_factory, pty_pair):
    twin_end, gcs_end = pty_pair
    twin = twin_factory(listen=[f"serial:{twin_end}:115200", "tcpin:127.0.0.1:0"], speed=4)
    assert any(s == "serial" for s, _ in twin.listeners), twin.listeners
    g = Gcs(gcs_end, baud=115200)
    try:
        hb = g.wait_vehicle_heartbeat(timeout=20)
        assert hb.type == MAV_TYPE_FIXED_WING and hb.base_mode & FLAG_CUSTOM_MODE
        assert g.m.target_system == 1
        p = g.param_get("HOVER_ALT")
        assert p.param_count > 0
        ack = g.command(65000)
        assert ack.result == 3, ack
        # more heartbeats keep coming over the serial line
        g.wait_vehicle_heartbeat(timeout=10)
    finally:
        g.close()
