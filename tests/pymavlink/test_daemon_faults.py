"""Faults the daemon survives, with real processes and a real filesystem: the log's disk fills
up (routing goes on, the error is shown, logging resumes when there is room), the vehicle
restarts (by its reboot command, or as a new process on the same port: the daemon sees
time_boot_ms go back and fetches the parameters again), and a client that sends half a frame
and hangs up (the daemon and the other clients carry on). `kill -9` while logging is in
test_daemon_tlog.py, the serial unplug and replug in test_daemon_serial.py."""

from __future__ import annotations

import os
import socket
import subprocess
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from conftest import MAV_TYPE_FIXED_WING, VEHICLE_COMPID, VEHICLE_SYSID
from daemon_support import daemon_factory, frame_ids, raw_records, script, wait_vehicle_silence  # noqa: F401 (fixture)
from test_daemon_tlog import read_with_pymavlink

MSG_PARAM_REQUEST_LIST = 21
MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN = 246
MAV_RESULT_ACCEPTED = 0
HALF_SENT_CMD = 65003


def fast_status(tmp_path: Path) -> list[str]:
    """A config file with five status lines a second, as --config arguments."""
    cfg = tmp_path / "fast-status.toml"
    cfg.write_text("status_interval_s = 0.2\n")
    return ["--config", str(cfg)]


def wait_status(daemon, pattern: str, timeout: float) -> str:
    """The first status line matching the regex `pattern` (waits on new lines, at most
    `timeout` s)."""
    return daemon.wait_line(r"^(sys |no vehicle).*" + pattern, timeout)


def vehicle_frames(g, n: int, timeout: float) -> int:
    """Receives n vehicle frames (fails after timeout); returns how many arrived."""
    deadline = time.monotonic() + timeout
    got = 0
    while got < n:
        assert time.monotonic() < deadline, f"only {got} of {n} vehicle frames in {timeout} s"
        g.beat()
        m = g.m.recv_match(blocking=True, timeout=0.25)
        if m is not None and (m.get_srcSystem(), m.get_srcComponent()) == (VEHICLE_SYSID, VEHICLE_COMPID):
            got += 1
    return got


# --------------------------------------------------------------------------------------------
# the log's disk fills up
# --------------------------------------------------------------------------------------------


