"""The daemon's .tlog (PROTOCOL.md D.2) read back by pymavlink and byte by byte: both directions,
direction bits in the timestamps (0 from the vehicle, 3 towards it), and after `kill -9` a file
that still reads cleanly and misses at most the last 100 ms."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

from pymavlink import mavutil

from conftest import VEHICLE_COMPID, VEHICLE_SYSID
from daemon_support import (  # noqa: F401 (fixture)
    DAEMON_BIN,
    SCRIPT_COMPID,
    SCRIPT_SYSID,
    daemon_factory,
    frame_ids,
    raw_records,
    script,
)

MSG_COMMAND_LONG = 76
MSG_COMMAND_ACK = 77
# unknown command ids: each gets exactly one COMMAND_ACK (UNSUPPORTED), and they tell the two
# scripts' commands apart
CMD_TCP, CMD_UDP = 65001, 65002


def read_with_pymavlink(path):
    """Every message pymavlink's tlog reader finds, until it returns None."""
    m = mavutil.mavlink_connection(str(path))
    out = []
    try:
        while True:
            msg = m.recv_match(blocking=False)
            if msg is None:
                break
            out.append(msg)
    finally:
        m.close()
    return out


def check_stamps(records, t_start: float, t_end: float):
    """Direction bits by sender, monotone-ish wall-clock µs stamps inside the session."""
    wrong = []
    for stamp, frame in records:
        _, sysid, compid, msgid = frame_ids(frame)
        want = 0 if (sysid, compid) == (VEHICLE_SYSID, VEHICLE_COMPID) else 3
        if stamp & 3 != want:
            wrong.append((stamp & 3, want, sysid, compid, msgid))
        assert t_start - 1 <= stamp / 1e6 <= t_end + 1, (
            f"stamp {stamp} µs is not wall-clock time of the session [{t_start}, {t_end}]")
    assert not wrong, f"{len(wrong)} records with the wrong direction bits (got, want, sysid, compid, msgid): {wrong[:10]}"


def test_tlog_holds_both_directions(daemon_factory):  # noqa: F811
    t_start = time.time()
    daemon = daemon_factory(serve=["tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"])
    acks = {}
    for url, cmd in ((daemon.tcp, CMD_TCP), (daemon.udp, CMD_UDP)):
        g = script(url)
        try:
            g.wait_vehicle_heartbeat(timeout=15)
            acks[cmd] = g.command(cmd, 7, timeout=10)
            assert acks[cmd].result == 3, acks[cmd]
        finally:
            g.close()
    daemon.assert_clean_exit()  # flushes and closes the log
    t_end = time.time()
    assert daemon.tlog is not None and daemon.tlog.exists(), daemon.stdout_lines[:5]

    data = daemon.tlog.read_bytes()
    records, cut = raw_records(data)
    assert cut == 0, f"a clean shutdown left {cut} bytes of a cut record at the end"
    check_stamps(records, t_start, t_end)

    msgs = read_with_pymavlink(daemon.tlog)
    bad = [m for m in msgs if m.get_type() == "BAD_DATA"]
    assert not bad, f"pymavlink found bad data: {bad[:3]}"
    assert len(msgs) == len(records), f"pymavlink read {len(msgs)} messages, the file has {len(records)} records"

    for cmd in (CMD_TCP, CMD_UDP):
        longs = [m for m in msgs if m.get_type() == "COMMAND_LONG" and m.command == cmd]
        assert len(longs) == 1, f"COMMAND_LONG {cmd} logged {len(longs)} times"
        c = longs[0]
        assert (c.get_srcSystem(), c.get_srcComponent()) == (SCRIPT_SYSID, SCRIPT_COMPID), c
        assert (c.target_system, c.target_component) == (VEHICLE_SYSID, VEHICLE_COMPID), c
        assert c._link == 3, f"the script's COMMAND_LONG is logged with link {c._link}, want 3"
        ack = [m for m in msgs if m.get_type() == "COMMAND_ACK" and m.command == cmd]
        assert len(ack) == 1, f"COMMAND_ACK {cmd} logged {len(ack)} times"
        a = ack[0]
        assert a.get_srcSystem() == VEHICLE_SYSID and a._link == 0, (a, a._link)
        assert a._timestamp >= c._timestamp, "the ACK is logged before its command"
        # what the script received is byte for byte what was logged
        assert a.get_msgbuf() == acks[cmd].get_msgbuf()
    # the vehicle's telemetry and the scripts' GCS heartbeats are in; the daemon's own client
    # (255, 190) sends no heartbeat while no operator is present (headless, no terminal UI)
    types = {(m.get_type(), m.get_srcSystem(), m.get_srcComponent(), m._link) for m in msgs}
    assert ("HEARTBEAT", VEHICLE_SYSID, VEHICLE_COMPID, 0) in types, types
    assert ("ATTITUDE", VEHICLE_SYSID, VEHICLE_COMPID, 0) in types, types
    assert ("HEARTBEAT", SCRIPT_SYSID, SCRIPT_COMPID, 3) in types, types
    assert not any(t[1:3] == (255, 190) for t in types), types


