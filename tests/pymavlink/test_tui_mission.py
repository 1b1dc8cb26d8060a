"""A mission flown with the Map view open, end to end: the real `vtol-gcs` binary in tmux (100x30)
on the twin (`firmware-sim serve --speed 4`: the flight takes half a minute, not two), the mission
uploaded, the mode set and the vehicle armed by the
`vtol-gcs mission|mode|arm` commands on the UI's serve port, as a user would in another terminal.

The Map view downloads the mission when first shown and draws it: the waypoints' numbers, `L`
for the landing, home `H`, the scale bar; the item the vehicle flies to (MISSION_CURRENT) is
highlighted and moves on along the box; the track grows behind the vehicle; the mission ends
landed and disarmed. Every wait is "until the screen shows it, with a deadline", never a sleep.

`VTOL_GCS_MAP_CAPTURES=DIR` keeps the screen mid-flight and at the end as text files in DIR.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import time
from pathlib import Path

from test_tui import GCS_BIN, screen_factory  # noqa: F401 (fixture)
from test_zenoh_fleet import free_tcp_port

# The twin's home. 150 m is 0.001349 degree of latitude and, here, 0.001652 of longitude.
HOME = (-35.363261, 149.16523)
N = HOME[0] + 0.001349
E = HOME[1] + 0.001652
# VTOL take-off to 20 m, a box of 150 m on the wing (north, north-east, east), and a VTOL
# landing at home after a 150 m leg west.
MISSION = "QGC WPL 110\n" + "".join(
    "\t".join(str(v) for v in row) + "\n"
    for row in [
        (0, 1, 0, 16, 0, 0, 0, 0, HOME[0], HOME[1], 584, 1),
        (1, 0, 3, 84, 0, 0, 0, 0, 0, 0, 20, 1),
        (2, 0, 3, 16, 0, 0, 0, 0, round(N, 7), HOME[1], 20, 1),
        (3, 0, 3, 16, 0, 0, 0, 0, round(N, 7), round(E, 7), 20, 1),
        (4, 0, 3, 16, 0, 0, 0, 0, HOME[0], round(E, 7), 20, 1),
        (5, 0, 3, 85, 0, 0, 0, 0, HOME[0], HOME[1], 0, 1),
    ]
)

# A label drawn black on yellow: the SGR codes of the current item (in any order, 8 or 256
# colours), then the label.
SGR = r"\x1b\[[0-9;]*m"


CURRENT = rf"\x1b\[(?=(?:[0-9;]*;)?(?:43|48;5;3)[;m])[0-9;]*m(?:{SGR})*(T1|2|3|4|L5)"


def on_map(pattern: str) -> str:
    """`pattern` inside the map's frame (the lines that begin with its border)."""
    return rf"(?m)^│.*{pattern}"


def braille(screen: str) -> int:
    """Cells of the map's canvas that draw something (track and legs)."""
    return sum(1 for c in screen if 0x2801 <= ord(c) <= 0x28FF)


def gcs(*args: str, port: int) -> str:
    out = subprocess.run([str(GCS_BIN), *args, "--link", f"tcp:127.0.0.1:{port}"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, f"vtol-gcs {' '.join(args)}: {out.stdout}{out.stderr}"
    return out.stdout


def keep(name: str, text: str) -> None:
    if d := os.environ.get("VTOL_GCS_MAP_CAPTURES"):
        Path(d).mkdir(parents=True, exist_ok=True)
        (Path(d) / name).write_text("\n".join(line.rstrip() for line in text.splitlines()) + "\n")


def test_a_mission_flown_on_the_map(screen_factory, twin_factory, tmp_path):  # noqa: F811
    twin = twin_factory(speed=4, listen=("tcpin:127.0.0.1:0",))
    (_, addr), = twin.listeners
    port = free_tcp_port()
    s = screen_factory(
        f"{shlex.quote(str(GCS_BIN))} tui --vehicle tcp:{addr} --serve tcpin:127.0.0.1:{port} --no-log",
        width=100,
        height=30,
    )
    s.wait(r"STANDBY", 30)
    path = tmp_path / "box.waypoints"
    path.write_text(MISSION)
    assert "uploaded 6 mission items" in gcs("mission", "upload", str(path), port=port)

    s.keys(*["Tab"] * 6)
    s.wait(r"Map\s+10 m/cell\s+following")
    # Drawn once downloaded: the waypoints, the landing, home, the scale bar, north.
    s.wait(on_map(r"\b2\b"), 15)
    for pattern in (r"\b3\b", r"\b4\b", r"L5\b", r"├─+┤ \d+ m", r"N↑"):
        s.wait(on_map(pattern), 5)
    legs = braille(s.text())
    assert legs > 20, s.text()  # the legs of the box, in braille dots

    assert "mode AUTO" in gcs("mode", "AUTO", port=port)
    assert "armed in AUTO" in gcs("arm", port=port)
    s.wait(r"AUTO\s+ARMED", 10)

    # Until the vehicle lands and disarms: the current item moves along the box, highlighted,
    # home shows once the vehicle has left it, the track grows behind the vehicle.
    highlighted: list[str] = []
    home_seen = False
    most = legs
    mid = None
    deadline = time.monotonic() + 170
    while True:
        screen = s.text(escapes=True)
        plain = s.text()
        if m := re.search(CURRENT, screen):
            if not highlighted or highlighted[-1] != m.group(1):
                highlighted.append(m.group(1))
        # Home's `H`, alone or leading the labels of the items at home (`HL5`, `HT1/L5`).
        home_seen = home_seen or bool(re.search(on_map(r"(?<!\w)H(?=T1|L5|\W|$)"), plain))
        most = max(most, braille(plain))
        if highlighted[-1:] == ["4"]:
            mid = plain  # the last screen on the east leg, the box almost flown
        if re.search(r"sys 1 \S+ disarmed", plain):
            break
        assert time.monotonic() < deadline, f"still flying; highlighted {highlighted}:\n{plain}"
        time.sleep(0.05)  # poll interval of the screen, not a wait for a state
    assert highlighted and highlighted[-1] == "L5" and len(highlighted) >= 3, highlighted
    order = ["T1", "2", "3", "4", "L5"]
    assert highlighted == sorted(highlighted, key=order.index), highlighted
    assert home_seen, plain
    assert most >= legs + 15, f"the track never grew ({legs} -> {most} cells)"
    assert mid is not None and re.search(on_map(r"L5\b"), mid), mid
    keep("map-mid-flight.txt", mid)
    assert re.search(on_map(r"L5\b"), plain) and re.search(on_map(r"├─+┤ \d+ m"), plain), plain
    keep("map-landed.txt", plain)
    s.keys("q")
    s.assert_exited_cleanly()
