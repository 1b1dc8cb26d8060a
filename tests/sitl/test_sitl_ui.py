"""The terminal UI flies ArduPlane SITL's QuadPlane tailsitter, as a user would: `vtol-gcs tui
--vehicle tcp:…` in a real terminal (tmux, 100x32), every mode change and arming by key. A pilot's
RC transmitter holds the throttle stick (RC_CHANNELS_OVERRIDE on SITL's second port, as a
transmitter's receiver would feed it): ArduPlane's QHOVER and QLOITER climb on the stick and hold
at mid-stick. Skipped unless `ARDUPILOT_SITL` names the arduplane binary (tests/sitl/sitl.py).

    ARDUPILOT_SITL=.../build/sitl/bin/arduplane VTOL_GCS_BIN=target/release/vtol-gcs \\
        VTOL_GCS_SITL_CAPTURES=docs/captures/sitl .venv/bin/python -m pytest -s tests/sitl/test_sitl_ui.py

The flight: QHOVER from the mode picker, arm, climb on the stick to 20 m; QLOITER (`p`); a forward
transition to CRUISE from the mode picker, on the wing; back to QLOITER from the picker (a back
transition); QLAND (`l`), landed and disarmed. At each step the screen shows the mode, the VTOL
state and the attitude in the frame it says; `VTOL_GCS_SITL_CAPTURES=DIR` keeps each screen.
"""

from __future__ import annotations

import os
import shlex
import sys
import threading
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "pymavlink"))
os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

from sitl import SITL_BIN, Sitl  # noqa: E402
from test_tui import GCS_BIN, screen_factory  # noqa: E402,F401 (fixture)

pytestmark = pytest.mark.skipif(not SITL_BIN, reason="ARDUPILOT_SITL does not name an arduplane binary")

MAV = mavutil.mavlink
ALT = r"Alt\s+([+-]\d+\.\d+) m"
PITCH = r"Pitch\s+([+-]\d+\.\d+)°"
ROLL = r"Roll\s+([+-]\d+\.\d+)°"


class Pilot:
    """An RC transmitter: RC_CHANNELS_OVERRIDE at 10 Hz on SITL's second port, sticks centred,
    the throttle where `throttle` says (µs)."""

    def __init__(self, url: str):
        self.m = mavutil.mavlink_connection(url, source_system=255, source_component=190)
        assert self.m.wait_heartbeat(timeout=60) is not None
        self.throttle = 1000
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        while not self.stop.wait(0.1):
            self.m.mav.rc_channels_override_send(1, 1, 1500, 1500, self.throttle, 1500, 0, 0, 0, 0)
            while self.m.recv_match(blocking=False) is not None:
                pass

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        self.m.close()


def keep(name: str, text: str) -> None:
    if d := os.environ.get("VTOL_GCS_SITL_CAPTURES"):
        Path(d).mkdir(parents=True, exist_ok=True)
        (Path(d) / f"{name}.txt").write_text("\n".join(line.rstrip() for line in text.splitlines()) + "\n")


def pick(s, mode: str) -> None:
    """The mode picker: `m`, the name typed, Enter."""
    s.keys("m")
    s.wait(r"filter:")
    s.keys(*mode.lower())
    s.wait(rf"▶?\s*{mode}\b")
    s.keys("Enter")


def test_the_ui_flies_the_tailsitter(screen_factory):  # noqa: F811
    with Sitl(speedup=1) as sitl:
        sitl.reboot_once()
        pilot = Pilot(sitl.url1)
        try:
            s = screen_factory(f"{shlex.quote(str(GCS_BIN))} tui --vehicle {sitl.url} --no-log",
                               width=100, height=32)
            # The parameters are in (the tailsitter is known) and the vehicle is ready.
            s.wait(r"Horizon \((wing|hover) frame\)", 120)
            s.wait(r"health ok", 120)
            keep("1-ground-manual", s.text())

            pick(s, "QHOVER")
            s.wait(r"sys 1 QHOVER", 15)
            s.wait(r"Horizon \(hover frame\)", 15)
            # Upright on the ground: a level horizon in the hover frame.
            s.wait_value(PITCH, lambda p: abs(p) < 5, 15, "pitch upright")
            keep("2-ground-qhover", s.text())
            t0 = time.monotonic()
            while True:
                s.keys("a")
                s.wait(r"y\b", 5)
                s.keys("y")
                try:
                    s.wait(r"QHOVER ARMED", 10)
                    break
                except AssertionError:
                    # Not ready to arm yet (the EKF settling): the refusal is on the screen.
                    assert time.monotonic() - t0 < 120, s.text()
            pilot.throttle = 1800
            s.wait_value(ALT, lambda a: a > 15, 90, "climb to 15 m")
            pilot.throttle = 1500
            keep("3-hover-climbed", s.text())

            s.keys("p")
            s.wait(r"sys 1 QLOITER", 15)
            s.wait(r"VTOL\s+MC", 15)
            keep("4-qloiter", s.text())

            pick(s, "CRUISE")
            s.wait(r"sys 1 CRUISE", 15)
            s.wait(r"VTOL\s+(→FW|FW)", 15)
            s.wait(r"VTOL\s+FW\b", 60)
            s.wait(r"Horizon \(wing frame\)", 15)
            # On the wing: the pitch a few tens of degrees at most, in the wing frame.
            s.wait_value(PITCH, lambda p: abs(p) < 45, 30, "pitch on the wing")
            keep("5-cruise-wing", s.text())

            pick(s, "QLOITER")
            s.wait(r"sys 1 QLOITER", 15)
            s.wait(r"VTOL\s+MC", 60)
            s.wait(r"Horizon \(hover frame\)", 15)
            keep("6-back-in-qloiter", s.text())

            s.keys("l")
            s.wait(r"sys 1 QLAND", 15)
            s.wait(r"QLAND disarmed", 180)
            keep("7-landed", s.text())
            s.keys("q")
            s.assert_exited_cleanly()
        finally:
            pilot.close()
