"""The terminal UI's views on the smallest terminal it supports (80x24), end to end: the real
`vtol-gcs` binary in tmux with the embedded twin. Every view shows its column titles and
values whole, enums in words; a script flying the vehicle in GUIDED sees its target on the
Flight view as the vehicle sends it back (POSITION_TARGET_GLOBAL_INT); a low battery shows its
failsafe banner and the battery in yellow while the vehicle lands.

Every wait is "until the screen shows it, with a deadline", never a sleep.
"""

from __future__ import annotations

import shlex

from conftest import FLAG_CUSTOM_MODE, MAV_CMD_DO_SET_MODE, MAV_RESULT_ACCEPTED, Gcs
from test_tui import GCS_BIN, screen_factory  # noqa: F401 (fixture)
from test_zenoh_fleet import free_tcp_port

MAV_FRAME_LOCAL_NED = 1
GUIDED = 15
# Only x, y, z used.
POSITION_ONLY = 0b110111111000


def test_every_view_at_80x24_and_the_live_target(screen_factory):  # noqa: F811
    port = free_tcp_port()
    s = screen_factory(
        f"{shlex.quote(str(GCS_BIN))} tui --serve tcpin:127.0.0.1:{port} --no-log",
        width=80,
        height=24,
    )
    s.wait(r"Horizon")
    s.wait(r"STANDBY", 30)
    s.wait(r"elevator\s+1\d{3} µs")  # every output on its row, under the horizon

    s.keys("Tab")
    s.wait(r"Position \(m\): alt (N|north) (E|east)")  # the legend in the title
    s.wait(r"Surfaces \(µs\): L ail R ail elev")
    s.keys("Tab")
    s.wait(r"id\s+side\s+peer\s+Hz\s+loss%\s+heard\s+rx\s+tx\s+drop\s+crc")
    s.keys("Tab")
    s.wait(r"autopilot\s+ardupilotmega")  # enums in words
    s.wait(r"system_status\s+(standby|active)")
    s.keys("Tab")
    s.wait(r"name\s+value\s+status")
    s.wait(r"BATT_CAPACITY\s+1300")
    s.keys("Tab")
    s.wait(r"Fleet: 1 vehicle, 0 lost")
    s.keys("Tab")
    s.wait(r"Map\s+10 m/cell\s+following")
    s.wait(r"N↑")  # drawn once the twin's GLOBAL_POSITION_INT placed the vehicle
    s.wait(r"├─+┤ 100 m")
    s.keys("Tab")
    s.wait(r"Horizon")

    with Gcs(f"tcp:127.0.0.1:{port}") as g:
        g.wait_ready(timeout=15)
        g.param_set("Q_GUIDED_MODE", 1)  # GUIDED targets held in a hover (0 flies them on the wing)
        g.set_mode("QHOVER")
        g.arm()
        g.recv("LOCAL_POSITION_NED", lambda p: -p.z > 0.5, timeout=30, what="climbing")
        ack = g.command(MAV_CMD_DO_SET_MODE, FLAG_CUSTOM_MODE, GUIDED)
        assert ack.result == MAV_RESULT_ACCEPTED, ack
        s.wait(r"GUIDED")
        g.mav.set_position_target_local_ned_send(
            0, 1, 1, MAV_FRAME_LOCAL_NED, POSITION_ONLY, 1.0, 0.5, -1.5, 0, 0, 0, 0, 0, 0, 0, 0
        )
        s.wait(r"North\s+[+-]\d+\.\d+ m\s+setpoint\s+\+1\.00 m", 15)
        s.wait(r"East\s+[+-]\d+\.\d+ m\s+setpoint\s+\+0\.50 m")
        s.wait(r"Alt\s+[+-]\d+\.\d+ m\s+setpoint\s+\+1\.50 m")
        s.wait(r"setpoint: the vehicle's live target")
        s.keys("l")
        g.recv("HEARTBEAT", lambda h: h.custom_mode == 20, timeout=10, what="QLAND from the UI")
    s.keys("q")
    s.assert_exited_cleanly()


def test_a_low_battery_in_the_terminal(screen_factory):  # noqa: F811
    """A script lowers the low-battery threshold just under the pack's capacity (BATT_LOW_MAH,
    land on low): a few seconds into the hover the 80x24 screen shows the failsafe banner, the
    battery in yellow and QLAND, and the vehicle lands by itself."""
    port = free_tcp_port()
    s = screen_factory(
        f"{shlex.quote(str(GCS_BIN))} tui --serve tcpin:127.0.0.1:{port} --no-log",
        width=80,
        height=24,
    )
    s.wait(r"STANDBY", 30)
    with Gcs(f"tcp:127.0.0.1:{port}") as g:
        g.wait_ready(timeout=15)
        g.param_set("BATT_LOW_MAH", 1296)
        g.param_set("BATT_FS_LOW_ACT", 2)
        g.set_mode("QHOVER")
        g.arm()
        s.wait(r"Battery failsafe: QLAND", 30)
        s.wait(r"vtol-gcs\s+sys 1 QLAND")
        # BAT right after an SGR that turns the foreground yellow (33, or 3 of 256 colours).
        s.wait(r"\x1b\[(?:[0-9;]*;)?(?:33|38;5;3)m(?:\x1b\[[0-9;]*m)*BAT ", 10, escapes=True)
        g.recv("HEARTBEAT", lambda h: not h.base_mode & 128, timeout=60, what="landed, disarmed")
    s.wait(r"disarmed", 10)
    s.keys("q")
    s.assert_exited_cleanly()
