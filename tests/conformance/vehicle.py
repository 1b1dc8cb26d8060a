"""A vehicle link that records what the vehicle answered, for the conformance scenarios.

`Vehicle` is the pymavlink suite's `Gcs` (tests/pymavlink/conftest.py: a GCS at system 255 with
deadline-bounded waits and a 1 Hz heartbeat) plus a recorder: every frame the vehicle sends
passes through `_seen`, which keeps the STATUSTEXTs, the EXTENDED_SYS_STATE and mode sequences
and the latest vehicle time, and feeds the flight-phase windows. A scenario writes what it
observed into a `Trace`:

- `proto(key, value)`: protocol, compared exactly (results, mode numbers, message sets, types);
- `phys(key, value)`: physics, compared within the tolerance `compare.TOLERANCES` gives the key
  (times, positions, attitudes, speeds);
- `info(key, value)`: kept in the trace for a reader, never compared (texts, versions).

Nothing here knows which vehicle it talks to: the same calls run against ArduPlane SITL and the
twin. Waits are on events with a deadline, measured in vehicle time where the vehicle's clock
matters (both SITL's --speedup and the twin's --speed run faster than the wall).
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import socket
import statistics
import time
from contextlib import contextmanager
from pathlib import Path

os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def _load_pymavlink_conftest():
    """tests/pymavlink/conftest.py under its own module name (pytest registers conftest modules
    by file name, so importing it as `conftest` would clash with this folder's)."""
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "pymavlink"))  # its `from procs import ...`
    spec = importlib.util.spec_from_file_location("pymavlink_suite_conftest",
                                                  ROOT / "tests" / "pymavlink" / "conftest.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


suite = _load_pymavlink_conftest()
Gcs = suite.Gcs
Timeout = suite.Timeout

MAV = mavutil.mavlink

# ArduPlane's mode numbers (what both vehicles put in HEARTBEAT.custom_mode).
PLANE_MODES = {
    "MANUAL": 0, "CIRCLE": 1, "STABILIZE": 2, "TRAINING": 3, "ACRO": 4, "FBWA": 5, "FBWB": 6,
    "CRUISE": 7, "AUTOTUNE": 8, "AUTO": 10, "RTL": 11, "LOITER": 12, "TAKEOFF": 13, "GUIDED": 15,
    "QSTABILIZE": 17, "QHOVER": 18, "QLOITER": 19, "QLAND": 20, "QRTL": 21, "QAUTOTUNE": 22,
    "QACRO": 23, "THERMAL": 24,
}
MODE_NAMES = {v: k for k, v in PLANE_MODES.items()}
MAV_RESULTS = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED", 4: "FAILED",
               5: "IN_PROGRESS", 6: "CANCELLED"}
PREARM_HEALTHY = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK in SYS_STATUS's sensor bits

# Messages whose presence in the vehicle's streams the identify scenario records.
WATCHED = ["HEARTBEAT", "SYS_STATUS", "SYSTEM_TIME", "GPS_RAW_INT", "ATTITUDE", "GLOBAL_POSITION_INT",
           "LOCAL_POSITION_NED", "VFR_HUD", "EKF_STATUS_REPORT", "EXTENDED_SYS_STATE", "BATTERY_STATUS",
           "MISSION_CURRENT", "NAV_CONTROLLER_OUTPUT", "RC_CHANNELS", "SERVO_OUTPUT_RAW", "RAW_IMU",
           "SCALED_PRESSURE", "POWER_STATUS", "MEMINFO", "HOME_POSITION", "POSITION_TARGET_GLOBAL_INT",
           "VIBRATION", "AHRS", "TIMESYNC", "PARAM_VALUE", "STATUSTEXT"]

# Stream rates a scenario asks for (message id, Hz): what the phase summaries need.
INTERVALS = [(30, 10.0), (33, 5.0), (74, 5.0), (245, 5.0), (42, 2.0), (1, 2.0), (24, 2.0)]


def category(text: str) -> str:
    """A STATUSTEXT's category: its text with numbers as '#', e.g. 'PreArm: VTOL land too short,
    min #m'."""
    return re.sub(r"-?\d+(\.\d+)?", "#", text.strip())


def prefix(text: str) -> str:
    """'PreArm', 'Arm', … : the text before the first ':' (or the first word)."""
    head = text.split(":", 1)[0] if ":" in text else text.split(" ", 1)[0]
    return re.sub(r"\d+$", "", head.strip())


