"""ArduPlane SITL as a subprocess, for the tests and benchmarks against the real autopilot.

`ARDUPILOT_SITL` names the arduplane binary (an ArduPilot `build/sitl/bin/arduplane`);
`ARDUPILOT_DEFAULTS` the defaults file (default: the QuadPlane tailsitter's,
`Tools/autotest/default_params/plane-tailsitter.parm` of the tree the binary was built in);
`SITL_INSTANCE` the `-I` instance (default 1: TCP ports 5770, 5772, 5773). Each start runs in a
fresh temporary directory (SITL writes eeprom.bin, logs and terrain there), so every run starts
from the defaults. `--serial0 tcp:0` makes it boot without waiting for a client.
"""

from __future__ import annotations

import os
import re
import select
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

SITL_BIN = os.environ.get("ARDUPILOT_SITL", "")
INSTANCE = int(os.environ.get("SITL_INSTANCE", "1"))
MODEL = os.environ.get("ARDUPILOT_MODEL", "plane-tailsitter")


def defaults_file() -> Path:
    if os.environ.get("ARDUPILOT_DEFAULTS"):
        return Path(os.environ["ARDUPILOT_DEFAULTS"])
    root = Path(SITL_BIN).resolve().parents[3]
    return root / "Tools" / "autotest" / "default_params" / f"{MODEL}.parm"


class Sitl:
    """`arduplane --model plane-tailsitter -I N` in a temporary directory; SERIAL0 (`url`) and
    SERIAL1 (`url1`) are TCP servers on loopback, one client each."""

    def __init__(self, speedup: int = 1, instance: int = INSTANCE, startup_timeout: float = 90.0):
        assert SITL_BIN and Path(SITL_BIN).exists(), "ARDUPILOT_SITL must name the arduplane binary"
        self.port = 5760 + 10 * instance
        self.url = f"tcp:127.0.0.1:{self.port}"
        self.url1 = f"tcp:127.0.0.1:{self.port + 2}"
        self.dir = Path(tempfile.mkdtemp(prefix="sitl-"))
        args = [SITL_BIN, "--model", MODEL, "--speedup", str(speedup), "--defaults", str(defaults_file()),
                "-I", str(instance), "--serial0", "tcp:0"]
        self.log = open(self.dir / "sitl.out", "wb")
        self.proc = subprocess.Popen(args, cwd=self.dir, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT)
        try:
            self._wait_listening(startup_timeout)
        except BaseException:
            self.close()
            raise

    def _wait_listening(self, timeout: float) -> None:
        """Reads SITL's output until it says SERIAL0 and SERIAL1 listen ("SERIALn on TCP port N")."""
        deadline = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        text = b""
        want = re.compile(rb"SERIAL0 on TCP port (\d+)")
        want1 = re.compile(rb"SERIAL1 on TCP port (\d+)")
        while not (want.search(text) and want1.search(text)):
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"SITL did not start listening: {text[-2000:]!r}")
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                raise AssertionError(f"SITL exited: {text[-2000:]!r}")
            text += chunk
            self.log.write(chunk)
        self.port = int(want.search(text).group(1))
        self.url = f"tcp:127.0.0.1:{self.port}"
        self.url1 = f"tcp:127.0.0.1:{int(want1.search(text).group(1))}"
        # Keep draining its output so it never blocks on a full pipe.
        import threading

        def drain() -> None:
            while True:
                try:
                    chunk = os.read(fd, 65536)
                except OSError:
                    return
                if not chunk:
                    return
                try:
                    self.log.write(chunk)
                except ValueError:
                    return

        threading.Thread(target=drain, daemon=True).start()

    def reboot_once(self, timeout: float = 90.0) -> None:
        """[`reboot_once`] on this SITL's second port."""
        reboot_once(self.url1, timeout)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        self.log.close()
        shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def reboot_once(url: str, timeout: float = 90.0) -> None:
    """Reboots the SITL at `url` once, as ArduPilot's own autotest does for a tailsitter
    (Tools/autotest/arduplane.py: "tailsitter needs extra re-boot to pick up the rotated AHRS
    view"): booted from a `--defaults` file its parameters arrive after QuadPlane's set-up, so
    until a reboot it has no VTOL view (ATTITUDE in the fixed-wing frame in every mode) and its
    hover wanders. A real vehicle, whose parameters are stored, always boots with it. Returns
    once SITL answers again on `url`."""
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(url, source_system=254, autoreconnect=False)
    try:
        assert m.wait_heartbeat(timeout=timeout) is not None, f"no heartbeat from SITL on {url}"
        m.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=10)
        assert ack is not None and ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED, ack
        # The process restarts: the old one closes the connection.
        m.port.settimeout(timeout)
        while m.port.recv(65536):
            pass
    finally:
        m.close()
    deadline = time.monotonic() + timeout
    while True:
        try:
            m = mavutil.mavlink_connection(url, source_system=254, autoreconnect=False)
            ok = m.wait_heartbeat(timeout=max(0.1, deadline - time.monotonic())) is not None
            m.close()
            if ok:
                return
        except OSError:
            pass
        assert time.monotonic() < deadline, "SITL did not come back after its reboot"
        time.sleep(0.2)  # polling a port that is not open yet; there is no event to wait on
