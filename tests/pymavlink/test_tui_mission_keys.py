"""The Map view's mission keys end to end: the real `vtol-gcs` binary in tmux (100x30) with the
embedded twin. `u` uploads a QGC WPL 110 file typed on the prompt (after `y`), and the vehicle
holds it (read back with `vtol-gcs mission download` on the UI's serve port); the map draws it;
`n` makes item 3 current, which the Flight view's mission line then shows; `w` downloads the
mission into a file that holds the same items. Every wait is "until the screen shows it, with a
deadline", never a sleep.
"""

from __future__ import annotations

import shlex

from test_mission_cli import close, rows
from test_tui import GCS_BIN, screen_factory  # noqa: F401 (fixture)
from test_tui_mission import MISSION, gcs, on_map
from test_zenoh_fleet import free_tcp_port

DEFAULT_FILE = "mission.waypoints"


def retype(s, text: str) -> None:
    """Replaces the prompt's offer (the file last named, or the next item) with `text`."""
    s.keys(*["BSpace"] * 24)
    s.keys("-l", text)
    s.keys("Enter")


def test_mission_keys_upload_set_current_and_download(screen_factory, tmp_path):  # noqa: F811
    port = free_tcp_port()
    s = screen_factory(
        f"{shlex.quote(str(GCS_BIN))} tui --serve tcpin:127.0.0.1:{port} --no-log",
        width=100,
        height=30,
    )
    s.wait(r"STANDBY", 30)
    (tmp_path / "box.waypoints").write_text(MISSION)

    s.keys("BTab")  # Shift-Tab from Flight: the Map view, which downloads the (empty) mission
    s.wait(r"Map\s+10 m/cell\s+following")
    s.wait(r"mission of 0 items", 15)

    # u: the file is read and checked, its items named, then y uploads and verifies it.
    s.keys("u")
    s.wait(r"Upload a mission file")
    s.wait(DEFAULT_FILE)
    retype(s, "box.waypoints")  # relative to the UI's working directory, tmp_path
    s.wait(r"Upload 5 mission items from box\.waypoints\?", 10)
    s.keys("y")
    s.wait(r"uploaded 5 mission items from box\.waypoints \(verified by download\)", 15)
    held = gcs("mission", "download", "-", port=port)
    assert close(rows(held)[1:], rows(MISSION)[1:]), held
    # The map draws the new mission.
    for pattern in (r"\b2\b", r"\b3\b", r"\b4\b", r"L5\b"):
        s.wait(on_map(pattern), 5)

    # n: the item to make current (disarmed on the ground: sent without a question).
    s.keys("n")
    s.wait(r"Make an item current")
    retype(s, "3")
    s.wait(r"current item 3: done", 10)
    s.keys("Tab")  # the Flight view's mission line follows MISSION_CURRENT
    s.wait(r"Mission 3/5 WAYPOINT \d+ m -, 2 left", 10)

    # w: the mission downloaded into a file (the prompt offers the file last named).
    s.keys("BTab", "w")
    s.wait(r"Download the mission into a file")
    s.wait(r"box\.waypoints▏")
    retype(s, "saved.waypoints")
    s.wait(r"mission of 5 items written to saved\.waypoints", 10)
    saved = (tmp_path / "saved.waypoints").read_text()
    assert close(rows(saved)[1:], rows(MISSION)[1:]), saved

    s.keys("q")
    s.assert_exited_cleanly()