def wrap180(deg: float) -> float:
    return (deg + 180.0) % 360.0 - 180.0


def circ_median(values: list[float]) -> float | None:
    """Median of angles in degrees, taken around their circular mean (so 359 and 1 give 0)."""
    if not values:
        return None
    s = sum(math.sin(math.radians(v)) for v in values)
    c = sum(math.cos(math.radians(v)) for v in values)
    mean = math.degrees(math.atan2(s, c))
    return round(wrap180(mean + statistics.median(wrap180(v - mean) for v in values)), 2) % 360.0


def median(values: list[float]) -> float | None:
    return round(statistics.median(values), 3) if values else None


class Trace:
    """What one scenario observed, as a JSON-ready dict."""

    def __init__(self, scenario: str):
        self.data: dict = {"scenario": scenario, "protocol": {}, "physics": {}, "info": {}}

    def proto(self, key: str, value) -> None:
        self.data["protocol"][key] = value

    def phys(self, key: str, value) -> None:
        self.data["physics"][key] = value

    def info(self, key: str, value) -> None:
        self.data["info"][key] = value


class Vehicle(Gcs):
    """The pymavlink suite's GCS, recording what the vehicle sends."""

    def __init__(self, url: str, connect_timeout: float = 60.0):
        if url.startswith("tcp:"):
            _wait_tcp(url[4:], connect_timeout)
        super().__init__(url, autoreconnect=url.startswith("tcp:"))
        self.statustexts: list[dict] = []
        self.ext_states: list[tuple[int, int]] = []  # (vtol_state, landed_state), changes only
        self.modes: list[int] = []  # HEARTBEAT custom_mode, changes only
        self.first_commanded: int | None = None  # len(modes) at the scenario's first mode command
        self.armed_seen: list[bool] = []  # HEARTBEAT armed bit, changes only
        self.last: dict[str, object] = {}
        self.t_ms = 0  # latest vehicle time (time_boot_ms)
        self._windows: list[list] = []
        self._chunks: dict[int, list[str]] = {}
        self.m.mav.set_callback(self._seen)

    # -- a pilot's sticks -------------------------------------------------------------------

    def hold_sticks(self, throttle: int | None) -> None:
        """A pilot's transmitter: sticks centred, the throttle at `throttle` (PWM µs), sent as
        RC_CHANNELS_OVERRIDE at 20 Hz of wall time by a thread of its own (both vehicles drop an
        override 3 s of their time after its last refresh, a fraction of a second of the wall at
        their speed-ups); None releases them. The modes a pilot flies (QHOVER, QSTABILIZE,
        CRUISE) read the throttle stick, and neither SITL nor the twin has one of its own."""
        import threading

        stop = getattr(self, "_sticks_stop", None)
        if stop is not None:
            stop.set()
            self._sticks_thread.join(timeout=5)
            self._sticks_stop = None
        if throttle is None:
            self.m.mav.rc_channels_override_send(suite.VEHICLE_SYSID, suite.VEHICLE_COMPID, 0, 0, 0, 0, 0, 0, 0, 0)
            return
        stop = threading.Event()

        def send():
            while not stop.wait(0.05):
                self.m.mav.rc_channels_override_send(suite.VEHICLE_SYSID, suite.VEHICLE_COMPID,
                                                     1500, 1500, throttle, 1500, 0, 0, 0, 0)
        self._sticks_stop = stop
        self._sticks_thread = threading.Thread(target=send, daemon=True)
        self._sticks_thread.start()

    # -- the recorder ----------------------------------------------------------------------

    def _seen(self, msg, *_):
        if msg.get_srcSystem() != suite.VEHICLE_SYSID or msg.get_srcComponent() != suite.VEHICLE_COMPID:
            return
        t = msg.get_type()
        if t == "BAD_DATA":
            return
        self.last[t] = msg
        tb = getattr(msg, "time_boot_ms", None)
        if isinstance(tb, int) and t != "HOME_POSITION":
            self.t_ms = tb
        if t == "HEARTBEAT":
            if msg.type == suite.MAV_TYPE_GCS:
                return
            if not self.modes or self.modes[-1] != msg.custom_mode:
                self.modes.append(msg.custom_mode)
            armed = bool(msg.base_mode & suite.FLAG_ARMED)
            if not self.armed_seen or self.armed_seen[-1] != armed:
                self.armed_seen.append(armed)
        elif t == "EXTENDED_SYS_STATE":
            s = (msg.vtol_state, msg.landed_state)
            if not self.ext_states or self.ext_states[-1] != s:
                self.ext_states.append(s)
        elif t == "STATUSTEXT":
            text = msg.text
            cid = getattr(msg, "id", 0)
            if cid:  # a chunked text: whole once a chunk shorter than 50 characters arrives
                self._chunks.setdefault(cid, []).append(text)
                if len(text) >= 50:
                    return
                text = "".join(self._chunks.pop(cid))
            self.statustexts.append({"t_ms": self.t_ms, "severity": msg.severity, "text": text})
        for w in self._windows:
            w.append((self.t_ms, msg))

    def texts_since(self, mark: int) -> list[str]:
        return [s["text"] for s in self.statustexts[mark:]]

    def wait_vehicle_time(self, seconds: float, timeout: float = 120.0) -> None:
        """Reads until `seconds` of vehicle time have passed."""
        self.until(lambda: False, timeout=timeout, vehicle_s=seconds, what=f"{seconds} s of vehicle time",
                   ok_on_time=True)

    def until(self, cond, timeout: float = 60.0, vehicle_s: float | None = None, what: str = "",
              ok_on_time: bool = False) -> bool:
        """Reads until cond() holds. Bounded by `timeout` wall seconds, and by `vehicle_s` seconds
        of vehicle time if given; at that bound returns False when `ok_on_time`, else raises."""
        deadline = time.monotonic() + timeout
        start = self.t_ms
        while not cond():
            if vehicle_s is not None and self.t_ms - start >= vehicle_s * 1000:
                if ok_on_time:
                    return False
                raise Timeout(f"{what}: not within {vehicle_s} s of vehicle time")
            if time.monotonic() > deadline:
                raise Timeout(f"{what}: not within {timeout} s")
            try:
                self.beat()
                self.m.recv_match(blocking=True, timeout=0.1)
            except ConnectionError:
                # A vehicle that restarts closes its TCP side; pymavlink reconnects (autoreconnect).
                if hasattr(self.m, "reconnect"):
                    self.m.reconnect()
        return True

    @contextmanager
    def window(self):
        """Every message the vehicle sends while the block runs, as (t_ms, msg)."""
        w: list = []
        self._windows.append(w)
        try:
            yield w
        finally:
            self._windows.remove(w)

    # -- the vehicle's side ----------------------------------------------------------------

    def setup_streams(self) -> dict:
        """Asks for the streams the scenarios use; returns the SET_MESSAGE_INTERVAL results."""
        self.m.mav.request_data_stream_send(suite.VEHICLE_SYSID, suite.VEHICLE_COMPID,
                                            MAV.MAV_DATA_STREAM_ALL, 4, 1)
        out = {}
        for mid, hz in INTERVALS:
            out[str(mid)] = MAV_RESULTS.get(self.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, mid, 1e6 / hz).result)
        return out

    def heartbeat(self, timeout: float = 15.0):
        return self.wait_vehicle_heartbeat(timeout)

    def wait_armable(self, timeout: float = 180.0) -> None:
        """A 3D fix and the pre-arm checks passing (SYS_STATUS), as a GCS shows 'ready to arm'.
        ArduPlane SITL needs about 48 s of its time before its EKF uses GPS."""
        def ok():
            gps = self.last.get("GPS_RAW_INT")
            st = self.last.get("SYS_STATUS")
            return (gps is not None and gps.fix_type >= 3 and st is not None
                    and st.onboard_control_sensors_health & PREARM_HEALTHY
                    and st.onboard_control_sensors_enabled & PREARM_HEALTHY)
        self.until(ok, timeout=timeout, what="ready to arm (3D fix, pre-arm checks healthy)")

    def cmd(self, command: int, *params: float, timeout: float = 10.0) -> str:
        """A COMMAND_LONG; its ACK's result by name."""
        return MAV_RESULTS.get(self.command(command, *params, timeout=timeout).result, "?")

    def mode(self, name: str) -> str:
        if self.first_commanded is None:
            # Where the modes the scenario chose begin: at the current one if it is the mode
            # asked for, else at the next change.
            here = len(self.modes) - 1
            self.first_commanded = here if here >= 0 and self.modes[here] == PLANE_MODES[name] else here + 1
        return self.cmd(MAV.MAV_CMD_DO_SET_MODE, suite.FLAG_CUSTOM_MODE, PLANE_MODES[name])

    def wait_mode(self, name: str, timeout: float = 15.0) -> bool:
        n = PLANE_MODES[name]
        return self.until(lambda: self.modes and self.modes[-1] == n, timeout=timeout, ok_on_time=True,
                          vehicle_s=timeout, what=f"mode {name}")

    def armed(self) -> bool:
        return bool(self.armed_seen and self.armed_seen[-1])

    def arm(self, force: bool = False) -> str:
        return self.cmd(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196 if force else 0)

    def disarm(self) -> str:
        return self.cmd(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 0)

    def rel_alt(self) -> float:
        g = self.last.get("GLOBAL_POSITION_INT")
        return g.relative_alt / 1000.0 if g is not None else float("nan")

    def home(self) -> tuple[int, int, int]:
        """Home (lat, lon in 1e-7 degree, alt in mm above sea level), asked with
        MAV_CMD_REQUEST_MESSAGE."""
        self.cmd(MAV.MAV_CMD_REQUEST_MESSAGE, 242)
        h = self.recv("HOME_POSITION", timeout=10)
        return h.latitude, h.longitude, h.altitude

    # -- parameters ---------------------------------------------------------------------------

    def param_read(self, name: str, timeout: float = 5.0):
        """PARAM_VALUE for `name`, or None when the vehicle does not answer within `timeout`."""
        try:
            return self.param_get(name, timeout=timeout)
        except Timeout:
            return None

    def param_write(self, name: str, value: float, timeout: float = 5.0):
        """PARAM_SET and the vehicle's PARAM_VALUE for that name (the echo, whatever value it
        stored), or None."""
        self.drain()
        self.m.param_set_send(name, value)
        try:
            return self.recv("PARAM_VALUE", lambda p: p.param_id == name, timeout, what=f"echo of {name}")
        except Timeout:
            return None