def test_tlog_after_kill9(daemon_factory):  # noqa: F811
    t_start = time.time()
    daemon = daemon_factory(serve=["tcpin:127.0.0.1:0"])
    g = script(daemon.tcp)
    received = []  # (monotonic receive time, raw frame) of every vehicle frame
    try:
        g.wait_vehicle_heartbeat(timeout=15)
        g.command(CMD_TCP, timeout=10)
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            msg = g.m.recv_match(blocking=True, timeout=0.25)
            now = time.monotonic()
            if msg is not None and (msg.get_srcSystem(), msg.get_srcComponent()) == (VEHICLE_SYSID, VEHICLE_COMPID):
                received.append((now, bytes(msg.get_msgbuf())))
        t_kill = time.monotonic()
        t_kill_wall = time.time()
        os.kill(daemon.proc.pid, signal.SIGKILL)
        daemon_factory.forget(daemon)
        daemon.kill9()
        assert daemon.proc.returncode == -signal.SIGKILL
    finally:
        g.close()
    t_end = time.time()
    assert len(received) > 20, f"only {len(received)} vehicle frames in 1.5 s"

    data = daemon.tlog.read_bytes()
    records, cut = raw_records(data)
    assert records, "empty tlog after kill -9"
    assert cut < 8 + 280, f"{cut} bytes after the last whole record: more than one cut record"
    check_stamps(records, t_start, t_end)
    msgs = read_with_pymavlink(daemon.tlog)
    bad = [m for m in msgs if m.get_type() == "BAD_DATA"]
    assert not bad, f"pymavlink found bad data in the killed daemon's log: {bad[:3]}"
    assert len(msgs) == len(records), f"pymavlink read {len(msgs)} messages, the file has {len(records)} whole records"

    logged = {frame for _, frame in records}
    missing = [(t_kill - t, frame_ids(f)) for t, f in received if f not in logged]
    late = [(round(age * 1000), ids) for age, ids in missing if age >= 0.1]
    assert not late, (
        f"{len(late)} vehicle frames a client had received ≥ 100 ms before the kill are not in the "
        f"log (age ms, (seq, sysid, compid, msgid)): {late[:10]}; last logged record "
        f"{frame_ids(records[-1][1])}, {len(records)} records, {cut} cut bytes")
    # and the last frame received before the kill in particular
    t_last, last = received[-1]
    assert last in logged or t_kill - t_last < 0.1, frame_ids(last)
    # what was lost, in time: from the log's last record to the kill
    print(f"kill -9: the log ends {(t_kill_wall - records[-1][0] / 1e6) * 1000:.0f} ms before the kill, "
          f"the client's last frame came {(t_kill - t_last) * 1000:.0f} ms before it")
    # `vtol-gcs log stats` reads it to the end too: exit 0, every whole record, at most one cut
    # record reported as such
    out = subprocess.run([str(DAEMON_BIN), "log", "stats", "--json", str(daemon.tlog)],
                         capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    stats = json.loads(out.stdout)
    assert stats["skipped_bytes"] == 0, stats
    assert stats["truncated_tail_bytes"] == cut, (stats["truncated_tail_bytes"], cut)
    assert stats["frames"] == len(records), (stats["frames"], len(records))
