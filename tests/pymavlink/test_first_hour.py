"""A new user's first hour with the release binaries, one test per failure they met (issue
"Every documented command works, every message says what really happened"): the top-level
grammar, a transport nobody spoke first on, exit codes against docs/cli.md's table, diagnoses
that named the wrong cause, fleets that all said system 1, and messages on standard error that
carried colour codes or the build machine's source paths.

Exit status (docs/cli.md): 0 done, 1 refused by the vehicle (`params diff`: different), 2 usage
or input error, 3 no vehicle or link failure, 4 a rollback that could not complete."""

from __future__ import annotations

import json
import os
import re
import socket
import struct
import subprocess
from pathlib import Path

import pytest
from pymavlink import mavutil

from conftest import TWIN_BIN
from daemon_support import DAEMON_BIN, Daemon, daemon_factory  # noqa: F401

ANSI = re.compile(r"\x1b\[")


def gcs(*args: str, timeout: float = 60.0, env: dict | None = None) -> subprocess.CompletedProcess:
    """`vtol-gcs ARGS`; a hang fails the test at `timeout`."""
    assert DAEMON_BIN.exists(), f"{DAEMON_BIN} missing: build it with `cargo build --workspace`"
    full_env = {k: v for k, v in os.environ.items() if k != "VTOL_GCS_SIGNING_PASSPHRASE"}
    full_env.update(env or {})
    return subprocess.run([str(DAEMON_BIN), *args], capture_output=True, text=True,
                          timeout=timeout, env=full_env)


def one_line(r: subprocess.CompletedProcess) -> str:
    """The single line a failure prints on standard error."""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got:\n{r.stderr}"
    assert not ANSI.search(r.stderr), r.stderr
    return lines[0]


@pytest.fixture(scope="module")
def twin(module_twin_factory):
    return module_twin_factory(speed=4)


@pytest.fixture(scope="module")
def keyed(module_twin_factory):
    return module_twin_factory(speed=4, listen=["tcpin:127.0.0.1:0"],
                               extra=["--signing-passphrase", "right"])


@pytest.fixture(scope="module")
def fleet(module_twin_factory):
    return module_twin_factory(speed=4, listen=["tcpin:127.0.0.1:0"], extra=["--count", "3"])


# --- one grammar -----------------------------------------------------------------------------


def test_no_subcommand_takes_the_tui_flags_and_help_says_so():
    r = gcs("--help")
    assert r.returncode == 0, r.stderr
    for flag in ("--vehicle", "--serve", "--zenoh-listen", "--connect", "--headless"):
        assert flag in r.stdout, f"{flag} missing from the top-level help:\n{r.stdout}"
    # Parsed as the UI's flags (it refuses the Zenoh flags without a zenoh: link), not
    # "unexpected argument '--vehicle' found".
    r = gcs("--vehicle", "tcp:127.0.0.1:5760", "--zenoh-listen", "tcp/127.0.0.1:7447")
    assert r.returncode == 2, r.stderr
    assert "need a zenoh: link" in one_line(r)


def test_no_subcommand_with_headless_runs_the_daemon(twin, tmp_path):
    args = [str(DAEMON_BIN), "--vehicle", twin.tcp, "--serve", "tcpin:127.0.0.1:0", "--headless",
            "--no-log"]
    d = Daemon.spawn(args, tmp_path, 1, 30.0, log=False)
    try:
        r = gcs("params", "get", "ALT_KP", "--link", d.tcp)
        assert r.returncode == 0 and r.stdout.split()[0] == "ALT_KP", r.stdout + r.stderr
    finally:
        d.assert_clean_exit()


# --- speaking first on udpout ---------------------------------------------------------------


def test_the_cli_speaks_first_on_udpout(twin):
    # The twin's udpin endpoint learns the client only from what the client sends.
    r = gcs("params", "get", "ALT_KP", "--link", twin.udp, timeout=30)
    assert r.returncode == 0 and r.stdout.split()[0] == "ALT_KP", r.stdout + r.stderr


def test_the_cli_speaks_first_to_a_daemon_udpin(daemon_factory):  # noqa: F811
    d = daemon_factory(serve=["udpin:127.0.0.1:0"], log=False)
    r = gcs("params", "get", "HOVER_ALT", "--link", d.udp, timeout=30)
    assert r.returncode == 0 and r.stdout.split()[0] == "HOVER_ALT", r.stdout + r.stderr


