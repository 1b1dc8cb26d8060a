"""A user's pymavlink script, written the way ArduPilot's examples are (scripts/ardupilot_flight.py:
3D fix, Q_GUIDED_MODE 1, arm in GUIDED, take off to 2 m, reposition 5 m, a 5-item mission in
AUTO flown in a hover with a MISSION_ITEM_REACHED for each, QRTL, disarm), run unchanged as its own process against the twin
and through the vtol-gcs daemon. The twin runs at 20x so a flight takes a few seconds."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from daemon_support import daemon_factory  # noqa: F401 (fixture)

SCRIPT = Path(__file__).parent / "scripts" / "ardupilot_flight.py"
SPEED = 20


def run_script(url: str, timeout: float = 120) -> str:
    """The script as a user runs it: a fresh interpreter, no MAVLINK20 in the environment (so
    pymavlink starts in MAVLink 1 and switches on the vehicle's first frame)."""
    env = {k: v for k, v in os.environ.items() if k != "MAVLINK20"}
    p = subprocess.run([sys.executable, str(SCRIPT), url], capture_output=True, text=True,
                       timeout=timeout, env=env)
    assert p.returncode == 0, f"script failed on {url}:\n{p.stdout}\n{p.stderr}"
    return p.stdout


def check_flight(out: str) -> None:
    lines = out.splitlines()
    for step in ("3D fix", "armed", "took off", "repositioned", "mission uploaded"):
        assert any(line.startswith(step) for line in lines), f"no '{step}' in:\n{out}"
    assert [line for line in lines if line.startswith("reached item")] == [
        f"reached item {n}" for n in (1, 2, 3, 4, 5)
    ], out
    assert lines[-1].startswith("landed") and lines[-1].endswith("disarmed"), out


def test_script_against_the_twin(twin_factory):
    twin = twin_factory(speed=SPEED, listen=["tcpin:127.0.0.1:0"])
    check_flight(run_script(twin.tcp))


def test_script_through_the_daemon(twin_factory, daemon_factory):  # noqa: F811
    twin = twin_factory(speed=SPEED, listen=["tcpin:127.0.0.1:0"])
    daemon = daemon_factory(vehicle=twin.tcp, serve=["tcpin:127.0.0.1:0"], log=False)
    check_flight(run_script(daemon.tcp))
    assert daemon.alive(), daemon.tail()
