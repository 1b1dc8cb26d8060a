"""Logs of every ground station: a tlog whose timestamps carry the direction in their low two
bits (MAVProxy's, this daemon's) and one of plain microseconds (QGroundControl's, Mission
Planner's), both written here with pymavlink from one seeded flight. `log stats`, `log export`
and a replay read both as pymavlink does, message for message: no vehicle frame is taken for the
ground station's because its stamp happens to end in binary 11, and a COMMAND_ACK of a command
number the dialect lacks, or a HEARTBEAT of a MAV_TYPE it lacks, is kept."""

from __future__ import annotations

import csv
import random
import struct
import time
from collections import Counter
from pathlib import Path

import pytest
from pymavlink import mavutil

from daemon_support import start_daemon
from test_log_tools import _same, gcs_tool, pymavlink_messages, stats_json

mavlink = mavutil.mavlink
VEHICLE = (1, 1)
GCS = (255, 190)
# A command number and a MAV_TYPE the dialect does not define.
UNKNOWN_COMMAND = 31337
UNKNOWN_TYPE = 60
# The replayed flight starts after this pause, so the client is connected before it does.
LEAD_IN_S = 3.0


def flight(seed: int) -> list[tuple[tuple[int, int], float, bytes]]:
    """(sender, seconds from the start, frame) of a short flight: a vehicle streaming, a ground
    station's heartbeat and commands, acks of known and unknown commands."""
    rng = random.Random(seed)
    senders = {s: mavlink.MAVLink(None, srcSystem=s[0], srcComponent=s[1]) for s in (VEHICLE, GCS)}
    for mav in senders.values():
        mav.robust_parsing = True
    out = []
    t = 0.0

    def add(sender, msg, t):
        out.append((sender, t, msg.pack(senders[sender])))

    add(VEHICLE, mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                   0x81, 5, mavlink.MAV_STATE_ACTIVE, 3), 0.0)
    t = LEAD_IN_S
    for i in range(300):
        t += rng.uniform(0.002, 0.012)
        add(VEHICLE, mavlink.MAVLink_attitude_message(i * 10, rng.uniform(-1, 1), rng.uniform(-1, 1),
                                                      rng.uniform(-3, 3), 0.0, 0.0, 0.0), t)
        if i % 25 == 0:
            t += 0.001
            kind = UNKNOWN_TYPE if i % 50 == 0 else mavlink.MAV_TYPE_QUADROTOR
            add(VEHICLE, mavlink.MAVLink_heartbeat_message(kind, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                           0x81, i % 7, mavlink.MAV_STATE_ACTIVE, 3), t)
            t += 0.001
            add(GCS, mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                                       0, 0, 0, 3), t)
        if i % 40 == 7:
            command = UNKNOWN_COMMAND if i % 80 == 7 else mavlink.MAV_CMD_DO_SET_MODE
            t += 0.001
            add(GCS, mavlink.MAVLink_command_long_message(1, 1, command, 0, 1, 5, 0, 0, 0, 0, 0), t)
            t += 0.003
            result = mavlink.MAV_RESULT_UNSUPPORTED if command == UNKNOWN_COMMAND else mavlink.MAV_RESULT_ACCEPTED
            # To every ground station: the replay's client is not the one that asked.
            add(VEHICLE, mavlink.MAVLink_command_ack_message(command, result, 0, 0, 0, 0), t)
    return out


def write_log(path: Path, seed: int, link_bits: bool) -> Path:
    """The flight as a tlog: MAVProxy's stamps (low bits 3 towards the vehicle, 0 from it) or
    plain microseconds with arbitrary low bits."""
    rng = random.Random(seed + 1)
    t0 = 1_764_000_000_000_000 + rng.randrange(1_000_000)
    with open(path, "wb") as f:
        for sender, t, frame in flight(seed):
            us = t0 + int(t * 1e6) + rng.randrange(4)
            if link_bits:
                us = us | 3 if sender == GCS else us & ~3
            f.write(struct.pack(">Q", us) + frame)
    return path


@pytest.fixture(params=["mavproxy", "qgc"])
def log(request, tmp_path):
    link_bits = request.param == "mavproxy"
    path = write_log(tmp_path / f"{request.param}.tlog", seed=43, link_bits=link_bits)
    return request.param, path


def test_stats_equal_pymavlink(log):
    which, path = log
    msgs = pymavlink_messages(path)
    s = stats_json(path)
    assert {m["name"]: m["count"] for m in s["messages"]} == dict(Counter(m.get_type() for m in msgs))
    assert s["frames"] == len(msgs)
    from_gcs = sum(1 for m in msgs if (m.get_srcSystem(), m.get_srcComponent()) == GCS)
    assert s["frames_to_vehicle"] == from_gcs, s
    assert s["direction_from"] == ("link_bits" if which == "mavproxy" else "sender")
    if which == "qgc":
        # Plain microseconds: many of the vehicle's own stamps end in binary 11.
        raw = path.read_bytes()
        assert from_gcs < sum(1 for m in msgs if int(m._timestamp * 1e6 + 0.5) & 3 == 3)
        assert raw


def test_export_equals_pymavlink(log, tmp_path):
    _, path = log
    msgs = pymavlink_messages(path)
    out = tmp_path / "csv"
    gcs_tool("export", str(path), "--csv", str(out))
    by_type: dict[str, list] = {}
    for m in msgs:
        by_type.setdefault(m.get_type(), []).append(m)
    assert sorted(p.stem for p in out.glob("*.csv")) == sorted(by_type)
    unknown_acks = 0
    for name, theirs in by_type.items():
        with open(out / f"{name}.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        assert len(rows) == len(theirs), name
        for row, msg in zip(rows, theirs):
            assert int(row["system_id"]) == msg.get_srcSystem()
            for field in msg.get_fieldnames():
                value = getattr(msg, field)
                assert _same(msg, field, value, row[field]), (name, field, value, row[field])
            if name == "COMMAND_ACK" and msg.command == UNKNOWN_COMMAND:
                unknown_acks += 1
    assert unknown_acks >= 3
    types = [int(r["type"]) for r in csv.DictReader(open(out / "HEARTBEAT.csv", newline=""))
             if r["type"].isdigit()]
    assert UNKNOWN_TYPE in types


def test_replay_sends_every_vehicle_frame(log, tmp_path):
    _, path = log
    expected = [m.get_msgbuf() for m in pymavlink_messages(path)
                if (m.get_srcSystem(), m.get_srcComponent()) == VEHICLE]
    daemon = start_daemon(tmp_path, vehicle=f"replay:{path}", serve=["tcpin:127.0.0.1:0"], log=False)
    try:
        m = mavutil.mavlink_connection(daemon.tcp, source_system=255, source_component=0)
        got = []
        try:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                msg = m.recv_match(blocking=True, timeout=1.5)
                if msg is None:
                    if len(got) > 1:
                        break  # the replay has ended
                    continue
                if msg.get_type() != "BAD_DATA" and msg.get_srcSystem() == VEHICLE[0]:
                    got.append(bytes(msg.get_msgbuf()))
        finally:
            m.close()
    finally:
        daemon.stop()
    # The first heartbeat goes out before the client connects; everything after the lead-in
    # arrives, in order, none left out.
    assert got and got == [bytes(b) for b in expected[len(expected) - len(got):]]
    assert len(got) >= len(expected) - 1, (len(got), len(expected))
