#!/usr/bin/env python3
"""Mission upload and download benchmark: 100 items over loopback TCP, the way a script does it.

    cargo build --workspace --bins
    FIRMWARE_SIM_BIN=target/debug/firmware-sim .venv/bin/python tests/pymavlink/bench_mission.py [--runs N]

A pymavlink client uploads a 100-item mission (home slot + 99 waypoints) and downloads it again,
N times each, against one twin:
  - upload: from MISSION_COUNT to the MISSION_ACK, answering each MISSION_REQUEST with its
    MISSION_ITEM_INT (one item in flight, as the protocol goes);
  - download: from MISSION_REQUEST_LIST to the last MISSION_ITEM_INT, one MISSION_REQUEST_INT
    per item;
each download is checked item by item against what was uploaded. Targets: < 100 ms each.

CPU per transfer is reported for both ends: the twin's (utime + stime from /proc, the twin run
at --speed 0.01 so that its physics costs nothing next to the protocol; its telemetry, at the
default wall-clock rates, about 100 messages a second, is counted in) and the client's (process
time). Medians, 95th percentiles and maxima of N runs.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("MAVLINK20", "1")

from conftest import start_twin  # noqa: E402
from pymavlink import mavutil  # noqa: E402

MAV = mavutil.mavlink
ITEMS = 100
HOME = (-353632610, 1491652300)  # SIM_HOME_LAT/LON defaults, 1e-7 degree
TICKS = os.sysconf("SC_CLK_TCK")


def twin_cpu_s(pid: int) -> float:
    """utime + stime of a process, s (from /proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def mission(target: tuple[int, int], count: int = ITEMS) -> list:
    """Home slot, then count - 1 waypoints on a spiral around home (within 40 m for 100 items)
    at 2-5 m."""
    items = [MAV.MAVLink_mission_item_int_message(*target, 0, MAV.MAV_FRAME_GLOBAL_INT,
                                                  MAV.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                                  HOME[0], HOME[1], 584.0)]
    for seq in range(1, count):
        r, a = 0.4 * seq, 0.5 * seq
        lat = HOME[0] + round(r * math.cos(a) / 0.011131884502145034)
        lon = HOME[1] + round(r * math.sin(a) / 0.011131884502145034 / math.cos(math.radians(HOME[0] * 1e-7)))
        items.append(MAV.MAVLink_mission_item_int_message(
            *target, seq, MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, MAV.MAV_CMD_NAV_WAYPOINT, 0, 1,
            float(seq % 3), 0.25, 0, float("nan"), lat, lon, 2.0 + (seq % 4)))
    return items


def recv(m, types, timeout: float = 5.0):
    msg = m.recv_match(type=types, blocking=True, timeout=timeout)
    if msg is None:
        raise SystemExit(f"no {types} within {timeout} s")
    return msg


def upload(m, items) -> float:
    t0 = time.perf_counter()
    m.mav.mission_count_send(1, 1, len(items))
    while True:
        msg = recv(m, ["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"])
        if msg.get_type() == "MISSION_ACK":
            dt = time.perf_counter() - t0
            if msg.type != MAV.MAV_MISSION_ACCEPTED:
                raise SystemExit(f"upload refused: {msg}")
            return dt
        m.mav.send(items[msg.seq])


def download(m, items, pos_tol: int = 0) -> float:
    """Downloads the list and checks it against `items` (positions to within `pos_tol` 1e-7 deg)."""
    t0 = time.perf_counter()
    m.mav.mission_request_list_send(1, 1)
    count = recv(m, "MISSION_COUNT").count
    got = []
    for seq in range(count):
        m.mav.mission_request_int_send(1, 1, seq)
        got.append(recv(m, "MISSION_ITEM_INT"))
    dt = time.perf_counter() - t0
    if count != len(items):
        raise SystemExit(f"downloaded {count} items, uploaded {len(items)}")
    for a, b in zip(got, items):
        # Home (item 0) comes back in MAV_FRAME_GLOBAL, as ArduPilot reports it.
        fa = (a.seq, a.command, a.frame, a.z, a.param1, a.param2, a.param3)
        fb = (b.seq, b.command, MAV.MAV_FRAME_GLOBAL if b.seq == 0 else b.frame, b.z, b.param1, b.param2, b.param3)
        far = abs(a.x - b.x) > pos_tol or abs(a.y - b.y) > pos_tol
        if fa != fb or far or math.isnan(a.param4) != math.isnan(b.param4):
            raise SystemExit(f"item {b.seq} differs: {a} vs {b}")
    return dt


def summary(name: str, xs: list[float]) -> str:
    q = sorted(xs)
    p95 = q[min(len(q) - 1, math.ceil(0.95 * len(q)) - 1)]
    return (f"{name:<36} median {statistics.median(xs) * 1e3:7.2f} ms  p95 {p95 * 1e3:7.2f} ms"
            f"  max {max(xs) * 1e3:7.2f} ms  (n={len(xs)})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=50)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        twin = start_twin(Path(tmp), listen=["tcpin:127.0.0.1:0"], speed=0.01)
        m = mavutil.mavlink_connection(twin.tcp, source_system=255, source_component=190)
        try:
            recv(m, "HEARTBEAT", 10)
            items = mission((1, 1))
            up, down, cpu_up, cpu_down, client_up, client_down = [], [], [], [], [], []
            for _ in range(args.runs):
                c0, p0 = twin_cpu_s(twin.proc.pid), time.process_time()
                up.append(upload(m, items))
                c1, p1 = twin_cpu_s(twin.proc.pid), time.process_time()
                down.append(download(m, items))
                c2, p2 = twin_cpu_s(twin.proc.pid), time.process_time()
                cpu_up.append(c1 - c0)
                cpu_down.append(c2 - c1)
                client_up.append(p1 - p0)
                client_down.append(p2 - p1)
        finally:
            m.close()
            twin.stop()
    n = args.runs
    print(f"{ITEMS}-item mission over loopback TCP, pymavlink client, {n} runs")
    print(summary("upload (COUNT -> ACK)", up))
    print(summary("download (REQUEST_LIST -> last item)", down))
    print(f"{'twin CPU per upload':<36} {sum(cpu_up) / n * 1e3:7.2f} ms"
          f"  ({sum(cpu_up) / n / ITEMS * 1e6:6.1f} us per item; /proc ticks of {1e3 / TICKS:.0f} ms, summed)")
    print(f"{'twin CPU per download':<36} {sum(cpu_down) / n * 1e3:7.2f} ms"
          f"  ({sum(cpu_down) / n / ITEMS * 1e6:6.1f} us per item)")
    print(f"{'client CPU per upload':<36} {statistics.mean(client_up) * 1e3:7.2f} ms")
    print(f"{'client CPU per download':<36} {statistics.mean(client_down) * 1e3:7.2f} ms")
    print(f"throughput: upload {ITEMS / statistics.median(up):.0f} items/s, "
          f"download {ITEMS / statistics.median(down):.0f} items/s")


if __name__ == "__main__":
    main()