def udp_sockets(pid: int) -> list[tuple[str, int]]:
    """The local (address, port) of every IPv4 UDP socket process `pid` holds (/proc)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[len("socket:["):-1])
    out = []
    with open("/proc/net/udp") as f:
        for line in f.readlines()[1:]:
            cols = line.split()
            if cols[9] in inodes:
                ip_hex, port_hex = cols[1].split(":")
                ip = socket.inet_ntoa(struct.pack("<I", int(ip_hex, 16)))
                out.append((ip, int(port_hex, 16)))
    return out


def test_the_daemon_speaks_first_on_a_udpout_vehicle_link_without_a_heartbeat(tmp_path):
    """What the daemon sends to open the link is no HEARTBEAT (ArduPilot and the twin take any
    heartbeat from SYSID_MYGCS as the operator's), and it leaves from loopback for a loopback
    destination."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(10)
    port = vehicle.getsockname()[1]
    args = [str(DAEMON_BIN), "run", "--vehicle", f"udpout:127.0.0.1:{port}", "--serve",
            "tcpin:127.0.0.1:0", "--headless", "--no-log"]
    d = Daemon.spawn(args, tmp_path, 1, 30.0, log=False)
    try:
        data, peer = vehicle.recvfrom(4096)
        assert peer[0] == "127.0.0.1", peer
        parser = mavutil.mavlink.MAVLink(None)
        msgs = parser.parse_buffer(data) or []
        assert msgs, data
        assert all(m.get_type() != "HEARTBEAT" for m in msgs), msgs
        # Its socket binds loopback, not every interface (only the udpout link uses UDP here).
        bound = udp_sockets(d.proc.pid)
        assert bound and all(ip == "127.0.0.1" for ip, _ in bound), bound
    finally:
        vehicle.close()
        d.assert_clean_exit()


def test_the_daemon_hears_a_vehicle_listening_on_udpin(twin, daemon_factory):  # noqa: F811
    d = daemon_factory(vehicle=twin.udp, serve=["tcpin:127.0.0.1:0"], log=False)
    r = gcs("params", "get", "HOVER_ALT", "--link", d.tcp, timeout=30)
    assert r.returncode == 0 and r.stdout.split()[0] == "HOVER_ALT", r.stdout + r.stderr


# --- exit codes and lines -------------------------------------------------------------------


def test_an_unknown_parameter_is_an_input_error(twin):
    r = gcs("params", "get", "NOPE", "--link", twin.tcp)
    assert r.returncode == 2, r.stderr
    assert one_line(r) == "error: the vehicle has no parameter NOPE"


def test_a_refused_set_says_so_in_one_line(twin):
    r = gcs("params", "set", "ALT_KP", "1000", "--link", twin.tcp)
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stdout == "", r.stdout
    line = one_line(r)
    assert line.startswith("error: set refused") and "ALT_KP" in line and "push" not in line, line
    r = gcs("params", "get", "ALT_KP", "--link", twin.tcp)
    assert r.stdout.split() == ["ALT_KP", "5"], r.stdout


def test_diff_exits_1_when_different_and_labels_the_sides(twin, tmp_path):
    f = tmp_path / "mine.parm"
    f.write_text("ALT_KP 7\n")
    r = gcs("params", "diff", str(f), "--link", twin.tcp)
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stdout.splitlines() == [f"NAME vehicle -> {f}", "ALT_KP 5 -> 7", "1 differ"], r.stdout
    f.write_text("ALT_KP 5\n")
    r = gcs("params", "diff", str(f), "--link", twin.tcp)
    assert r.returncode == 0 and r.stdout == "0 differ\n", r.stdout + r.stderr


def test_a_dry_run_expected_to_be_refused_exits_1_without_float32_noise(twin, tmp_path):
    f = tmp_path / "bad.parm"
    f.write_text("LAT_SAT_B 1.2\n")
    r = gcs("params", "push", "--dry-run", str(f), "--link", twin.tcp)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "a=1.2, b=1.2," in r.stdout and "00000" not in r.stdout, r.stdout
    assert "would likely be refused" in one_line(r)


def test_a_fraction_for_an_integer_parameter_is_refused(twin):
    r = gcs("params", "set", "SIM_PUSH_MS", "37.5", "--link", twin.tcp)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "SIM_PUSH_MS is an integer parameter: 37.5 would be stored as 38" in one_line(r)


def test_mode_lists_the_modes_and_takes_numbers(twin):
    r = gcs("mode", "FOO", "--link", twin.tcp)
    assert r.returncode == 2
    line = one_line(r)
    assert "QHOVER (18)" in line and "QLAND (20)" in line, line
    r = gcs("mode", "17", "--link", twin.tcp)
    assert r.returncode == 0 and r.stdout == "mode QSTABILIZE\n", r.stdout + r.stderr


def test_a_target_that_is_not_there_names_those_that_are(twin):
    r = gcs("params", "get", "ALT_KP", "--target", "9", "--link", twin.tcp)
    assert r.returncode == 3, r.stderr
    assert one_line(r) == "error: no vehicle 9 among the vehicles heard: 1"


# --- diagnoses ------------------------------------------------------------------------------


def test_a_refused_connection_fails_at_once():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    r = gcs("params", "pull", "--link", f"tcp:127.0.0.1:{port}", timeout=30)
    assert r.returncode == 3, r.stderr
    line = one_line(r)
    assert "cannot connect" in line and "refused" in line, line


def test_a_wrong_key_is_named(keyed, tmp_path):
    r = gcs("params", "get", "ALT_KP", "--link", keyed.tcp, "--signing-passphrase", "wrong",
            "--signing-state", str(tmp_path / "s.toml"))
    assert r.returncode == 2, r.stderr
    assert one_line(r) == ("error: frames from system 1 arrive but fail signature verification "
                           "(wrong key?)")


def test_a_missing_key_is_named(keyed):
    r = gcs("params", "get", "ALT_KP", "--link", keyed.tcp)
    assert r.returncode == 2, r.stderr
    assert one_line(r).startswith("error: frames from the vehicle are signed and no key was given")


def test_the_passphrase_can_come_from_the_environment(keyed, tmp_path):
    assert "VTOL_GCS_SIGNING_PASSPHRASE" in gcs("params", "--help").stdout
    r = gcs("params", "get", "ALT_KP", "--link", keyed.tcp, "--signing-state",
            str(tmp_path / "s.toml"), env={"VTOL_GCS_SIGNING_PASSPHRASE": "right"})
    assert r.returncode == 0 and r.stdout.split() == ["ALT_KP", "5"], r.stdout + r.stderr


def test_several_vehicles_without_a_target_is_refused(fleet):
    r = gcs("params", "pull", "--link", fleet.tcp)
    assert r.returncode == 2, r.stderr
    assert one_line(r) == "error: several vehicles answer (1, 2, 3): give --target"


def test_zenoh_port_in_use_is_one_plain_line():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    port = s.getsockname()[1]
    try:
        r = gcs("run", "--vehicle", "zenoh:f/*", "--zenoh-listen", f"tcp/127.0.0.1:{port}",
                "--headless", "--no-log", timeout=60)
        assert r.returncode == 3, r.stderr
        line = one_line(r)
        assert "Address already in use" in line and ".rs:" not in line, line
        # With Zenoh's own warnings asked for, they still carry no colour codes into a pipe.
        r = gcs("run", "--vehicle", "zenoh:f/*", "--zenoh-listen", f"tcp/127.0.0.1:{port}",
                "--headless", "--no-log", env={"RUST_LOG": "warn"}, timeout=60)
        assert "WARN" in r.stderr and not ANSI.search(r.stderr), r.stderr
    finally:
        s.close()


# --- fleets ---------------------------------------------------------------------------------


def test_each_twin_of_a_fleet_reports_its_own_system_id(fleet):
    for sysid in (1, 2, 3):
        r = gcs("params", "get", "SYSID_THISMAV", "--target", str(sysid), "--link", fleet.tcp)
        assert r.returncode == 0, r.stderr
        assert r.stdout.split() == ["SYSID_THISMAV", str(sysid)], r.stdout


def test_a_twin_given_a_sysid_reports_it(twin_factory):
    t = twin_factory(speed=4, listen=["tcpin:127.0.0.1:0"], extra=["--sysid", "2"])
    r = gcs("params", "get", "SYSID_THISMAV", "--link", t.tcp)
    assert r.returncode == 0 and r.stdout.split() == ["SYSID_THISMAV", "2"], r.stdout + r.stderr


# --- smaller --------------------------------------------------------------------------------


def test_log_stats_of_a_file_with_no_record_fails_in_one_line(tmp_path):
    f = tmp_path / "empty.tlog"
    f.write_bytes(b"")
    r = gcs("log", "stats", str(f))
    assert r.returncode == 2, r.stdout + r.stderr
    assert "no tlog record" in one_line(r) and r.stdout == "", r.stdout


def test_simulate_without_csv_says_nothing_was_written(tmp_path):
    r = subprocess.run([str(TWIN_BIN), "simulate", "--duration", "0.1"], capture_output=True,
                       text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "no CSV written" in r.stderr, r.stderr
    out = tmp_path / "out.csv"
    r = subprocess.run([str(TWIN_BIN), "simulate", "--duration", "0.1", "--csv", str(out)],
                       capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 0 and "no CSV" not in r.stderr, r.stderr
    assert out.read_text().count("\n") > 1


def test_the_twin_saves_parameters_at_full_precision(twin_factory, tmp_path):
    t = twin_factory(speed=4, listen=["tcpin:127.0.0.1:0"])
    r = gcs("params", "set", "ALT_KP", "1.2345678", "--link", t.tcp)
    assert r.returncode == 0, r.stderr
    assert "ALT_KP           1.2345678\n" in t.param_file.read_text()


# --- loss figures that count only losses ----------------------------------------------------


def write_tlog(path: Path, frames: list[tuple[int, int, int, float]]) -> None:
    """A tlog of HEARTBEATs: (system, component, seq, time s) each."""
    out = bytearray()
    for sysid, compid, seq, t in frames:
        mav = mavutil.mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        mav.seq = seq
        msg = mav.heartbeat_encode(mavutil.mavlink.MAV_TYPE_VTOL_TILTROTOR,
                                   mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 3)
        buf = msg.pack(mav)
        out += struct.pack(">Q", int(t * 1e6) & ~3) + buf
    path.write_bytes(out)


def loss(path: Path) -> dict[str, int]:
    r = gcs("log", "stats", "--json", str(path))
    assert r.returncode == 0, r.stderr
    return {f"{s['system_id']}:{s['component_id']}": s["seq_lost"] for s in json.loads(r.stdout)["sources"]}


def test_log_stats_counts_a_restart_and_repeated_zeros_as_no_loss(tmp_path):
    f = tmp_path / "restart.tlog"
    frames = [(1, 1, i, i * 0.1) for i in range(100)]             # a vehicle, seq 0..99
    frames += [(1, 1, i, 10.5 + i * 0.1) for i in range(50)]      # restarted at once: 0..49
    frames += [(255, 190, 0, 0.0), (255, 190, 0, 0.5)]            # a client's first two, both 0
    frames += [(255, 190, i, 0.5 + i) for i in range(1, 5)]
    frames += [(1, 2, i, i * 0.1) for i in (0, 1, 2, 5, 6)]         # a real gap: 3, 4 lost
    frames.sort(key=lambda x: x[3])
    write_tlog(f, frames)
    assert loss(f) == {"1:1": 0, "1:2": 2, "255:190": 0}


def test_command_line_runs_are_counted_apart_from_the_daemon(daemon_factory, tmp_path):  # noqa: F811
    """Each run speaks as its own component (not the daemon's 255:190), so the daemon's log
    shows no phantom loss for any ground-station sender."""
    d = daemon_factory(serve=["tcpin:127.0.0.1:0"])
    for _ in range(3):
        r = gcs("params", "get", "ALT_KP", "--link", d.tcp)
        assert r.returncode == 0, r.stderr
    d.assert_clean_exit()
    ours = {k: v for k, v in loss(d.tlog).items() if k.startswith("255:")}
    assert ours and "255:190" not in ours, ours
    assert all(v == 0 for v in ours.values()), ours
