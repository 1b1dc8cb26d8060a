"""Records the tlog behind the README's Figs 8-10: the twin, embedded in the daemon, hovers in
QSTABILIZE (attitude hold, throttle from the pilot) and is pushed on the roll, pitch and yaw axes
in turn through SIM_PUSH_ROLL / SIM_PUSH_PITCH / SIM_PUSH_YAW (200 ms torque pushes), 10 s apart.

The "pilot" is this script: it takes off in QHOVER, then holds the throttle stick with RC
overrides (channel 3) at the hover value, trimmed slowly on altitude as a pilot would, while
channels 1, 2 and 4 stay centred. Usage (from the repository root, binaries built):

    .venv/bin/python docs/figures/record_pushes.py target/debug/vtol-gcs OUT_DIR

It prints the tlog's path; `vtol-gcs log plot` draws it (see README).
"""

import os
import re
import subprocess
import sys
import time
from pathlib import Path

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

PUSHES = [("SIM_PUSH_ROLL", 0.1), ("SIM_PUSH_PITCH", 0.1), ("SIM_PUSH_YAW", 0.05)]
GAP_S = 10.0


def main(gcs_bin: str, out_dir: str) -> None:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = subprocess.Popen([gcs_bin, "run", "--headless", "--serve", "tcpin:127.0.0.1:0",
                          "--log-dir", str(out)], stdout=subprocess.PIPE, text=True)
    url = tlog = None
    while url is None or tlog is None:
        line = d.stdout.readline()
        if m := re.match(r"serving tcpin:(\S+)", line):
            url = "tcp:" + m[1]
        if m := re.match(r"logging (\S+)", line):
            tlog = m[1]
    m = mavutil.mavlink_connection(url, source_system=255, source_component=0)
    last_beat = 0.0
    z = vz = 0.0
    thr = 1460

    def pump(seconds: float, rc: bool) -> None:
        nonlocal last_beat, z, vz, thr
        end = time.monotonic() + seconds
        next_rc = 0.0
        while time.monotonic() < end:
            now = time.monotonic()
            if now - last_beat > 1:
                m.mav.heartbeat_send(6, 8, 0, 0, 0)
                last_beat = now
            if rc and now >= next_rc:
                # a pilot's slow altitude trim around the hover throttle
                thr = int(min(1700, max(1300, 1460 + 150 * (1.0 - z) - 60 * vz)))
                m.mav.rc_channels_override_send(1, 1, 1500, 1500, thr, 1500, 0, 0, 0, 0)
                next_rc = now + 0.05
            msg = m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=0.05)
            if msg is not None:
                z, vz = -msg.z, -msg.vz

    def command(cmd, *p, rc=False):
        p = list(p) + [0] * (7 - len(p))
        m.mav.command_long_send(1, 1, cmd, 0, *p)
        pump(0.5, rc)

    m.recv_match(type="HEARTBEAT", condition="HEARTBEAT.type!=6", blocking=True, timeout=10)
    # wait for the end of calibration (STANDBY), then take off in QHOVER
    while True:
        hb = m.recv_match(type="HEARTBEAT", condition="HEARTBEAT.type!=6", blocking=True, timeout=10)
        if hb is not None and hb.system_status == 3:
            break
    command(511, 32, 50000)  # LOCAL_POSITION_NED at 20 Hz
    command(400, 1)  # arm
    command(176, 1, 18)  # QHOVER
    pump(8.0, False)
    pump(1.0, True)  # the throttle stick is live before the switch
    command(176, 1, 17, rc=True)  # QSTABILIZE, pilot throttle from here on
    pump(4.0, True)
    for name, torque in PUSHES:
        m.mav.param_set_send(1, 1, name.encode(), torque, 9)
        pump(GAP_S, True)
    m.close()
    d.send_signal(2)
    d.wait(timeout=20)
    print(tlog)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
