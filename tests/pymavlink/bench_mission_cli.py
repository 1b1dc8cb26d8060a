#!/usr/bin/env python3
"""`vtol-gcs mission upload` against a bare pymavlink loop and MAVProxy's `wp load`, side by side
against one twin over loopback TCP.

    cargo build --release --workspace --bins
    FIRMWARE_SIM_BIN=target/release/firmware-sim VTOL_GCS_BIN=target/release/vtol-gcs \\
        .venv/bin/python tests/pymavlink/bench_mission_cli.py [--items 500] [--runs N]

A QGC WPL 110 file of ITEMS items (home slot, then waypoints on a spiral, bench_mission.py's
mission) is uploaded N times by each of, in turn within each run:
  - `vtol-gcs mission upload FILE --link tcp:... --target 1`, the whole process (start, connect,
    find the vehicle, read the file, upload, then download the list again and compare: the
    verify download is included), its wall and CPU time (getrusage), and its own upload figure
    (from its first MISSION_COUNT to the MISSION_ACK, whole milliseconds); then the same
    without --target, which waits 1.2 s to be sure only one vehicle answers;
  - a bare pymavlink loop on a connection held open (bench_mission.py's: MISSION_COUNT, each
    MISSION_REQUEST(_INT) answered with its MISSION_ITEM_INT, to the MISSION_ACK), then its
    download of the list, checked item by item: upload alone and upload + download;
  - MAVProxy 1.8.75's `wp load FILE` in one MAVProxy kept running (after its parameter
    download), from the command to its "Sent all N waypoints" line, printed when it answers the
    last request (it does not wait for the ACK); then the list is downloaded by pymavlink and
    checked (outside the timing; positions to within 1e-7 degree, as MAVProxy truncates
    degrees x 1e7 with int()).
The twin runs at --speed 0.01, its telemetry at the default wall-clock rates. Client CPU per
transfer: vtol-gcs from getrusage (whole process), pymavlink from process_time, MAVProxy from
/proc over the transfer (its idle loop included). Medians and maxima; every run must succeed.
"""

from __future__ import annotations

import argparse
import math
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_mission import download, mission, recv, twin_cpu_s, upload  # noqa: E402
from bench_params import DAEMON_BIN, timed_run  # noqa: E402
from conftest import start_twin  # noqa: E402
from procs import MAVPROXY_MODULES, mavproxy  # noqa: E402
from pymavlink import mavutil  # noqa: E402


def write_wpl(items, path: Path) -> None:
    """The items as QGC WPL 110 (degrees with 7 decimals: exact to the 1e-7 of the INT items)."""
    lines = ["QGC WPL 110"]
    for it in items:
        p = [f"{v:g}" if not math.isnan(v) else "nan" for v in (it.param1, it.param2, it.param3, it.param4)]
        lines.append("\t".join([str(it.seq), "1" if it.seq == 0 else "0", str(it.frame), str(it.command), *p,
                                f"{it.x / 1e7:.7f}", f"{it.y / 1e7:.7f}", f"{it.z:g}", str(it.autocontinue)]))
    path.write_text("\n".join(lines) + "\n")


def drain(m) -> None:
    """Drops what the twin sent this connection meanwhile (it also tells every client about other
    clients' transfers), so that the next exchange reads only its own answers."""
    while m.recv_match(blocking=False) is not None:
        pass


def gcs_upload(path: Path, url: str, *extra: str) -> tuple[float, float, float, float]:
    """Whole-process wall and CPU seconds, and the upload and its verify download as vtol-gcs
    reports them (from its first MISSION_COUNT to the ACK, then the download)."""
    wall, cpu, r = timed_run([str(DAEMON_BIN), "mission", "upload", str(path), "--link", url, *extra])
    got = re.search(r"uploaded (\d+) mission items .*verified by download; upload ([0-9.]+) ms, verify ([0-9.]+) ms",
                    r.stdout)
    if not got:
        raise SystemExit(f"unexpected output: {r.stdout}{r.stderr}")
    return wall, cpu, float(got[2]) / 1e3, float(got[3]) / 1e3


