"""Real autopilots other than the twin, as the daemon and `vtol-gcs mode` meet them: a vehicle
whose HEARTBEAT names a MAV_TYPE the dialect does not define is still heard (its mode shown as a
number), an ArduCopter's modes read and are set by Copter's names and numbers, and a PX4's by its
main and sub modes (MAV_CMD_DO_SET_MODE with the custom-mode flag). The vehicle here is a
pymavlink peer speaking as each autopilot: it beats, and acknowledges and applies mode changes."""

from __future__ import annotations

import threading
import time

import pytest
from pymavlink import mavutil

from daemon_support import start_daemon
from test_first_hour import gcs

mavlink = mavutil.mavlink


class Autopilot:
    """A vehicle (1, 1) that beats every 0.2 s as `kind` = (MAV_TYPE, MAV_AUTOPILOT) in
    `custom_mode`, and applies MAV_CMD_DO_SET_MODE as ArduPilot or PX4 read it."""

    def __init__(self):
        self.m = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=1, source_component=1)
        self.port = self.m.port.getsockname()[1]
        self.kind = (60, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
        self.custom_mode = 7
        self.set_modes: list[tuple[float, float, float]] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        next_beat = 0.0
        while not self.stop.is_set():
            now = time.monotonic()
            # udpin learns its peer from the daemon's first frame (it speaks first).
            if now >= next_beat:
                next_beat = now + 0.2
                if self.m.clients:
                    self.m.mav.heartbeat_send(self.kind[0], self.kind[1], 0x81, self.custom_mode,
                                              mavlink.MAV_STATE_ACTIVE)
            msg = self.m.recv_match(blocking=True, timeout=0.05)
            if msg is None or msg.get_type() != "COMMAND_LONG" or msg.command != mavlink.MAV_CMD_DO_SET_MODE:
                continue
            self.set_modes.append((msg.param1, msg.param2, msg.param3))
            if self.kind[1] == mavlink.MAV_AUTOPILOT_PX4:
                self.custom_mode = (int(msg.param2) << 16) | (int(msg.param3) << 24)
            else:
                self.custom_mode = int(msg.param2)
            self.m.mav.command_ack_send(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_RESULT_ACCEPTED, 255, 0,
                                        msg.get_srcSystem(), msg.get_srcComponent())

    def close(self):
        self.stop.set()
        self.thread.join(timeout=5)
        self.m.close()


@pytest.fixture
def vehicle_and_daemon(tmp_path):
    ap = Autopilot()
    daemon = start_daemon(tmp_path, vehicle=f"udpout:127.0.0.1:{ap.port}", serve=["tcpin:127.0.0.1:0"], log=False)
    try:
        yield ap, daemon
    finally:
        daemon.stop()
        ap.close()


def test_a_type_the_dialect_lacks_then_arducopter_then_px4(vehicle_and_daemon):
    ap, daemon = vehicle_and_daemon
    # MAV_TYPE 60: heard, its mode as the number.
    daemon.wait_line(r"^sys 1 MODE\(7\) ARMED", timeout=15)
    r = gcs("mode", "LOITER", "--link", daemon.tcp)
    assert r.returncode == 2 and "not known" in r.stderr, r.stderr
    r = gcs("mode", "9", "--link", daemon.tcp)
    assert r.returncode == 0 and r.stdout == "mode MODE(9)\n", r.stdout + r.stderr
    assert ap.set_modes[-1] == (1.0, 9.0, 0.0)

    # ArduCopter: custom_mode 5 is LOITER; GUIDED is 4.
    ap.kind, ap.custom_mode = (mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA), 5
    daemon.wait_line(r"^sys 1 LOITER ARMED", timeout=15)
    r = gcs("mode", "guided", "--link", daemon.tcp)
    assert r.returncode == 0 and r.stdout == "mode GUIDED\n", r.stdout + r.stderr
    assert ap.set_modes[-1] == (1.0, 4.0, 0.0)
    daemon.wait_line(r"^sys 1 GUIDED ARMED", timeout=15)
    r = gcs("mode", "QHOVER", "--link", daemon.tcp)
    assert r.returncode == 2 and "ArduCopter" in r.stderr and "LOITER (5)" in r.stderr, r.stderr

    # PX4: main mode 3 (POSCTL); MISSION is AUTO (4) with sub mode 4.
    ap.kind, ap.custom_mode = (mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4), 3 << 16
    daemon.wait_line(r"^sys 1 POSCTL ARMED", timeout=15)
    r = gcs("mode", "Mission", "--link", daemon.tcp)
    assert r.returncode == 0 and r.stdout == "mode MISSION\n", r.stdout + r.stderr
    assert ap.set_modes[-1] == (1.0, 4.0, 4.0)
    daemon.wait_line(r"^sys 1 MISSION ARMED", timeout=15)
