"""The terminal UI end to end: the real `vtol-gcs` binary in a real terminal (tmux), driven by
keys and read from the screen as a user would, with the embedded twin flying behind it (or, in
the fleet test, three twins over Zenoh).

Every wait is "until the screen shows it, with a deadline" (`Screen.wait`), never a sleep. The
terminal is checked afterwards: the process exited 0, the alternate screen is off and the tty
settings are exactly those from before the UI started (raw mode undone).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from conftest import Gcs
from daemon_support import daemon_factory  # noqa: F401 (fixture)

ROOT = Path(__file__).resolve().parents[2]
# A relative path in the environment is taken from where the command was started.
GCS_BIN = Path(os.environ.get("VTOL_GCS_BIN", ROOT / "target" / "debug" / "vtol-gcs")).absolute()

WIDTH, HEIGHT = 120, 36


class Screen:
    """One tmux server (own socket) with one window running `command` in `workdir`."""

    def __init__(self, workdir: Path, command: str, width: int = WIDTH, height: int = HEIGHT):
        assert shutil.which("tmux"), "tmux is needed (tests/run.sh installs it)"
        self.workdir = workdir
        self.sock = str(workdir / "tmux.sock")
        self.before = workdir / "stty.before"
        self.after = workdir / "stty.after"
        # stty reads the pane's terminal before and after the UI, the exit code is printed.
        script = (
            f"stty -g > {shlex.quote(str(self.before))}; {command}; echo EXIT=$?; "
            f"stty -g > {shlex.quote(str(self.after))}; exec sleep 600"
        )
        self.tmux("new-session", "-d", "-x", str(width), "-y", str(height), "-c", str(workdir),
                  "sh", "-c", script)

    def tmux(self, *args: str) -> str:
        return subprocess.run(["tmux", "-S", self.sock, *args], check=True, capture_output=True,
                              text=True, timeout=10).stdout

    def text(self, escapes: bool = False) -> str:
        """The screen as text; with `escapes`, with the SGR sequences of its attributes."""
        return self.tmux("capture-pane", "-p", *(["-e"] if escapes else []))

    def keys(self, *keys: str) -> None:
        self.tmux("send-keys", *keys)

    def wait(self, pattern: str, timeout: float = 20.0, escapes: bool = False) -> re.Match:
        """The first match of `pattern` on the screen (with `escapes`, on the text with its
        attributes); AssertionError with the screen after `timeout` seconds."""
        deadline = time.monotonic() + timeout
        rx = re.compile(pattern)
        while True:
            screen = self.text(escapes)
            if m := rx.search(screen):
                return m
            if time.monotonic() > deadline:
                raise AssertionError(f"screen never showed {pattern!r} in {timeout} s:\n{screen}")
            time.sleep(0.05)  # poll interval of the screen, not a wait for a state

    def wait_value(self, pattern: str, ok, timeout: float, what: str) -> float:
        """Waits until the number captured by `pattern` satisfies ok(value); returns it."""
        deadline = time.monotonic() + timeout
        rx = re.compile(pattern)
        last = None
        while True:
            screen = self.text()
            if m := rx.search(screen):
                last = float(m.group(1))
                if ok(last):
                    return last
            if time.monotonic() > deadline:
                raise AssertionError(f"{what}: last {last} in {timeout} s:\n{screen}")
            time.sleep(0.05)

    def alternate_on(self) -> bool:
        return self.tmux("display-message", "-p", "#{alternate_on}").strip() == "1"

    def close(self) -> None:
        subprocess.run(["tmux", "-S", self.sock, "kill-server"], capture_output=True, timeout=10)

    def assert_exited_cleanly(self, timeout: float = 15.0) -> None:
        self.wait(r"EXIT=0\b", timeout)
        deadline = time.monotonic() + timeout
        while not self.after.exists() or self.after.stat().st_size == 0:
            assert time.monotonic() < deadline, "stty after the UI never ran"
            time.sleep(0.05)
        assert not self.alternate_on(), "the alternate screen is still on"
        assert self.before.read_text() == self.after.read_text(), "tty settings not restored"
        assert "panicked" not in self.text()


@pytest.fixture
def screen_factory(tmp_path):
    screens: list[Screen] = []

    def make(command: str, width: int = WIDTH, height: int = HEIGHT) -> Screen:
        s = Screen(tmp_path, command, width, height)
        screens.append(s)
        return s

    yield make
    for s in screens:
        s.close()


ALT = r"Alt\s+([+-]\d+\.\d+) m"


def test_fly_from_the_terminal(screen_factory):
    """Horizon and PWM values appear; arm (with its confirmation), QHOVER climbs to HOVER_ALT on
    screen, QLAND lands and disarms, q quits with exit status 0 and a restored terminal."""
    s = screen_factory(f"{shlex.quote(str(GCS_BIN))} tui --serve tcpin:127.0.0.1:0 --no-log")
    s.wait(r"Horizon")
    s.wait(r"▼")  # the heading tape's pointer
    s.wait(r"Roll\s+[+-]\d+\.\d°")
    # Output names come from SERVOn_FUNCTION once the table is downloaded.
    s.wait(r"right motor\s+1\d{3} µs")
    s.wait(r"elevator\s+1\d{3} µs")
    s.wait(r"STANDBY", 30)  # calibration done: ready to arm

    s.keys("a")
    s.wait(r"Arm the vehicle\?")
    s.keys("y")
    s.wait(r"arm: done")
    s.wait(r"ARMED")

    s.keys("t")
    s.wait(r"mode QHOVER: done")
    # The setpoint shown in QHOVER is the vehicle's HOVER_ALT.
    hover_alt = float(s.wait(r"Alt\s+[+-]\d+\.\d+ m\s+setpoint\s+\+?(\d+\.\d+) m").group(1))
    assert hover_alt > 0.3
    s.wait_value(ALT, lambda a: abs(a - hover_alt) < 0.1, 30, "altitude on screen reaches HOVER_ALT")

    s.keys("l")
    s.wait(r"mode QLAND: done")
    s.wait_value(ALT, lambda a: a < 0.1, 30, "altitude on screen back on the ground")
    s.wait(r"disarmed", 30)

    s.keys("q")
    s.assert_exited_cleanly()


def test_help_overlay_and_resize(screen_factory):
    """`?` shows the keys; a terminal made too small says so and survives; q still quits."""
    s = screen_factory(f"{shlex.quote(str(GCS_BIN))} tui --serve tcpin:127.0.0.1:0 --no-log")
    s.wait(r"Horizon")
    s.keys("?")
    s.wait(r"Keys")
    s.wait(r"take off: QHOVER")
    s.keys("Escape")
    s.wait(r"Horizon")
    s.tmux("resize-window", "-x", "50", "-y", "12")
    s.wait(r"Terminal too small")
    s.tmux("resize-window", "-x", str(WIDTH), "-y", str(HEIGHT))
    s.wait(r"Horizon")
    s.keys("q")
    s.assert_exited_cleanly()
    # The embedded twin's parameters go with the process: the user is told, once the screen is back.
    s.wait(r"embedded twin's parameters were kept in memory only")


def test_script_commands_the_vehicle_while_the_ui_is_open(screen_factory, tmp_path):
    """`vtol-gcs` with no arguments: the UI on the embedded twin, serving the default port. A
    pymavlink script there sees the vehicle and commands it, and the UI shows what it did."""
    s = screen_factory(shlex.quote(str(GCS_BIN)))
    s.wait(r"Horizon")
    s.wait(r"STANDBY", 30)
    with Gcs("tcp:127.0.0.1:5770") as g:
        g.wait_ready(timeout=15)
        # The UI is an operator: the daemon's own GCS heartbeat (255:190) flows while it is open
        # (the script's own heartbeats never come back to it).
        g.recv("HEARTBEAT", lambda h: h.type == 6 and h.get_srcComponent() == 190, timeout=5,
               sysid=255, what="the daemon's GCS heartbeat")
        g.set_mode("QHOVER")
        s.wait(r"QHOVER")
        g.arm()
        s.wait(r"ARMED")
        g.recv("LOCAL_POSITION_NED", lambda p: -p.z > 0.3, timeout=30, what="climbing")
        s.wait_value(ALT, lambda a: a > 0.3, 10, "the UI shows the climb the script started")
        # The script sees the UI's commands too: land from the keyboard.
        s.keys("l")
        g.recv("HEARTBEAT", lambda h: h.custom_mode == 20, timeout=10, what="QLAND from the UI")
    # The UI wrote its tlog in the work directory, like `vtol-gcs run`.
    assert list(tmp_path.glob("logs/*.tlog")), "no tlog"
    s.keys("q")
    s.assert_exited_cleanly()


def test_sigterm_restores_the_terminal(screen_factory):
    """SIGTERM ends the UI like q: exit 0 and the terminal restored."""
    s = screen_factory(f"{shlex.quote(str(GCS_BIN))} tui --serve tcpin:127.0.0.1:0 --no-log")
    s.wait(r"Horizon")
    shell = s.tmux("display-message", "-p", "#{pane_pid}").strip()
    children = subprocess.run(["ps", "-o", "pid=,comm=", "--ppid", shell], capture_output=True,
                              text=True, timeout=10).stdout.split("\n")
    pids = [int(line.split()[0]) for line in children if "vtol-gcs" in line]
    assert len(pids) == 1, children
    os.kill(pids[0], 15)
    s.assert_exited_cleanly()


def test_connect_to_a_running_daemon(screen_factory, daemon_factory):  # noqa: F811
    """`vtol-gcs tui --connect` attaches to a headless daemon's serve port: the vehicle behind it
    appears, and a mode switch from the keyboard reaches it."""
    d = daemon_factory(serve=["tcpin:127.0.0.1:0"], log=False)
    port = next(addr for scheme, addr in d.serving if scheme == "tcpin").rsplit(":", 1)[1]
    s = screen_factory(f"{shlex.quote(str(GCS_BIN))} tui --connect tcp:127.0.0.1:{port}")
    s.wait(r"Horizon")
    s.wait(r"right motor\s+1\d{3} µs", 30)
    s.keys("t")
    s.wait(r"mode QHOVER: done")
    s.wait(r"QHOVER ")
    s.keys("q")
    s.assert_exited_cleanly()


# One entry of the fleet's vehicle list: system id, mode, armed state, and its link health (a
# rate that is not zero, and the loss).
def fleet_entry(n: int, mode: str = r"[A-Z]+") -> str:
    return rf"{n} {mode} (?:disarmed|ARMED) [1-9]\d* Hz \d+\.\d%"


def fleet_list(*entries: str) -> str:
    return r"vehicles \(v/V\)\s+" + r"\s+│\s+".join(entries)


def highlighted(n: int) -> str:
    """Vehicle n's entry right after an SGR that turns on reverse video (the selection)."""
    return rf"vehicles \(v/V\).*\x1b\[(?:[0-9;]*;)?7(?:;[0-9;]*)?m(?:\x1b\[[0-9;]*m)* {n} "