def summary(name: str, xs: list[float]) -> str:
    return f"{name:<54} median {statistics.median(xs) * 1e3:8.1f} ms  max {max(xs) * 1e3:8.1f} ms  (n={len(xs)})"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--items", type=int, default=500)
    ap.add_argument("--runs", type=int, default=10)
    args = ap.parse_args()
    n_items = args.items
    r: dict[str, list[float]] = {k: [] for k in (
        "gcs_up", "gcs_upverify", "gcs_wall", "gcs_cpu", "gcs_any_wall", "py_up", "py_updown", "py_cpu_up", "py_cpu_updown",
        "mp_wall", "mp_own", "mp_cpu")}
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        twin = start_twin(tmp / "twin", listen=["tcpin:127.0.0.1:0"], speed=0.01)
        m = mavutil.mavlink_connection(twin.tcp, source_system=255, source_component=190)
        try:
            recv(m, "HEARTBEAT", 10)
            items = mission((1, 1), n_items)
            plan = tmp / "mission.waypoints"
            write_wpl(items, plan)
            (tmp / "mp").mkdir()
            with mavproxy(twin.tcp, tmp / "mp", modules=MAVPROXY_MODULES + ",wp", timeout=120) as mp:
                mp.expect(r"Received \d+ parameters")
                for _ in range(args.runs):
                    wall, cpu, up, verify = gcs_upload(plan, twin.tcp, "--target", "1")
                    r["gcs_wall"].append(wall)
                    r["gcs_cpu"].append(cpu)
                    r["gcs_up"].append(up)
                    r["gcs_upverify"].append(up + verify)
                    r["gcs_any_wall"].append(gcs_upload(plan, twin.tcp)[0])

                    drain(m)
                    p0 = time.process_time()
                    up = upload(m, items)
                    p1 = time.process_time()
                    down = download(m, items)
                    p2 = time.process_time()
                    r["py_up"].append(up)
                    r["py_updown"].append(up + down)
                    r["py_cpu_up"].append(p1 - p0)
                    r["py_cpu_updown"].append(p2 - p0)

                    c0, t0 = twin_cpu_s(mp.pid), time.perf_counter()
                    mp.sendline(f"wp load {plan}")
                    mp.expect(rf"Loaded {n_items} waypoints in ([0-9.]+)s")
                    own = float(mp.match[1])
                    mp.expect(rf"Sent all {n_items} waypoints")
                    r["mp_wall"].append(time.perf_counter() - t0)
                    r["mp_cpu"].append(twin_cpu_s(mp.pid) - c0)
                    r["mp_own"].append(own)
                    drain(m)
                    download(m, items, pos_tol=1)
        finally:
            m.close()
            twin.stop()
    med = statistics.median
    print(f"{n_items}-item mission upload over loopback TCP to one twin, {args.runs} runs each, side by side")
    print(summary("vtol-gcs mission upload: upload (COUNT -> ACK)", r["gcs_up"]))
    print(summary("vtol-gcs mission upload: upload + verify download", r["gcs_upverify"]))
    print(summary("vtol-gcs mission upload: whole process incl. verify, wall", r["gcs_wall"]))
    print(summary("vtol-gcs mission upload: whole process, CPU", r["gcs_cpu"]))
    print(summary("the same without --target (waits to hear every vehicle)", r["gcs_any_wall"]))
    print(summary("pymavlink loop: upload (COUNT -> ACK)", r["py_up"]))
    print(summary("pymavlink loop: upload + download", r["py_updown"]))
    print(summary("pymavlink loop: CPU per upload", r["py_cpu_up"]))
    print(summary("pymavlink loop: CPU per upload + download", r["py_cpu_updown"]))
    print(summary("MAVProxy wp load: command -> 'Sent all'", r["mp_wall"]))
    print(summary("MAVProxy wp load: its own figure (COUNT -> last item)", r["mp_own"]))
    print(summary("MAVProxy wp load: its CPU over the transfer", r["mp_cpu"]))
    print(f"vtol-gcs upload / pymavlink upload {med(r['gcs_up']) / med(r['py_up']):.2f}x; "
          f"vtol-gcs upload + verify / pymavlink upload {med(r['gcs_upverify']) / med(r['py_up']):.2f}x (target <= 1.5x); "
          f"vtol-gcs whole process / pymavlink upload + download {med(r['gcs_wall']) / med(r['py_updown']):.2f}x; "
          f"MAVProxy / vtol-gcs whole process {med(r['mp_wall']) / med(r['gcs_wall']):.2f}x")


if __name__ == "__main__":
    main()
