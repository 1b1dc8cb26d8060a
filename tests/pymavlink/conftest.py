"""Shared fixtures for the pymavlink / MAVProxy suite.

Every test talks to the real twin (`firmware-sim serve`) over real sockets or pseudo-terminals.
The twin is started with port-0 listeners; the bound addresses are read from its stdout
(`listening <scheme>:<host>:<port>`, one line per listener). The process mechanics (start lines,
stdout drain, clean-exit checks) are procs.py's, shared with the daemon (daemon_support.py).

Waiting is always "until the event, with a deadline as the upper bound" (`Gcs.recv`), never a
sleep.
"""

from __future__ import annotations

import math
import os
import re
import struct
import time
from functools import partial
from pathlib import Path
from typing import Callable, Iterable

# Scripts in this suite speak MAVLink 2 from their first frame. This must be set before pymavlink
# is imported (PROTOCOL.md C.2). test_connect runs its MAVLink-1 client in a clean subprocess.
os.environ["MAVLINK20"] = "1"

import pytest  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from procs import ManagedProcess, ProcessFactory, factory_fixtures  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
# A relative path in the environment is taken from where the command was started.
TWIN_BIN = Path(os.environ.get("FIRMWARE_SIM_BIN", ROOT / "target" / "debug" / "firmware-sim")).absolute()

VEHICLE_SYSID = 1
VEHICLE_COMPID = 1
GCS_SYSID = 255
GCS_COMPID = 190

MAV_TYPE_GCS = 6
MAV_TYPE_VTOL_DUOROTOR = 19
# The twin's HEARTBEAT type: ArduPlane's for a tailsitter with Q_MAV_TYPE at its default.
MAV_TYPE_FIXED_WING = 1
MAV_AUTOPILOT_GENERIC = 0
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_INVALID = 8
FLAG_CUSTOM_MODE = 1
FLAG_ARMED = 128
MAV_STATE_STANDBY = 3

MODES = {"QSTABILIZE": 17, "QHOVER": 18, "QLOITER": 19, "QLAND": 20}

MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_UNSUPPORTED = 3

MSG_ATTITUDE = 30
MSG_LOCAL_POSITION_NED = 32
MSG_SERVO_OUTPUT_RAW = 36

LISTEN_RE = re.compile(r"^listening\s+(?P<scheme>[a-z]+):(?P<addr>\S+)\s*$")


def f32(x: float) -> float:
    """The float32 nearest to x, as a Python float (what PARAM_VALUE carries)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


# Hovering, ATTITUDE is ArduPlane's VTOL view of a tailsitter (docs/compatibility.md): the
# fixed-wing frame pitched 90° down, so upright on the tail reads roll 0°, pitch 0°, its x axis
# through the belly and its z axis along the nose reversed (the thrust axis, down).


def _thrust_axis_ned(a) -> tuple[float, float, float]:
    """The nose (thrust axis, up in a hover) in NED, from a VTOL-view ATTITUDE: minus its z axis."""
    sr, cr = math.sin(a.roll), math.cos(a.roll)
    sp, cp = math.sin(a.pitch), math.cos(a.pitch)
    sy, cy = math.sin(a.yaw), math.cos(a.yaw)
    # Third column of Rz(yaw)·Ry(pitch)·Rx(roll), negated.
    return (-(cr * sp * cy + sr * sy), -(cr * sp * sy - sr * cy), -(cr * cp))


def tilt_rad(a) -> float:
    """How far the nose (the thrust axis) leans from vertical, rad (a VTOL-view ATTITUDE)."""
    return math.acos(max(-1.0, min(1.0, -_thrust_axis_ned(a)[2])))


def nose_lean_rad(a, bearing_rad: float) -> float:
    """How far the nose leans from vertical toward the horizontal bearing `bearing_rad`, rad
    (a VTOL-view ATTITUDE)."""
    n, e, _ = _thrust_axis_ned(a)
    return math.asin(max(-1.0, min(1.0, n * math.cos(bearing_rad) + e * math.sin(bearing_rad))))


def belly_heading_rad(a) -> float:
    """The heading of the belly, rad: a hover's heading, the yaw of a VTOL-view ATTITUDE."""
    return a.yaw


# --------------------------------------------------------------------------------------------
# The twin as a subprocess
# --------------------------------------------------------------------------------------------


class Twin(ManagedProcess):
    """`firmware-sim serve`: one `listening <scheme>:<addr>` line per --listen."""

    KIND = "twin"
    ENDPOINT_RE = LISTEN_RE
    ENDPOINT_WORD = "listener"
    param_file: Path

    @property
    def listeners(self) -> list[tuple[str, str]]:
        """(scheme, address) as printed."""
        return self.endpoints


