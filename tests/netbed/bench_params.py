#!/usr/bin/env python3
"""Parameter pull through the daemon over the test bed's vehicle link: 200 ms of round trip
(100 ms each way in the delay stage), lossless and then with 30 % of the datagrams dropped each
way (nftables). Target: the lossy pull within 2x the lossless one (docs/benchmarks/network.md).

    cargo build --release --bins
    FIRMWARE_SIM_BIN=target/release/firmware-sim VTOL_GCS_BIN=target/release/vtol-gcs \\
        .venv/bin/python tests/netbed/bench_params.py [--runs N] [--loss PCT]...

Each run is a whole `vtol-gcs params pull --target 1` process in the client namespace (start,
connect to the daemon, find the vehicle, probe the round trip, pull the table, write the file);
it must succeed. (`--target` names the vehicle: without it the command waits a heartbeat period
for a second vehicle before it picks the only one.) Prints, per loss level, the median, minimum
and maximum of the process's wall time and of the download alone (the time the command reports:
from the list request to the last value), and the ratios of the medians. Needs root.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "pymavlink"))
os.environ.setdefault("MAVLINK20", "1")

from netbed_support import UNSUPPORTED, Scene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--loss", type=int, action="append", help="loss levels in %% (default 0 and 30)")
    ap.add_argument("--one-way-ms", type=float, default=100.0)
    a = ap.parse_args()
    if UNSUPPORTED:
        sys.exit(f"cannot run: {UNSUPPORTED}")
    levels = a.loss or [0, 30]
    medians = {}
    with tempfile.TemporaryDirectory() as tmp:
        s = Scene(Path(tmp), delay_ms=a.one_way_ms, seed=11)
        try:
            g = s.client()
            g.wait_vehicle_heartbeat(timeout=30)
            for pct in levels:
                s.bed.loss(pct)
                times, downloads = [], []
                for i in range(a.runs):
                    wall, r = s.cli("params", "pull", "--target", "1", "-o", str(Path(tmp) / f"pull-{pct}-{i}.parm"))
                    if r.returncode != 0:
                        sys.exit(f"pull failed at {pct} % loss: {r.stderr}")
                    times.append(wall)
                    m = re.search(r"\(download ([\d.]+) (ms|s)\)", r.stderr)
                    if m is None:
                        sys.exit(f"no download time in {r.stderr!r}")
                    downloads.append(float(m[1]) / (1000.0 if m[2] == "ms" else 1.0))
                medians[pct] = (statistics.median(times), statistics.median(downloads))
                print(f"loss {pct:>2} %  RTT {2 * a.one_way_ms:.0f} ms  pull median {medians[pct][0]:.2f} s  "
                      f"min {min(times):.2f} s  max {max(times):.2f} s;  download median {medians[pct][1]:.2f} s  "
                      f"min {min(downloads):.2f} s  max {max(downloads):.2f} s  ({a.runs} runs)", flush=True)
            c = s.bed.counters()
            print(f"bed: {c['dropped_from_vehicle']} of {c['from_vehicle']} datagrams from the vehicle dropped, "
                  f"{c['dropped_from_ground']} of {c['from_ground']} from the ground")
        finally:
            s.close()
    if 0 in medians:
        for pct in levels:
            if pct:
                print(f"{pct} % loss / lossless: pull {medians[pct][0] / medians[0][0]:.2f}x (target <= 2x), "
                      f"download alone {medians[pct][1] / medians[0][1]:.2f}x")


if __name__ == "__main__":
    main()