def _wait_tcp(hostport: str, timeout: float) -> None:
    """Waits until something listens on `hostport` (a vehicle process that is still starting)."""
    host, port = hostport.rsplit(":", 1)
    deadline = time.monotonic() + timeout
    while True:
        try:
            socket.create_connection((host, int(port)), timeout=1).close()
            return
        except OSError:
            if time.monotonic() > deadline:
                raise Timeout(f"nothing listens on {hostport} after {timeout} s")
            time.sleep(0.2)  # polling a port that is not open yet; there is no event to wait on


def phase_summary(window: list, min_ground_speed: float = 1.0) -> dict:
    """Medians over a flight phase: roll, pitch, yaw (ATTITUDE, degrees), heading and airspeed
    (VFR_HUD), climb rate (VFR_HUD), course and ground speed (GLOBAL_POSITION_INT vx/vy), height above home, and the
    phase's length in vehicle time."""
    att = [m for _, m in window if m.get_type() == "ATTITUDE"]
    hud = [m for _, m in window if m.get_type() == "VFR_HUD"]
    gpi = [m for _, m in window if m.get_type() == "GLOBAL_POSITION_INT"]
    ts = [t for t, _ in window if t]
    moving = [g for g in gpi if math.hypot(g.vx, g.vy) / 100.0 >= min_ground_speed]
    return {
        "duration_s": round((ts[-1] - ts[0]) / 1000.0, 2) if len(ts) > 1 else 0.0,
        "roll_deg": median([math.degrees(a.roll) for a in att]),
        "pitch_deg": median([math.degrees(a.pitch) for a in att]),
        "yaw_deg": circ_median([math.degrees(a.yaw) % 360 for a in att]),
        "heading_deg": circ_median([float(h.heading) for h in hud]),
        "airspeed_m_s": median([h.airspeed for h in hud]),
        "groundspeed_m_s": median([math.hypot(g.vx, g.vy) / 100.0 for g in gpi]),
        "course_deg": circ_median([math.degrees(math.atan2(g.vy, g.vx)) % 360 for g in moving]),
        "rel_alt_m": median([g.relative_alt / 1000.0 for g in gpi]),
        "climb_m_s": median([h.climb for h in hud]),
    }
