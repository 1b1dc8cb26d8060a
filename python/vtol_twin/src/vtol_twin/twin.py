"""One `firmware-sim serve` process: started on free ports, driven through its harness channel,
stopped with a check that it exited cleanly.

The twin prints `listening tcpin:127.0.0.1:PORT` (the MAVLink port) and `control
tcpin:127.0.0.1:PORT` (the harness channel) on stdout once it is ready. The harness channel is
a line protocol: one request line (`advance SECONDS`, `state`, `param NAME VALUE`), one JSON
reply line (`firmware-sim/src/shell/harness.rs` documents it). A twin counts as started when its first
HEARTBEAT has arrived on the MAVLink port; that frame is read and checked here (CRC and all)
without pymavlink, so importing this module never fixes pymavlink's MAVLink version.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Optional, Union

from .startup import ExitedAtStart, StartTimeout, read_start_lines

# Lockstep (the default): sim time moves only on `advance`; "fast": as fast as the CPU allows;
# a number: that many times real time.
Speed = Union[str, float, int]

START_TIMEOUT_S = 30.0  # upper bound for the start lines and the first heartbeat
REPLY_TIMEOUT_S = 30.0  # upper bound for a harness reply (plus the advance's own share)
STOP_TIMEOUT_S = 10.0
STDERR_TAIL_LINES = 30

LISTEN_RE = re.compile(r"^listening tcpin:(?P<host>[^\s]+):(?P<port>\d+)$")
CONTROL_RE = re.compile(r"^control tcpin:(?P<host>[^\s]+):(?P<port>\d+)$")

MSG_HEARTBEAT = 0
HEARTBEAT_CRC_EXTRA = 50


class TwinError(RuntimeError):
    """The twin could not start, refused a request, or did not exit cleanly."""


def find_binary(explicit: Optional[Union[str, os.PathLike]] = None,
                search_from: Optional[Path] = None) -> Path:
    """The `firmware-sim` binary: `explicit` (the --vtol-twin-bin option or `vtol_twin_bin`
    ini value), else $FIRMWARE_SIM_BIN, else `firmware-sim` on PATH (`cargo install --path
    firmware-sim`), else a cargo build in `target/release` or `target/debug` of `search_from` or
    any folder above it."""
    tried: list[str] = []
    for label, value in (("--vtol-twin-bin", explicit), ("FIRMWARE_SIM_BIN", os.environ.get("FIRMWARE_SIM_BIN"))):
        if value:
            p = Path(value).expanduser().absolute()
            if p.is_file() and os.access(p, os.X_OK):
                return p
            raise TwinError(f"{label} names {p}, which is not an executable file")
    tried.append("--vtol-twin-bin / FIRMWARE_SIM_BIN (unset)")
    on_path = shutil.which("firmware-sim")
    if on_path:
        return Path(on_path)
    tried.append("firmware-sim on PATH")
    here = (search_from or Path.cwd()).resolve()
    for d in (here, *here.parents):
        for profile in ("release", "debug"):
            p = d / "target" / profile / "firmware-sim"
            if p.is_file() and os.access(p, os.X_OK):
                return p
    tried.append(f"target/release|debug/firmware-sim in {here} and above")
    raise TwinError(
        "firmware-sim not found (tried " + "; ".join(tried) + "): build it with "
        "`cargo install --path firmware-sim`, or point FIRMWARE_SIM_BIN or --vtol-twin-bin at it"
    )


@dataclass
class TwinOptions:
    """How to start a twin. Every field has a `firmware-sim serve` flag behind it."""

    # Real time by default: a script written as tutorials write them (wait for the armed
    # heartbeat, poll the altitude against a wall-clock deadline) runs unchanged. "lockstep"
    # holds sim time until `advance` moves it (fast, and the same telemetry on every run);
    # "fast" runs as fast as the CPU allows; a number is a multiple of real time.
    speed: Speed = 1
    seed: int = 1
    model: str = "physical"
    # Where it stands at start, on the ground: {"x": m, "y": m, "psi": rad} (paper frame), or the
    # flag's own text "x=..,y=..,psi=..".
    initial: Union[None, str, dict] = None
    # A parameter file to start from. It is copied first: the twin saves every change to its
    # file, and a test must not rewrite the user's.
    param_file: Optional[Union[str, os.PathLike]] = None
    # Parameters written through the harness once the twin is up (name -> value).
    params: dict = field(default_factory=dict)
    sysid: Optional[int] = None
    ideal_sensors: bool = False
    # The hardware's 1 s gyro calibration after power-up (arming refused until then).
    boot_calibration: bool = False
    extra_args: list = field(default_factory=list)

    KNOWN = ("speed", "seed", "model", "initial", "param_file", "params", "sysid", "ideal_sensors",
             "boot_calibration", "extra_args")

    @classmethod
    def merged(cls, *layers: dict) -> "TwinOptions":
        """Options from dicts, later ones winning; an unknown key is an error."""
        values: dict[str, Any] = {}
        for layer in layers:
            for k, v in layer.items():
                if k not in cls.KNOWN:
                    raise TypeError(f"unknown vtol_twin option '{k}' (known: {', '.join(cls.KNOWN)})")
                values[k] = v
        return cls(**values)

    @property
    def lockstep(self) -> bool:
        return self.speed == "lockstep"

    def args(self, workdir: Path) -> list[str]:
        a = ["--listen", "tcpin:127.0.0.1:0", "--control", "tcpin:127.0.0.1:0",
             "--seed", str(int(self.seed)), "--model", str(self.model)]
        if self.speed == "lockstep":
            a.append("--lockstep")
        elif self.speed == "fast":
            a.append("--fast")
        elif isinstance(self.speed, (int, float)) and not isinstance(self.speed, bool):
            a += ["--speed", f"{float(self.speed):g}"]
        else:
            raise TypeError(f"speed must be 'lockstep', 'fast' or a number, not {self.speed!r}")
        if self.initial:
            text = self.initial if isinstance(self.initial, str) else ",".join(
                f"{k}={v}" for k, v in self.initial.items())
            a += ["--initial", text]
        if self.param_file is not None:
            src = Path(self.param_file)
            if not src.is_file():
                raise TwinError(f"param_file {src} does not exist")
            copy = workdir / "params.parm"
            shutil.copyfile(src, copy)
            a += ["--param-file", str(copy)]
        if self.sysid is not None:
            a += ["--sysid", str(int(self.sysid))]
        if self.ideal_sensors:
            a.append("--ideal-sensors")
        if self.boot_calibration:
            a.append("--boot-calibration")
        return a + [str(x) for x in self.extra_args]


@dataclass(frozen=True)
class TrueState:
    """The vehicle's true state (not what its sensors or estimator say), in MAVLink's frames:
    NED position and velocity; roll/pitch/yaw (radians) and body rates in ArduPilot's fixed-wing
    body frame (x the nose, z the belly: pitch 90° on the tail), as ATTITUDE reports them on the
    wing (hovering, ATTITUDE is ArduPlane's VTOL view instead)."""

    t_us: int
    armed: bool
    mode: str
    system_status: str
    landed: bool
    position_ned_m: tuple
    altitude_m: float
    velocity_ned_m_s: tuple
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    rates_frd_rad_s: tuple
    pwm_us: tuple

    @property
    def t_s(self) -> float:
        return self.t_us / 1e6

    @classmethod
    def from_json(cls, d: dict) -> "TrueState":
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()
                      if k in cls.__dataclass_fields__})


