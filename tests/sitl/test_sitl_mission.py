"""A mission flown by ArduPlane SITL's QuadPlane tailsitter from the ground station, as a user
would: `vtol-gcs mission upload` (a QGC WPL 110 file: a VTOL take-off to 20 m, a 200 m box on the
wing, a VTOL landing at home after a 100 m leg), `mission download` equal to the file, `mode AUTO`
and `arm`, all through `vtol-gcs run`; the flight watched on SITL's second port
(MISSION_ITEM_REACHED, EXTENDED_SYS_STATE). Skipped unless `ARDUPILOT_SITL` names the arduplane
binary (tests/sitl/sitl.py). The times of each command and of each item reached are printed.

    ARDUPILOT_SITL=.../build/sitl/bin/arduplane VTOL_GCS_BIN=target/release/vtol-gcs \\
        .venv/bin/python -m pytest -s -c tests/sitl/pytest.ini tests/sitl/test_sitl_mission.py

SITL runs at `--speedup 5`. Its `plane-tailsitter` model cannot fly on the wing (ArduPilot's
autotest lists it as "unstable in hover; unflyable in cruise"): after the transition it touches
the ground again and again ("SIM Hit ground") and seldom reaches the box's first corner. The test
asks for what ArduPlane does with the mission whatever the model: the upload and the download
equal, AUTO and the arming accepted, the VTOL take-off item reached, and the transition to the
wing after it; the items reached afterwards in the next minute of flight are printed.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "pymavlink"))
os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

from daemon_support import DAEMON_BIN, start_daemon  # noqa: E402
from sitl import SITL_BIN, Sitl  # noqa: E402

pytestmark = pytest.mark.skipif(not SITL_BIN, reason="ARDUPILOT_SITL does not name an arduplane binary")

MAV = mavutil.mavlink
SPEEDUP = 5


def gcs(*args: str, link: str, timeout: float = 120.0) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    r = subprocess.run([str(DAEMON_BIN), *args, "--link", link, "--target", "1"], capture_output=True,
                       text=True, timeout=timeout)
    took = time.monotonic() - t0
    print(f"\n  vtol-gcs {' '.join(args)}: exit {r.returncode} in {took:.2f} s: {r.stdout.strip()[-200:]}")
    return r, took


def box(home: tuple[float, float, float]) -> str:
    """QGC WPL 110: home, VTOL take-off, a 200 m box north-east of home, a VTOL landing at home."""
    lat, lon, alt = home
    dlat = 200 / 111_320
    dlon = 200 / (111_320 * math.cos(math.radians(lat)))
    rows = [
        (0, 1, 0, 16, lat, lon, alt),
        (1, 0, 3, 84, 0, 0, 20),
        (2, 0, 3, 16, lat + dlat, lon, 20),
        (3, 0, 3, 16, lat + dlat, lon + dlon, 20),
        (4, 0, 3, 16, lat, lon + dlon, 20),
        (5, 0, 3, 16, lat, lon + dlon / 2, 20),
        (6, 0, 3, 85, lat, lon, 0),
    ]
    return "QGC WPL 110\n" + "".join(
        f"{seq}\t{cur}\t{frame}\t{cmd}\t0\t0\t0\t0\t{x:.7f}\t{y:.7f}\t{z:.2f}\t1\n"
        for seq, cur, frame, cmd, x, y, z in rows
    )


def test_a_mission_uploaded_downloaded_and_flown(tmp_path):
    with Sitl(speedup=SPEEDUP) as sitl:
        sitl.reboot_once()
        d = start_daemon(tmp_path / "daemon", vehicle=sitl.url, serve=["tcpin:127.0.0.1:0"], log=False)
        try:
            link = f"tcp:{d.serving[0][1]}"
            m = mavutil.mavlink_connection(sitl.url1, source_system=250, source_component=190)
            assert m.wait_heartbeat(timeout=60) is not None
            m.mav.request_data_stream_send(1, 1, MAV.MAV_DATA_STREAM_ALL, 4, 1)
            # EXTENDED_SYS_STATE is in no stream group of ArduPlane's: asked for by interval.
            m.mav.command_long_send(1, 1, MAV.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                    MAV.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 200_000, 0, 0, 0, 0, 0)
            home = m.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=30)
            assert home is not None
            path = tmp_path / "box.waypoints"
            path.write_text(box((home.lat / 1e7, home.lon / 1e7, home.alt / 1e3)))

            r, _ = gcs("mission", "upload", str(path), link=link)
            assert r.returncode == 0, r.stderr
            back = tmp_path / "back.waypoints"
            r, _ = gcs("mission", "download", str(back), link=link)
            assert r.returncode == 0, r.stderr
            rows = lambda p: [line.split("\t")[3:] for line in p.read_text().splitlines()[2:]]  # noqa: E731
            # Every item after home as written (home is the vehicle's own: ArduPilot's altitude).
            assert [[round(float(v), 5) for v in row] for row in rows(back)] == \
                [[round(float(v), 5) for v in row] for row in rows(path)]

            # Armed in AUTO once the EKF is ready (ArduPlane refuses until then).
            r, _ = gcs("mode", "AUTO", link=link)
            assert r.returncode == 0, r.stderr
            t0 = time.monotonic()
            while True:
                r, _ = gcs("arm", link=link)
                if r.returncode == 0:
                    break
                assert time.monotonic() - t0 < 120, r.stderr
            start = time.monotonic()
            reached, states, texts = {}, [], []
            on_wing_at = None
            while 6 not in reached and time.monotonic() - start < 300 / SPEEDUP + 60:
                if on_wing_at is not None and time.monotonic() - on_wing_at > 60 / SPEEDUP:
                    break
                msg = m.recv_match(type=["MISSION_ITEM_REACHED", "MISSION_CURRENT", "EXTENDED_SYS_STATE",
                                         "STATUSTEXT"], blocking=True, timeout=1)
                if msg is None:
                    continue
                if msg.get_type() == "STATUSTEXT":
                    texts.append(f"{(time.monotonic() - start) * SPEEDUP:.0f} s {msg.text}")
                if msg.get_type() == "MISSION_ITEM_REACHED" and msg.seq not in reached:
                    reached[msg.seq] = time.monotonic() - start
                    print(f"  item {msg.seq} reached at {reached[msg.seq] * SPEEDUP:.0f} s of flight")
                elif msg.get_type() == "MISSION_CURRENT" and msg.seq == 6 and 5 in reached:
                    reached.setdefault(6, time.monotonic() - start)
                elif msg.get_type() == "EXTENDED_SYS_STATE" and (not states or states[-1] != msg.vtol_state):
                    states.append(msg.vtol_state)
                    if msg.vtol_state == MAV.MAV_VTOL_STATE_FW and 1 in reached and on_wing_at is None:
                        on_wing_at = time.monotonic()
                        print(f"  on the wing at {(on_wing_at - start) * SPEEDUP:.0f} s of flight")
            print(f"  VTOL states {states}")
            print("  " + "\n  ".join(texts[-25:]))
            print(f"  items reached: {sorted(reached)}")
            assert 1 in reached, reached
            # After the VTOL take-off, a transition to the wing for the waypoints, as ArduPlane
            # flies a mission.
            after = states[states.index(MAV.MAV_VTOL_STATE_MC):] if MAV.MAV_VTOL_STATE_MC in states else []
            assert MAV.MAV_VTOL_STATE_TRANSITION_TO_FW in after and MAV.MAV_VTOL_STATE_FW in after, states
            m.close()
        finally:
            d.stop()