def start_twin(
    workdir: Path,
    listen: Iterable[str] = ("tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"),
    speed: float | None = None,
    seed: int = 1,
    param_file: Path | None = None,
    extra: Iterable[str] = (),
    startup_timeout: float = 30.0,
) -> Twin:
    assert TWIN_BIN.exists(), f"{TWIN_BIN} missing: build it with `cargo build -p firmware-sim`"
    listen = list(listen)
    param_file = param_file or workdir / "params.parm"
    args = [str(TWIN_BIN), "serve"]
    for url in listen:
        args += ["--listen", url]
    if speed is not None:
        args += ["--speed", f"{speed:g}"]
    args += ["--seed", str(seed), "--param-file", str(param_file), *extra]
    return Twin.spawn(args, workdir, len(listen), startup_timeout, param_file=param_file)


# Starts twins on demand (`TwinFactory(base)`); the fixtures stop every one (checking a clean exit).
TwinFactory = partial(ProcessFactory, start=start_twin, prefix="twin")
twin_factory, module_twin_factory = factory_fixtures(start_twin, "twin")


@pytest.fixture(scope="module")
def twin(module_twin_factory):
    """One twin for a whole module, at 4x speed (for tests that do not measure timing)."""
    return module_twin_factory(speed=4)


# --------------------------------------------------------------------------------------------
# A pymavlink GCS with deadline-bounded waits
# --------------------------------------------------------------------------------------------


class Timeout(AssertionError):
    pass


