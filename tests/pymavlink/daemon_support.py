"""The `vtol-gcs` daemon as a subprocess, for the test_daemon_* modules.

Started like the twin in conftest.py, by the same code (procs.py): port-0 endpoints, the real
addresses read from its stdout (`vehicle …`, `serving <scheme>:<host>:<port>` per --serve,
`logging <path>.tlog`), then its status lines are drained by a thread. Every wait has a deadline
as its upper bound.
"""

from __future__ import annotations

import os
import re
import select
import shutil
import struct
import subprocess
import time
from functools import partial
from pathlib import Path
from typing import Iterable

from conftest import ROOT, VEHICLE_COMPID, VEHICLE_SYSID, Gcs
from procs import ManagedProcess, ProcessFactory, factory_fixtures

# A relative path in the environment is taken from where the command was started.
DAEMON_BIN = Path(os.environ.get("VTOL_GCS_BIN", ROOT / "target" / "debug" / "vtol-gcs")).absolute()

# An endpoint with a policy is printed with its query (`serving tcpin:127.0.0.1:5770?trust=sign`).
SERVING_RE = re.compile(r"^serving\s+(?P<scheme>[a-z]+):(?P<addr>[^\s?]+)(?P<query>\?\S*)?\s*$")
LOGGING_RE = re.compile(r"^logging\s+(?P<path>.+\.tlog)\s*$")
VEHICLE_RE = re.compile(r"^vehicle\s+(?P<what>.+)$")

# Scripts through the daemon speak as (255, 0), pymavlink's default (README "Routing").
SCRIPT_SYSID = 255
SCRIPT_COMPID = 0


class Daemon(ManagedProcess):
    """`vtol-gcs run --headless`: `vehicle …`, one `serving <scheme>:<addr>` line per --serve and,
    when logging, `logging <path>.tlog`."""

    KIND = "daemon"
    ENDPOINT_RE = SERVING_RE
    tlog: Path | None = None
    vehicle: str = ""
    log: bool = True

    @property
    def serving(self) -> list[tuple[str, str]]:
        """(scheme, address) as printed."""
        return self.endpoints

    def on_line(self, text: str) -> None:
        if m := LOGGING_RE.match(text):
            self.tlog = Path(m["path"])
            if not self.tlog.is_absolute():
                self.tlog = self.workdir / self.tlog
        elif m := VEHICLE_RE.match(text):
            self.vehicle = m["what"]

    def started(self) -> bool:
        return super().started() and bool(self.vehicle) and (self.tlog is not None or not self.log)


def start_daemon(
    workdir: Path,
    vehicle: str = "embedded",
    serve: Iterable[str] = ("tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"),
    log: bool = True,
    extra: Iterable[str] = (),
    startup_timeout: float = 30.0,
    log_dir: Path | None = None,
) -> Daemon:
    assert DAEMON_BIN.exists(), f"{DAEMON_BIN} missing: build it with `cargo build --workspace`"
    serve = list(serve)
    args = [str(DAEMON_BIN), "run", "--vehicle", vehicle, "--headless"]
    for url in serve:
        args += ["--serve", url]
    args += ["--log-dir", str(log_dir or workdir / "logs")] if log else ["--no-log"]
    args += list(extra)
    return Daemon.spawn(args, workdir, len(serve), startup_timeout, log=log)


# Starts daemons on demand (`DaemonFactory(base)`); the fixtures stop every one (checking a clean exit).
DaemonFactory = partial(ProcessFactory, start=start_daemon, prefix="daemon")
daemon_factory, module_daemon_factory = factory_fixtures(start_daemon, "daemon")


def script(url: str) -> Gcs:
    """A pymavlink script through the daemon: (255, 0), like `mavutil.mavlink_connection(url)`.
    Its 1 Hz GCS heartbeat is also how a udpin endpoint of the daemon learns it."""
    return Gcs(url, source_system=SCRIPT_SYSID, source_component=SCRIPT_COMPID)