def _x25(data: bytes, crc: int = 0xFFFF) -> int:
    """MAVLink's CRC-16/MCRF4XX."""
    for b in data:
        tmp = (b ^ crc) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def first_heartbeat(buf: bytes) -> tuple[Optional[int], int]:
    """Scans `buf` for a whole MAVLink 2 HEARTBEAT with a good CRC. Returns (its sysid or None,
    how many bytes may be dropped from the front)."""
    i = 0
    while True:
        i = buf.find(b"\xfd", i)
        if i < 0:
            return None, len(buf)
        if len(buf) - i < 10:
            return None, i
        length, incompat = buf[i + 1], buf[i + 2]
        total = 10 + length + 2 + (13 if incompat & 1 else 0)
        if len(buf) - i < total:
            return None, i
        msgid = int.from_bytes(buf[i + 7:i + 10], "little")
        if msgid == MSG_HEARTBEAT:
            crc = struct.unpack_from("<H", buf, i + 10 + length)[0]
            if _x25(buf[i + 1:i + 10 + length] + bytes([HEARTBEAT_CRC_EXTRA])) == crc:
                return buf[i + 5], i + total
        i += 1


class VtolTwin:
    """A running twin. `url` is the pymavlink connection string of its MAVLink port."""

    def __init__(self, proc: subprocess.Popen, workdir: Path, tlog: Path, options: TwinOptions,
                 stderr_path: Path, args: list[str]):
        self.proc = proc
        self.workdir = workdir
        self.tlog = tlog
        self.options = options
        self.stderr_path = stderr_path
        self.args = args
        self.url = ""
        self.mavlink_address: tuple[str, int] = ("", 0)
        self.control_address: tuple[str, int] = ("", 0)
        self.sysid: Optional[int] = None
        self.keep_tlog = False
        self._control: Optional[socket.socket] = None
        self._control_rd = None
        self._connections: list = []
        self._stopped = False

    # -- start ------------------------------------------------------------------------------

    @classmethod
    def spawn(cls, binary: Path, workdir: Path, options: TwinOptions, tlog: Path) -> "VtolTwin":
        """Starts the process (returns at once; `wait_started` waits for it)."""
        workdir.mkdir(parents=True, exist_ok=True)
        args = [str(binary), "serve", *options.args(workdir), "--tlog", str(tlog)]
        stderr_path = workdir / "firmware-sim.stderr"
        env = dict(os.environ)
        env.setdefault("RUST_LOG", "warn")
        with open(stderr_path, "wb") as err:
            proc = subprocess.Popen(args, cwd=workdir, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                    stderr=err, env=env)
        return cls(proc, workdir, tlog, options, stderr_path, args)

    def wait_started(self, timeout: float = START_TIMEOUT_S) -> "VtolTwin":
        """Reads the start lines, waits for the first HEARTBEAT and applies `options.params`."""
        deadline = time.monotonic() + timeout
        try:
            self._read_start_lines(deadline)
            self._wait_heartbeat(deadline)
            self._control = socket.create_connection(self.control_address, timeout=max(0.1, deadline - time.monotonic()))
            self._control_rd = self._control.makefile("rb")
            for name, value in self.options.params.items():
                self.set_param(name, value)
        except BaseException:
            self._kill()
            raise
        return self

    def _read_start_lines(self, deadline: float) -> None:
        got: set[str] = set()

        def on_line(text: str) -> None:
            if m := LISTEN_RE.match(text):
                self.mavlink_address = (m["host"].strip("[]"), int(m["port"]))
                self.url = f"tcp:{m['host']}:{m['port']}"
                got.add("listen")
            elif m := CONTROL_RE.match(text):
                self.control_address = (m["host"].strip("[]"), int(m["port"]))
                got.add("control")

        try:
            read_start_lines(self.proc, on_line, lambda: got >= {"listen", "control"}, deadline)
        except StartTimeout:
            raise TwinError(f"firmware-sim printed no start lines in time; args {self.args}\n{self.stderr_tail()}") from None
        except ExitedAtStart as e:
            raise TwinError(f"firmware-sim exited ({e.returncode}) at start; args {self.args}\n"
                            f"{self.stderr_tail()}") from None

    def _wait_heartbeat(self, deadline: float) -> None:
        with socket.create_connection(self.mavlink_address, timeout=max(0.1, deadline - time.monotonic())) as s:
            buf = b""
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TwinError(f"no HEARTBEAT from the twin at {self.url} in time\n{self.stderr_tail()}")
                s.settimeout(left)
                try:
                    chunk = s.recv(4096)
                except socket.timeout:
                    continue
                if not chunk:
                    raise TwinError(f"the twin closed {self.url} before its first HEARTBEAT\n{self.stderr_tail()}")
                sysid, used = first_heartbeat(buf + chunk)
                buf = (buf + chunk)[used:]
                if sysid is not None:
                    self.sysid = sysid
                    return

    # -- the harness channel ----------------------------------------------------------------

    def _call(self, line: str, timeout: float = REPLY_TIMEOUT_S) -> dict:
        if self._control is None or self._stopped:
            raise TwinError("the twin is not running")
        self._control.settimeout(timeout)
        try:
            self._control.sendall(line.encode() + b"\n")
            reply = self._control_rd.readline()
        except (socket.timeout, TimeoutError):
            raise TwinError(
                f"'{line}' got no reply in {timeout:.0f} s. Under lockstep the twin waits for every "
                f"client to read its telemetry: does a connection go unread?\n{self.stderr_tail()}"
            ) from None
        if not reply:
            raise TwinError(f"the twin closed its control channel ('{line}')\n{self.stderr_tail()}")
        d = json.loads(reply)
        if "error" in d:
            raise TwinError(f"'{line}': {d['error']}")
        return d

    def advance(self, seconds: float) -> float:
        """Flies `seconds` more of sim time (lockstep twins only) and returns the sim time, s.
        When it returns, every frame of those seconds is on its way to its link. Wait for the
        replies to what you sent (COMMAND_ACK, PARAM_VALUE) before you advance: then every run
        is the same."""
        if not self.options.lockstep:
            raise TwinError(
                f"advance needs a lockstep twin; this one runs at speed {self.options.speed!r} "
                "(the default is real time): mark the test @pytest.mark.vtol_twin(speed=\"lockstep\")")
        d = self._call(f"advance {float(seconds)!r}", timeout=REPLY_TIMEOUT_S + float(seconds) / 100.0)
        return d["t_us"] / 1e6

    def state(self) -> TrueState:
        """The true state."""
        return TrueState.from_json(self._call("state"))

    @property
    def time_s(self) -> float:
        """Sim time, s."""
        return self.state().t_s

    def set_param(self, name: str, value: float) -> float:
        """Writes a parameter with the vehicle's own checks (TwinError says why it was refused)
        and returns the value stored. Every MAVLink client gets the PARAM_VALUE."""
        if not re.fullmatch(r"[A-Za-z0-9_]{1,16}", name):
            raise TwinError(f"'{name}' is not a parameter name")
        return self._call(f"param {name} {float(value)!r}")["value"]

    def push(self, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0, ms: float = 200.0) -> None:
        """A torque push on the hover frame's FRD body axes (as a pilot behind the hovering
        vehicle sees them), N·m, for `ms` milliseconds (SIM_PUSH_*), like the paper's hover
        experiments."""
        if not (roll or pitch or yaw):
            raise TwinError("push needs a non-zero torque on some axis")
        self.set_param("SIM_PUSH_MS", ms)
        for name, v in (("SIM_PUSH_ROLL", roll), ("SIM_PUSH_PITCH", pitch), ("SIM_PUSH_YAW", yaw)):
            if v:
                self.set_param(name, v)

    def wind(self, speed_m_s: float, direction_deg: float = 0.0, turbulence_m_s: float = 0.0) -> None:
        """Steady wind from `direction_deg` (where it comes from, degrees from north) with
        gusts of `turbulence_m_s` (SIM_WIND_*)."""
        self.set_param("SIM_WIND_DIR", direction_deg)
        self.set_param("SIM_WIND_TURB", turbulence_m_s)
        self.set_param("SIM_WIND_SPD", speed_m_s)

    def connect(self, timeout: float = 10.0, **kw):
        """A pymavlink connection to the twin (system 255 by default) that has seen its
        heartbeat; closed when the twin stops."""
        from pymavlink import mavutil  # imported late: the user's conftest may set MAVLINK20

        kw.setdefault("source_system", 255)
        m = mavutil.mavlink_connection(self.url, **kw)
        self._connections.append(m)
        if m.wait_heartbeat(timeout=timeout) is None:
            raise TwinError(f"no HEARTBEAT on {self.url} within {timeout} s")
        return m

    # -- stop -------------------------------------------------------------------------------

    def stderr_tail(self) -> str:
        try:
            lines = self.stderr_path.read_text(errors="replace").splitlines()
        except OSError:
            return "(no stderr)"
        return "firmware-sim stderr:\n" + "\n".join(lines[-STDERR_TAIL_LINES:])

    def stop(self) -> None:
        """Stops the twin like Ctrl-C and checks that it exited cleanly (TwinError if not)."""
        if self._stopped:
            return
        self._stopped = True
        for m in self._connections:
            try:
                m.close()
            except OSError:
                pass
        for f in (self._control_rd, self._control):
            if f is not None:
                f.close()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self._kill()
                raise TwinError(f"firmware-sim did not stop within {STOP_TIMEOUT_S} s of SIGINT\n"
                                f"{self.stderr_tail()}") from None
        if self.proc.stdout:
            self.proc.stdout.close()
        tail = self.stderr_tail()
        if self.proc.returncode != 0 or "panicked" in tail:
            raise TwinError(f"firmware-sim exited with {self.proc.returncode}\n{tail}")

    def _kill(self) -> None:
        self._stopped = True
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        if self.proc.stdout:
            self.proc.stdout.close()


def start_fleet(binary: Path, workdirs: Iterable[Path], tlogs: Iterable[Path],
                options: Iterable[TwinOptions], timeout: float = START_TIMEOUT_S) -> list[VtolTwin]:
    """Starts several twins at once: every process is launched before any is waited for."""
    twins: list[VtolTwin] = []
    try:
        for w, t, o in zip(workdirs, tlogs, options):
            twins.append(VtolTwin.spawn(binary, w, o, t))
        for t in twins:
            t.wait_started(timeout)
    except BaseException:
        for t in twins:
            t._kill()
        raise
    return twins