class Gcs:
    """A pymavlink connection acting as a GCS (sysid 255).

    It sends a GCS HEARTBEAT at 1 Hz while it waits, as a real GCS does; on UDP this is also how
    the twin learns our address.
    """

    def __init__(self, url: str, **kw):
        kw.setdefault("source_system", GCS_SYSID)
        kw.setdefault("source_component", GCS_COMPID)
        self.url = url
        self.m = mavutil.mavlink_connection(url, **kw)
        self._last_beat = 0.0
        self.beat(force=True)

    def close(self) -> None:
        self.m.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def mav(self):
        return self.m.mav

    def beat(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self._last_beat >= 1.0:
            self._last_beat = now
            self.m.mav.heartbeat_send(MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def drain(self) -> int:
        """Drops whatever already arrived (e.g. echoes broadcast for another client's write), so
        that the next wait sees only replies to what we send next."""
        n = 0
        while self.m.recv_match(blocking=False) is not None:
            n += 1
        return n

    def recv(
        self,
        types: str | list[str],
        pred: Callable | None = None,
        timeout: float = 10.0,
        sysid: int | None = VEHICLE_SYSID,
        what: str = "",
    ):
        """First message of `types` from `sysid` for which pred(msg) holds; AssertionError after
        `timeout` seconds."""
        types_l = [types] if isinstance(types, str) else list(types)
        deadline = time.monotonic() + timeout
        last = None
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise Timeout(
                    f"no {types_l} {what} within {timeout} s on {self.url} (last of type: {last})"
                )
            self.beat()
            msg = self.m.recv_match(type=types_l, blocking=True, timeout=min(left, 0.25))
            if msg is None:
                continue
            if sysid is not None and msg.get_srcSystem() != sysid:
                continue
            last = msg
            if pred is None or pred(msg):
                return msg

    def collect(self, types, until: Callable[[list], bool], timeout: float, pred=None) -> list:
        """Messages of `types` (from the vehicle) until until(list) is true; AssertionError on
        timeout."""
        out: list = []
        deadline = time.monotonic() + timeout
        while not until(out):
            left = deadline - time.monotonic()
            if left <= 0:
                raise Timeout(f"collect {types}: condition not met in {timeout} s ({len(out)} msgs)")
            msg = self.recv(types, pred=pred, timeout=left)
            out.append(msg)
        return out

    # -- vehicle ------------------------------------------------------------------------------

    def wait_vehicle_heartbeat(self, timeout: float = 15.0, pred=None):
        """The vehicle's heartbeat (never a GCS one: PROTOCOL.md C.3)."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise Timeout(f"no vehicle HEARTBEAT within {timeout} s on {self.url}")
            self.beat()
            msg = self.m.recv_match(
                type="HEARTBEAT", condition="HEARTBEAT.type!=6", blocking=True, timeout=min(left, 0.25)
            )
            if msg is None or msg.get_srcSystem() != VEHICLE_SYSID:
                continue
            if pred is None or pred(msg):
                return msg

    def wait_ready(self, timeout: float = 30.0):
        """Heartbeat with system_status STANDBY: calibration done, ready to arm."""
        return self.wait_vehicle_heartbeat(timeout, pred=lambda h: h.system_status == MAV_STATE_STANDBY)

    def command(self, cmd: int, *params: float, timeout: float = 10.0):
        p = list(params) + [0.0] * (7 - len(params))
        self.drain()
        self.m.mav.command_long_send(VEHICLE_SYSID, VEHICLE_COMPID, cmd, 0, *p)
        return self.recv("COMMAND_ACK", lambda a: a.command == cmd, timeout, what=f"for command {cmd}")

    def set_interval(self, msg_id: int, hz: float):
        ack = self.command(MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)
        assert ack.result == MAV_RESULT_ACCEPTED, f"SET_MESSAGE_INTERVAL({msg_id}) → {ack}"
        return ack

    def arm(self):
        ack = self.command(MAV_CMD_COMPONENT_ARM_DISARM, 1)
        assert ack.result == MAV_RESULT_ACCEPTED, f"arm refused: {ack}"
        return ack

    def set_mode(self, name: str):
        ack = self.command(MAV_CMD_DO_SET_MODE, FLAG_CUSTOM_MODE, MODES[name])
        assert ack.result == MAV_RESULT_ACCEPTED, f"mode {name} refused: {ack}"
        return ack

    # -- parameters ---------------------------------------------------------------------------

    def param_get(self, name: str, timeout: float = 10.0):
        self.drain()
        self.m.mav.param_request_read_send(VEHICLE_SYSID, VEHICLE_COMPID, name.encode(), -1)
        return self.recv("PARAM_VALUE", lambda p: p.param_id == name, timeout, what=name)

    def param_set(self, name: str, value: float, timeout: float = 10.0):
        """PARAM_SET of an acceptable value and its PARAM_VALUE echo (the only acknowledgement),
        recognised by name and the stored value (float32, or rounded for integer types): an echo
        broadcast earlier for another client's write may still be on its way."""
        self.drain()
        self.m.param_set_send(name, value)

        def is_echo(p):
            if p.param_id != name:
                return False
            return p.param_value == (f32(value) if p.param_type == 9 else float(round(value)))

        return self.recv("PARAM_VALUE", is_echo, timeout, what=f"echo of {name}={value}")


@pytest.fixture
def gcs_factory():
    conns: list[Gcs] = []

    def make(url: str, **kw) -> Gcs:
        g = Gcs(url, **kw)
        conns.append(g)
        return g

    yield make
    for g in conns:
        g.close()


# --------------------------------------------------------------------------------------------
# Flight helpers
# --------------------------------------------------------------------------------------------


def wait_hover(gcs: Gcs, alt: float, tol: float = 0.05, settle_s: float = 2.0, window_s: float = 5.0,
               timeout: float = 90.0):
    """Wait until LOCAL_POSITION_NED has stayed within alt ± tol for `settle_s` seconds of vehicle
    time (time_boot_ms), then return the samples of the following `window_s` seconds, which the
    caller checks strictly."""
    run: list = []
    deadline = time.monotonic() + timeout
    last = None
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise Timeout(f"not within {alt} ± {tol} m for {settle_s} s after {timeout} s; last sample {last}")
        p = gcs.recv("LOCAL_POSITION_NED", timeout=left)
        last = p
        if abs(-p.z - alt) > tol:
            run = []
            continue
        run.append(p)
        if run[-1].time_boot_ms - run[0].time_boot_ms >= settle_s * 1000:
            break
    window = [gcs.recv("LOCAL_POSITION_NED")]
    while window[-1].time_boot_ms - window[0].time_boot_ms < window_s * 1000:
        window.append(gcs.recv("LOCAL_POSITION_NED"))
    return window


def take_off(gcs: Gcs, alt: float | None = None, pos_hz: float = 20.0):
    """Arm, QHOVER, wait for a steady hover at HOVER_ALT. Returns the hover window."""
    if alt is None:
        alt = gcs.param_get("HOVER_ALT").param_value
    gcs.set_interval(MSG_LOCAL_POSITION_NED, pos_hz)
    gcs.wait_ready()
    gcs.arm()
    gcs.set_mode("QHOVER")
    window = wait_hover(gcs, alt)
    assert all(abs(-p.z - alt) <= 0.05 for p in window), [round(-p.z, 3) for p in window]
    return window


def is_finite(x: float) -> bool:
    return not (math.isnan(x) or math.isinf(x))
