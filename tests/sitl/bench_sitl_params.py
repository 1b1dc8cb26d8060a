#!/usr/bin/env python3
"""Full parameter download from ArduPlane SITL (QuadPlane tailsitter) on loopback, side by side:

    cargo build --release --bins
    ARDUPILOT_SITL=.../build/sitl/bin/arduplane VTOL_GCS_BIN=target/release/vtol-gcs \\
        .venv/bin/python tests/sitl/bench_sitl_params.py [--runs N]

SITL at real time (`--speedup 1`, instance SITL_INSTANCE, default 1), `vtol-gcs run --vehicle
tcp:...` in front of it. Through the daemon's serve port, N runs each, interleaved:
  - `vtol-gcs params pull --no-ftp` (the parameter protocol): the download as the client
    reports it (PARAM_REQUEST_LIST to the last value, after the vehicle was found) and the
    whole process's wall time;
  - `vtol-gcs params pull` (the table as `@PARAM/param.pck` over MAVLink FTP): the same;
  - a bare pymavlink loop (`param_fetch_all`, then PARAM_VALUEs until every index is in; no
    re-requests), timed from its request, as a script would;
  - MAVProxy 1.8.75's download (its default, FTP when offered), from its "online system"
    line to "Received N parameters".
Medians and maxima; every run must succeed.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "pymavlink"))
os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

from daemon_support import DAEMON_BIN, start_daemon  # noqa: E402
from procs import mavproxy  # noqa: E402
from sitl import Sitl  # noqa: E402


def gcs_pull(url: str, out: Path, ftp: bool) -> tuple[float, float]:
    """(download, whole process) seconds."""
    args = [str(DAEMON_BIN), "params", "pull", "-o", str(out), "--link", url]
    if not ftp:
        args.append("--no-ftp")
    t0 = time.perf_counter()
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed ({r.returncode}): {r.stderr}")
    m = re.search(r"^(\d+) parameters written .*download ([0-9.]+) ms", r.stderr, re.M)
    if not m:
        raise SystemExit(f"no download time in: {r.stderr}")
    return float(m[2]) / 1e3, wall


def pymavlink_loop(url: str) -> float:
    m = mavutil.mavlink_connection(url, source_system=255, source_component=190)
    try:
        m.recv_match(type="HEARTBEAT", condition="HEARTBEAT.type!=6", blocking=True, timeout=10)
        m.target_component = 1
        t0 = time.perf_counter()
        m.param_fetch_all()
        seen: set[int] = set()
        count = None
        while count is None or len(seen) < count:
            p = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=10)
            if p is None:
                raise SystemExit(f"pymavlink loop: stalled at {len(seen)} of {count}")
            if p.param_index == 65535:
                continue
            count = p.param_count
            seen.add(p.param_index)
        return time.perf_counter() - t0
    finally:
        m.close()


def mavproxy_download(url: str, work: Path) -> float:
    work.mkdir(parents=True)
    with mavproxy(url, work, timeout=120, modules=None) as child:
        child.expect(r"online system 1")
        t0 = time.perf_counter()
        child.expect(r"Received (\d+) parameters")
        return time.perf_counter() - t0


def summary(name: str, xs: list[float]) -> str:
    return f"{name:<58} median {statistics.median(xs) * 1e3:8.1f} ms  max {max(xs) * 1e3:8.1f} ms  (n={len(xs)})"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--mavproxy-runs", type=int, default=3)
    a = ap.parse_args()
    proto, proto_wall, ftp, ftp_wall, loop, mp = [], [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp_s, Sitl() as sitl:
        tmp = Path(tmp_s)
        d = start_daemon(tmp / "daemon", vehicle=sitl.url, serve=["tcpin:127.0.0.1:0"], log=False)
        url = f"tcp:{d.serving[0][1]}"
        out = tmp / "pull.params"
        try:
            for _ in range(a.runs):
                dl, w = gcs_pull(url, out, ftp=False)
                proto.append(dl)
                proto_wall.append(w)
                dl, w = gcs_pull(url, out, ftp=True)
                ftp.append(dl)
                ftp_wall.append(w)
                loop.append(pymavlink_loop(url))
            mp = [mavproxy_download(url, tmp / f"mp{i}") for i in range(a.mavproxy_runs)]
            n = sum(1 for line in out.read_text().splitlines() if line and not line.startswith("#"))
        finally:
            d.stop()
    med = statistics.median
    print(f"full table pull from ArduPlane SITL through `vtol-gcs run`, loopback TCP ({n} parameters)")
    print(summary("vtol-gcs params pull --no-ftp: download", proto))
    print(summary("vtol-gcs params pull --no-ftp: whole process", proto_wall))
    print(summary("vtol-gcs params pull (FTP): download", ftp))
    print(summary("vtol-gcs params pull (FTP): whole process", ftp_wall))
    print(summary("pymavlink param_fetch_all loop", loop))
    print(summary("MAVProxy download (online -> Received)", mp))
    print(f"parameter protocol / pymavlink loop: {med(proto) / med(loop):.2f}x (target <= 1.5x); "
          f"FTP download {med(ftp) * 1e3:.0f} ms (target <= 300 ms)")


if __name__ == "__main__":
    main()
