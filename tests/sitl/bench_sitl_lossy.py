#!/usr/bin/env python3
"""The full parameter pull from ArduPlane SITL through the daemon over the network test bed
(tests/netbed, docs/network.md): SITL in the vehicle namespace behind a UDP face
(udp_bridge.py: one MAVLink frame per datagram, as a UDP vehicle sends), 200 ms of round trip in
the delay stage, the daemon in the ground namespace, `vtol-gcs params pull --target 1` in the
client namespace; lossless, then 30 % of the datagrams dropped each way. Target (issue: the
ground station for real autopilots): the lossy pull within 2x the lossless one. Needs root.

    ARDUPILOT_SITL=.../build/sitl/bin/arduplane VTOL_GCS_BIN=target/release/vtol-gcs \\
        .venv/bin/python tests/sitl/bench_sitl_lossy.py [--runs N] [--loss PCT]... [--no-ftp]

`--no-ftp` pulls with the parameter protocol (PARAM_REQUEST_LIST), else MAVLink FTP is used
where SITL offers it (it does).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "pymavlink"))
os.environ.setdefault("MAVLINK20", "1")

from daemon_support import DAEMON_BIN, script  # noqa: E402
from netbed_support import UNSUPPORTED, NetDaemon  # noqa: E402
from sitl import MODEL, SITL_BIN, defaults_file  # noqa: E402

from netbed import GROUND_CLIENT_SIDE, VEHICLE_ADDR, Bed  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--loss", type=int, action="append", help="loss levels in %% (default 0 and 30)")
    ap.add_argument("--one-way-ms", type=float, default=100.0)
    ap.add_argument("--no-ftp", action="store_true")
    ap.add_argument("--verbose", action="store_true", help="print each pull's standard error")
    a = ap.parse_args()
    if UNSUPPORTED:
        sys.exit(f"cannot run: {UNSUPPORTED}")
    if not SITL_BIN:
        sys.exit("ARDUPILOT_SITL must name the arduplane binary")
    levels = a.loss or [0, 30]
    medians = {}
    bed = Bed()
    procs: list[subprocess.Popen] = []
    daemon = None
    stop = threading.Event()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        try:
            sitl = subprocess.Popen(
                [*Bed.exec_prefix(bed.vehicle), SITL_BIN, "--model", MODEL, "--speedup", "1", "--defaults",
                 str(defaults_file()), "-I", "0", "--serial0", "tcp:0"],
                cwd=tmp, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            procs.append(sitl)
            while "SERIAL0 on TCP port" not in (line := sitl.stdout.readline()):
                if not line:
                    sys.exit("SITL exited before it listened")
            port = int(re.search(r"port (\d+)", line)[1])
            threading.Thread(target=lambda: [None for _ in sitl.stdout], daemon=True).start()
            bridge = subprocess.Popen(
                [*Bed.exec_prefix(bed.vehicle), sys.executable, str(HERE / "udp_bridge.py"),
                 "--listen", f"{VEHICLE_ADDR}:0", "--to", f"127.0.0.1:{port}"],
                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
            procs.append(bridge)
            face = bridge.stdout.readline().split()[1]
            relay = bed.start_relay(face, a.one_way_ms, 0.0, 11)
            daemon = NetDaemon.spawn(
                [*Bed.exec_prefix(bed.ground), str(DAEMON_BIN), "run", "--vehicle", f"udpout:{relay}",
                 "--headless", "--serve", f"tcpin:{GROUND_CLIENT_SIDE}:0", "--serve", f"udpin:{GROUND_CLIENT_SIDE}:0",
                 "--no-log"],
                tmp / "daemon", 2, log=False)
            with Bed.inside(bed.client):
                op = script(daemon.udp)

            def operate() -> None:
                while not stop.is_set():
                    op.beat()
                    op.m.recv_match(blocking=True, timeout=0.2)

            threading.Thread(target=operate, daemon=True).start()
            with Bed.inside(bed.client):
                g = script(daemon.tcp)
            g.wait_vehicle_heartbeat(timeout=60)
            g.close()
            extra = ["--no-ftp"] if a.no_ftp else []
            for pct in levels:
                bed.loss(pct)
                times, downloads, counts = [], [], []
                for i in range(a.runs):
                    t0 = time.monotonic()
                    r = subprocess.run([*Bed.exec_prefix(bed.client), str(DAEMON_BIN), "params", "pull", "--target",
                                        "1", *extra, "-o", str(tmp / f"pull-{pct}-{i}.parm"), "--link", daemon.tcp],
                                       capture_output=True, text=True, timeout=300, cwd=tmp)
                    wall = time.monotonic() - t0
                    if a.verbose:
                        print(r.stderr[-3000:], flush=True)
                        (tmp.parent / f"pull-{pct}-{i}.stderr").write_text(r.stderr) if os.environ.get("BENCH_KEEP") else None
                    if r.returncode != 0:
                        sys.exit(f"pull failed at {pct} % loss: {r.stderr}")
                    times.append(wall)
                    m = re.search(r"\(download ([\d.]+) (ms|s)\)", r.stderr)
                    downloads.append(float(m[1]) / (1000.0 if m[2] == "ms" else 1.0) if m else float("nan"))
                    counts.append(sum(1 for _ in open(tmp / f"pull-{pct}-{i}.parm") if _.strip() and not _.startswith("#")))
                medians[pct] = (statistics.median(times), statistics.median(downloads))
                print(f"loss {pct:>2} %  RTT {2 * a.one_way_ms:.0f} ms  {'protocol' if a.no_ftp else 'ftp'}  "
                      f"pull median {medians[pct][0]:.2f} s  min {min(times):.2f} s  max {max(times):.2f} s;  "
                      f"download median {medians[pct][1]:.2f} s;  parameters {sorted(set(counts))}  ({a.runs} runs)",
                      flush=True)
            c = bed.counters()
            print(f"bed: {c['dropped_from_vehicle']} of {c['from_vehicle']} datagrams from the vehicle dropped, "
                  f"{c['dropped_from_ground']} of {c['from_ground']} from the ground")
        finally:
            stop.set()
            if daemon is not None:
                daemon.stop()
            for p in procs:
                p.terminate()
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
            bed.close()
    if 0 in medians:
        for pct in levels:
            if pct:
                print(f"{pct} % loss / lossless: pull {medians[pct][0] / medians[0][0]:.2f}x (target <= 2x), "
                      f"download alone {medians[pct][1] / medians[0][1]:.2f}x")


if __name__ == "__main__":
    main()