def test_a_zenoh_fleet_in_the_terminal(screen_factory, twin_factory, daemon_factory):  # noqa: F811
    """The UI is the ground end of a Zenoh fleet (`tui --vehicle 'zenoh:test/*'`, listening on a
    free port) with three twins, each behind its own daemon serving `zenoh:test/vN`: the list
    shows the three with their link health; v and V switch the selected vehicle and the header,
    the attitude and position pane (twin n stands n m north) and the commands follow it; a
    vehicle whose daemon dies is LOST on screen while the others go on."""
    from test_zenoh_fleet import free_tcp_port, vehicle_daemon

    port = free_tcp_port()
    s = screen_factory(
        f"{shlex.quote(str(GCS_BIN))} tui --vehicle 'zenoh:test/*' "
        f"--zenoh-listen tcp/127.0.0.1:{port} --serve tcpin:127.0.0.1:0 --no-log",
        width=150,  # three vehicles at about 100 Hz each take 120 columns and more
    )
    s.wait(r"waiting for a vehicle heartbeat")
    joins = ["--zenoh-connect", f"tcp/127.0.0.1:{port}"]
    # Twin n stands n m north of the origin (paper frame: north is -x).
    daemons = {
        n: vehicle_daemon(twin_factory, daemon_factory, n, joins, ["--initial", f"x={-n}"])[1]
        for n in (1, 2, 3)
    }
    s.wait(fleet_list(*(fleet_entry(n) for n in (1, 2, 3))), 15)

    def north(n: int) -> float:
        return s.wait_value(r"North\s+([+-]\d+\.\d+) m", lambda x: abs(x - n) < 0.2, 10,
                            f"vehicle {n}'s position in the detail pane")

    def shows(n: int) -> None:
        s.wait(rf"vtol-gcs\s+sys {n} ")
        s.wait(highlighted(n), 10, escapes=True)
        north(n)

    def after(n: int, k: int) -> int:
        """The vehicle k places after n in the list (system ids 1..3, wrapping)."""
        return (n - 1 + k) % 3 + 1

    first = int(s.wait(r"vtol-gcs\s+sys (\d) ").group(1))
    shows(first)
    s.keys("v")
    shows(after(first, 1))
    s.wait(rf"vehicle {after(first, 1)} \(component 1\) selected")
    s.keys("v")
    shows(after(first, 2))
    s.keys("V")
    selected = after(first, 1)
    shows(selected)

    # A command goes to the selected vehicle only. In QHOVER the setpoint is the HOVER_ALT of
    # the parameter table, which a switch empties: it shows once this vehicle's table is in.
    s.keys("t")
    s.wait(r"mode QHOVER: done")
    s.wait(r"Alt\s+[+-]\d+\.\d+ m\s+setpoint\s+\+\d+\.\d+ m", 10)
    s.wait(fleet_list(*(fleet_entry(n, "QHOVER" if n == selected else "QSTABILIZE")
                        for n in (1, 2, 3))))

    # The daemon of another vehicle dies: that one is LOST within 5 s, the others go on.
    victim = after(selected, 1)
    d = daemons[victim]
    daemon_factory.forget(d)
    d.proc.kill()
    d.proc.wait(timeout=10)
    entries = {n: fleet_entry(n) for n in (1, 2, 3)}
    entries[victim] = rf"{victim} LOST \d+ s"
    s.wait(fleet_list(*(entries[n] for n in (1, 2, 3))), 5)
    s.keys("s")
    s.wait(r"mode QSTABILIZE: done")
    entries[selected] = fleet_entry(selected, "QSTABILIZE")
    s.wait(fleet_list(*(entries[n] for n in (1, 2, 3))))

    # Selecting the lost vehicle shows it lost in the header too.
    s.keys("v")
    s.wait(rf"vtol-gcs\s+sys {victim} .*LINK LOST")
    s.wait(highlighted(victim), 10, escapes=True)

    s.keys("q")
    s.assert_exited_cleanly()