# --------------------------------------------------------------------------------------------
# socat pseudo-terminal pairs with fixed link names
# --------------------------------------------------------------------------------------------


class Socat:
    """`socat pty,raw,echo=0,link=A pty,raw,echo=0,link=B`; restartable with the same names."""

    def __init__(self, a: Path, b: Path):
        assert shutil.which("socat"), "socat missing (tests/run.sh installs it)"
        self.a, self.b = a, b
        self.proc: subprocess.Popen | None = None

    def start(self, timeout: float = 10.0) -> None:
        assert self.proc is None or self.proc.poll() is not None
        self.proc = subprocess.Popen(
            ["socat", "-d", "-d", f"pty,raw,echo=0,link={self.a}", f"pty,raw,echo=0,link={self.b}"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        text = ""
        deadline = time.monotonic() + timeout
        fd = self.proc.stderr.fileno()
        while "starting data transfer loop" not in text:
            left = deadline - time.monotonic()
            if left <= 0:
                self.stop()
                raise AssertionError(f"socat did not come up: {text!r}")
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(fd, 4096)
            if not chunk:
                self.stop()
                raise AssertionError(f"socat exited: {text!r}")
            text += chunk.decode(errors="replace")
        assert self.a.exists() and self.b.exists(), text

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        if self.proc is not None and self.proc.stderr is not None:
            self.proc.stderr.close()


# --------------------------------------------------------------------------------------------
# tlog reading (PROTOCOL.md D.2)
# --------------------------------------------------------------------------------------------


def frame_len(buf: bytes, i: int) -> int | None:
    """Length of the MAVLink frame starting at buf[i], or None if it is not a frame start or the
    header is cut."""
    if i >= len(buf):
        return None
    magic = buf[i]
    if magic == 0xFE:
        if i + 2 > len(buf):
            return None
        return 6 + buf[i + 1] + 2
    if magic == 0xFD:
        if i + 3 > len(buf):
            return None
        return 10 + buf[i + 1] + 2 + (13 if buf[i + 2] & 0x01 else 0)
    raise ValueError(f"no MAVLink magic at offset {i}: {buf[i:i + 16].hex()}")


def raw_records(data: bytes) -> tuple[list[tuple[int, bytes]], int]:
    """Walks the records of a tlog strictly: (stamp µs, frame) each, plus the number of bytes of a
    cut last record (0 if the file ends on a record boundary). Any other damage raises."""
    out = []
    i = 0
    while i < len(data):
        if i + 8 > len(data):
            return out, len(data) - i
        (stamp,) = struct.unpack(">Q", data[i:i + 8])
        n = frame_len(data, i + 8)
        if n is None or i + 8 + n > len(data):
            return out, len(data) - i
        out.append((stamp, data[i + 8:i + 8 + n]))
        i += 8 + n
    return out, 0


def frame_ids(frame: bytes) -> tuple[int, int, int, int]:
    """(seq, sysid, compid, msgid) of a raw frame."""
    if frame[0] == 0xFE:
        return frame[2], frame[3], frame[4], frame[5]
    return frame[4], frame[5], frame[6], frame[7] | frame[8] << 8 | frame[9] << 16


def wait_vehicle_silence(g, quiet_s: float, timeout: float) -> None:
    """Until no vehicle frame has arrived for quiet_s seconds (the link is really down)."""
    deadline = time.monotonic() + timeout
    last = time.monotonic()
    while time.monotonic() - last < quiet_s:
        assert time.monotonic() < deadline, f"vehicle frames kept coming for {timeout} s after the vehicle link was cut"
        g.beat()
        m = g.m.recv_match(blocking=True, timeout=0.1)
        if m is not None and m.get_srcSystem() == VEHICLE_SYSID and m.get_srcComponent() == VEHICLE_COMPID:
            last = time.monotonic()