@pytest.fixture
def small_disk(tmp_path):
    """A 256 KiB tmpfs mounted for the test (root only), unmounted after it."""
    mnt = tmp_path / "small-disk"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("a full disk needs a real small filesystem: mounting a tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a 256 KiB tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def fill(path: Path) -> None:
    """Writes path until the filesystem is full."""
    with open(path, "wb", buffering=0) as f:
        try:
            while True:
                f.write(b"\0" * 4096)
        except OSError:
            pass


def test_full_log_disk_routing_goes_on_and_logging_resumes(daemon_factory, small_disk, tmp_path):  # noqa: F811
    # 16 KiB left for the log: a few seconds of the embedded twin's telemetry.
    reserve = small_disk / "reserve"
    reserve.write_bytes(b"\0" * 16384)
    fill(small_disk / "filler")
    reserve.unlink()
    daemon = daemon_factory(serve=["tcpin:127.0.0.1:0"], extra=fast_status(tmp_path),
                            log_dir=small_disk / "logs")
    assert daemon.tlog is not None and str(daemon.tlog).startswith(str(small_disk)), daemon.tlog
    g = script(daemon.tcp)
    try:
        g.wait_vehicle_heartbeat(timeout=15)
        line = wait_status(daemon, "tlog ERROR", 60)
        assert "No space left on device" in line and "routing goes on" in line, line
        # routing goes on: telemetry keeps coming and a command is answered
        vehicle_frames(g, 50, timeout=10)
        ack = g.command(65000, timeout=10)
        assert ack.result == 3, ack
        err = daemon.stderr()
        assert err.count("tlog write failed") == 1, f"the error is logged once per failure:\n{err[-3000:]}"

        # room again: logging resumes by itself
        size_full = daemon.tlog.stat().st_size
        (small_disk / "filler").unlink()
        line = wait_status(daemon, "lost to write errors", 10)
        assert "tlog ERROR" not in line, line
        deadline = time.monotonic() + 10
        while daemon.tlog.stat().st_size <= size_full:
            assert time.monotonic() < deadline, "the log does not grow again after room was made"
            vehicle_frames(g, 1, timeout=5)
        assert "tlog writing again" in daemon.stderr(), daemon.stderr()[-2000:]
    finally:
        g.close()
    daemon_factory.stop(daemon)  # clean exit (checked by the fixture's stop)
    # whole records only: a batch that did not fit was cut off again, so the file reads strictly
    records, cut = raw_records(daemon.tlog.read_bytes())
    assert cut == 0 and records, (cut, len(records))


# --------------------------------------------------------------------------------------------
# the vehicle restarts
# --------------------------------------------------------------------------------------------


def param_request_lists(tlog: Path) -> list[int]:
    """Timestamps (µs) of the daemon's own downloads in its log: its PARAM_REQUEST_LISTs, the
    copies a download sends together (and any resend within a second) counted once."""
    records, _ = raw_records(tlog.read_bytes())
    sent = [t for t, f in records if frame_ids(f)[1:] == (255, 190, MSG_PARAM_REQUEST_LIST)]
    return [t for i, t in enumerate(sent) if i == 0 or t - sent[i - 1] > 1_000_000]


@pytest.mark.parametrize("how", ["reboot command", "new process"])
def test_vehicle_restart_parameters_fetched_again(twin_factory, daemon_factory, tmp_path, how):  # noqa: F811
    twin = twin_factory(listen=["tcpin:127.0.0.1:0"], speed=1)
    host, port = twin.host_port("tcpin")
    daemon = daemon_factory(vehicle=f"tcp:{host}:{port}", serve=["tcpin:127.0.0.1:0"],
                            extra=fast_status(tmp_path) + ["--fetch-params"])
    g = script(daemon.tcp)
    try:
        g.wait_vehicle_heartbeat(timeout=20)
        first = wait_status(daemon, r" \| params ", 20)
        assert "fetched again" not in first and "rebooted" not in first, first
        # A restart shows as the boot clock going back: let the vehicle's clock pass what the
        # reboot takes (1.5 s of silence, then the new clock's first telemetry).
        before = g.recv("ATTITUDE", lambda a: a.time_boot_ms > 2500, timeout=10).time_boot_ms

        if how == "reboot command":
            ack = g.command(MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1, timeout=10)
            assert ack.result == MAV_RESULT_ACCEPTED, ack
        else:
            twin_factory.stop(twin)
            wait_vehicle_silence(g, quiet_s=0.5, timeout=10)
            twin2 = twin_factory(listen=[f"tcpin:{host}:{port}"], speed=1)
            assert twin2.host_port("tcpin") == (host, port)
        line = wait_status(daemon, "fetched again after 1 reboot", 30)
        assert "rebooted 1x" in line, line
        # telemetry of the restarted vehicle flows: its boot clock started again
        g.recv("ATTITUDE", lambda a: a.time_boot_ms < before, timeout=10, what="after the restart")
        err = daemon.stderr()
        assert "rebooted (time_boot_ms" in err, err[-2000:]
        assert "parameters fetched again after the reboot" in err, err[-2000:]
        assert g.command(65000, timeout=10).result == 3  # both ways through the same daemon
    finally:
        g.close()
    daemon_factory.stop(daemon)
    # the log shows the two downloads: at first contact and after the restart
    assert len(param_request_lists(daemon.tlog)) == 2, param_request_lists(daemon.tlog)


# --------------------------------------------------------------------------------------------
# a client hangs up in the middle of a frame
# --------------------------------------------------------------------------------------------


def test_client_closing_mid_frame_harms_nobody(daemon_factory):  # noqa: F811
    daemon = daemon_factory(serve=["tcpin:127.0.0.1:0"])
    host, port = daemon.host_port("tcpin")
    g = script(daemon.tcp)
    try:
        hb = g.wait_vehicle_heartbeat(timeout=15)
        assert hb.type == MAV_TYPE_FIXED_WING
        # A whole COMMAND_LONG for the vehicle, of which only the first half is sent.
        mav = mavutil.mavlink.MAVLink(None, srcSystem=255, srcComponent=0)
        frame = bytes(mav.command_long_encode(VEHICLE_SYSID, VEHICLE_COMPID, HALF_SENT_CMD, 0,
                                              1, 2, 3, 4, 5, 6, 7).pack(mav))
        for _ in range(5):
            s = socket.create_connection((host, port), timeout=5)
            s.sendall(frame[: len(frame) // 2])
            s.close()
        # the daemon and the other client carry on, both ways
        vehicle_frames(g, 50, timeout=10)
        ack = g.command(65000, timeout=10)
        assert ack.result == 3, ack
        assert daemon.alive(), daemon.tail()
    finally:
        g.close()
    daemon_factory.stop(daemon)
    # the half frame never reached the vehicle or the log
    logged = [m for m in read_with_pymavlink(daemon.tlog)
              if m.get_type() == "COMMAND_LONG" and m.command == HALF_SENT_CMD]
    assert not logged, logged