def test_qstabilize_in_the_air_asks_first_and_reboot_clears_the_crash(screen_factory):
    """`s` while hovering asks first, naming the fall, and `n` leaves the vehicle hovering in
    QHOVER; confirmed, the vehicle falls and crashes. Arming is then refused with the way out,
    and `R` (confirmed) reboots the vehicle, which arms again."""
    s = screen_factory(f"{shlex.quote(str(GCS_BIN))} tui --serve tcpin:127.0.0.1:0 --no-log")
    s.wait(r"STANDBY", 30)
    s.keys("t")
    s.wait(r"mode QHOVER: done")
    s.keys("a")
    s.wait(r"Arm the vehicle\?")
    s.keys("y")
    s.wait_value(ALT, lambda a: a > 0.8, 30, "climbing")
    s.keys("s")
    s.wait(r"Switch to QSTABILIZE in the air\?")
    s.wait(r"vehicle falls")
    s.keys("n")
    s.wait(r"mode QSTABILIZE cancelled: nothing sent")
    s.wait_value(ALT, lambda a: a > 0.8, 5, "still hovering after n")
    s.wait(r"QHOVER ARMED", 5)  # the header follows the 1 Hz HEARTBEAT

    s.keys("s")
    s.wait(r"Switch to QSTABILIZE")
    s.keys("y")
    s.wait(r"EMERGENCY", 30)
    s.wait(r"Crash detected")
    s.keys("a")
    s.keys("y")
    s.wait(r"vtol-gcs reboot", 15)
    s.keys("R")
    s.wait(r"Reboot the autopilot\?")
    s.keys("y")
    s.wait(r"reboot: done", 15)
    s.wait(r"STANDBY", 40)
    s.keys("t")
    s.wait(r"QHOVER disarmed", 15)
    s.keys("a")
    s.keys("y")
    s.wait(r"QHOVER ARMED", 30)
    s.keys("q")
    s.assert_exited_cleanly()
