"""The `vtol-gcs` daemon as a subprocess, for the test_daemon_* modules.

Started like the twin in conftest.py: port-0 endpoints, the real addresses read from its stdout
(`vehicle …`, `serving <scheme>:<host>:<port>` per --serve, `logging <path>.tlog`), then its
status lines are drained by a thread. Every wait has a deadline as its upper bound.
"""

from __future__ import annotations

import os
import re
import select
import shutil
import signal
import struct
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import pytest

from conftest import ROOT, VEHICLE_COMPID, VEHICLE_SYSID, Gcs

DAEMON_BIN = Path(os.environ.get("VTOL_GCS_BIN", ROOT / "target" / "debug" / "vtol-gcs"))

SERVING_RE = re.compile(r"^serving\s+(?P<scheme>[a-z]+):(?P<addr>\S+)\s*$")
LOGGING_RE = re.compile(r"^logging\s+(?P<path>.+\.tlog)\s*$")
VEHICLE_RE = re.compile(r"^vehicle\s+(?P<what>.+)$")

# Scripts through the daemon speak as (255, 0), pymavlink's default (README "Routing").
SCRIPT_SYSID = 255
SCRIPT_COMPID = 0


@dataclass
class Daemon:
    proc: subprocess.Popen
    args: list[str]
    workdir: Path
    stderr_path: Path
    serving: list[tuple[str, str]] = field(default_factory=list)
    tlog: Path | None = None
    vehicle: str = ""
    stdout_lines: list[str] = field(default_factory=list)
    _drain: threading.Thread | None = None

    def addr(self, scheme: str, nth: int = 0) -> str:
        found = [a for (s, a) in self.serving if s == scheme]
        assert len(found) > nth, f"no {scheme} endpoint #{nth} in {self.serving}"
        return found[nth]

    @property
    def tcp(self) -> str:
        """pymavlink URL of the first tcpin endpoint."""
        return "tcp:" + self.addr("tcpin")

    @property
    def udp(self) -> str:
        """pymavlink URL of the first udpin endpoint."""
        return "udpout:" + self.addr("udpin")

    def stderr(self) -> str:
        try:
            return self.stderr_path.read_text(errors="replace")
        except OSError:
            return ""

    def tail(self) -> str:
        return f"stdout tail: {self.stdout_lines[-5:]}\nstderr tail:\n{self.stderr()[-3000:]}"

    def alive(self) -> bool:
        return self.proc.poll() is None

    def kill9(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        if self._drain is not None:
            self._drain.join(timeout=5)

    def stop(self) -> int:
        """Ctrl-C the daemon and return its exit code (killed → negative)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
                raise AssertionError("daemon did not exit within 15 s of SIGINT\n" + self.tail())
        if self._drain is not None:
            self._drain.join(timeout=5)
        return self.proc.returncode

    def assert_clean_exit(self) -> None:
        rc = self.stop()
        err = self.stderr()
        assert rc == 0, f"daemon exited with {rc}\n{self.tail()}"
        assert "panicked" not in err, f"daemon panicked:\n{err[-3000:]}"


def start_daemon(
    workdir: Path,
    vehicle: str = "embedded",
    serve: Iterable[str] = ("tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"),
    log: bool = True,
    extra: Iterable[str] = (),
    startup_timeout: float = 30.0,
) -> Daemon:
    assert DAEMON_BIN.exists(), f"{DAEMON_BIN} missing: build it with `cargo build --workspace`"
    workdir.mkdir(parents=True, exist_ok=True)
    serve = list(serve)
    args = [str(DAEMON_BIN), "run", "--vehicle", vehicle, "--headless"]
    for url in serve:
        args += ["--serve", url]
    args += ["--log-dir", str(workdir / "logs")] if log else ["--no-log"]
    args += list(extra)
    stderr_path = workdir / f"daemon-{time.monotonic_ns()}.stderr"
    err = open(stderr_path, "wb")
    env = dict(os.environ)
    env.setdefault("RUST_LOG", "info")
    env.setdefault("RUST_BACKTRACE", "1")
    proc = subprocess.Popen(args, cwd=workdir, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=err, env=env)
    err.close()
    d = Daemon(proc, args, workdir, stderr_path)
    deadline = time.monotonic() + startup_timeout
    buf = b""
    fd = proc.stdout.fileno()

    def started() -> bool:
        return bool(d.vehicle) and len(d.serving) >= len(serve) and (d.tlog is not None or not log)

    try:
        while not started():
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"daemon did not print its start lines in {startup_timeout} s; "
                                     f"args {args}\n{d.tail()}")
            ready, _, _ = select.select([fd], [], [], min(left, 0.5))
            if not ready:
                continue
            chunk = os.read(fd, 4096)
            if not chunk:
                proc.wait(timeout=5)
                raise AssertionError(f"daemon exited ({proc.returncode}) at start; args {args}\n{d.tail()}")
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                text = line.decode(errors="replace").strip()
                d.stdout_lines.append(text)
                if m := SERVING_RE.match(text):
                    d.serving.append((m["scheme"], m["addr"]))
                elif m := LOGGING_RE.match(text):
                    d.tlog = Path(m["path"])
                    if not d.tlog.is_absolute():
                        d.tlog = workdir / d.tlog
                elif m := VEHICLE_RE.match(text):
                    d.vehicle = m["what"]
    except BaseException:
        proc.kill()
        proc.wait()
        raise

    def drain() -> None:
        rest = buf
        while True:
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            rest += chunk
            *lines, rest = rest.split(b"\n")
            d.stdout_lines.extend(x.decode(errors="replace") for x in lines)
            del d.stdout_lines[:-200]  # only the tail matters (status lines, 1 a second)
        if rest:
            d.stdout_lines.append(rest.decode(errors="replace"))

    d._drain = threading.Thread(target=drain, daemon=True)
    d._drain.start()
    for scheme, addr in d.serving:
        if scheme in ("tcpin", "udpin"):
            assert int(addr.rsplit(":", 1)[1]) > 0, d.serving
    return d


class DaemonFactory:
    """Starts daemons on demand; stops every one of them (checking a clean exit) at teardown."""

    def __init__(self, base: Path):
        self.base = base
        self.daemons: list[Daemon] = []
        self.n = 0

    def __call__(self, **kw) -> Daemon:
        self.n += 1
        workdir = kw.pop("workdir", None) or self.base / f"daemon{self.n}"
        d = start_daemon(workdir, **kw)
        self.daemons.append(d)
        return d

    def forget(self, d: Daemon) -> None:
        """For a daemon the test killed itself."""
        self.daemons.remove(d)

    def close(self) -> None:
        errors = []
        for d in self.daemons:
            try:
                d.assert_clean_exit()
            except AssertionError as e:
                errors.append(str(e))
        self.daemons.clear()
        assert not errors, "\n".join(errors)


@pytest.fixture
def daemon_factory(tmp_path):
    f = DaemonFactory(tmp_path)
    yield f
    f.close()


@pytest.fixture(scope="module")
def module_daemon_factory(tmp_path_factory):
    f = DaemonFactory(tmp_path_factory.mktemp("daemon"))
    yield f
    f.close()


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
