#!/usr/bin/env python3
"""Parameter download and upload benchmark, side by side against the same twin over loopback TCP.

    cargo build --release --workspace --bins
    FIRMWARE_SIM_BIN=target/release/firmware-sim VTOL_GCS_BIN=target/release/vtol-gcs \\
        .venv/bin/python tests/pymavlink/bench_params.py [--runs N]

Prints, for a full pull of the twin's table:
  - `vtol-gcs params pull` (the whole process: start, connect, find the vehicle, pull, write the
    file), its wall time and its CPU time (user + system, from getrusage);
  - a bare pymavlink loop (`param_fetch_all`, then PARAM_VALUEs until every index is in; no
    re-requests) timed from after the vehicle heartbeat, as a script would;
  - MAVProxy 1.8.75's download, from its "online system" line to "Received N parameters";
then `vtol-gcs params pull` at 5 % frame loss each way (target: within 2x the lossless time), and
at 30 % loss each way a pull plus a verified push of the 12 controller gains
(`vtol-gcs params push`, which pulls, writes, reads every value back), target < 3 s.
Medians and maxima of N runs; every run must succeed.
"""

from __future__ import annotations

import argparse
import re
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("MAVLINK20", "1")

from conftest import start_twin  # noqa: E402
from daemon_support import DAEMON_BIN  # noqa: E402
from procs import mavproxy  # noqa: E402
from pymavlink import mavutil  # noqa: E402

GAINS = ["LAT_SAT_A", "LAT_SAT_B", "LAT_SAT_C", "LAT_SAT_D", "LON_SAT_A", "LON_SAT_B", "LON_SAT_C",
         "LON_SAT_D", "ALT_KD", "ALT_KP", "YAW_KD", "YAW_KP"]
SET_A = dict(zip(GAINS, [1.2, 0.6, 0.22, 0.18, 1.2, 0.6, 0.22, 0.18, 2, 5, 5, 5]))
SET_B = dict(zip(GAINS, [0.4, 0.2, 0.1, 0.05, 0.4, 0.2, 0.1, 0.05, 2.5, 4.5, 4.5, 4.5]))


def timed(args: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of one child process, which must exit 0."""
    return timed_full(args)[:2]


def timed_full(args: list[str]) -> tuple[float, float, str]:
    """Wall and CPU seconds and standard error of one child process, which must exit 0."""
    wall, cpu, r = timed_run(args)
    return wall, cpu, r.stderr


def timed_run(args: list[str]) -> tuple[float, float, subprocess.CompletedProcess]:
    """Wall and CPU seconds and the outcome of one child process, which must exit 0."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(args, capture_output=True, text=True, timeout=120)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed ({r.returncode}): {r.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, r


def gcs_pull(url: str, out: Path) -> tuple[float, float, float]:
    """Whole-process wall and CPU seconds, and the download alone as the client reports it
    (from its PARAM_REQUEST_LIST to the last value, after the vehicle was found)."""
    wall, cpu, err = timed_full([str(DAEMON_BIN), "params", "pull", "-o", str(out), "--link", url])
    m = re.search(r"download ([0-9.]+) ms", err)
    if not m:
        raise SystemExit(f"no download time in: {err}")
    return wall, cpu, float(m[1]) / 1e3


def pymavlink_loop(url: str) -> float:
    m = mavutil.mavlink_connection(url, source_system=255, source_component=190)
    try:
        m.recv_match(type="HEARTBEAT", condition="HEARTBEAT.type!=6", blocking=True, timeout=10)
        t0 = time.perf_counter()
        m.param_fetch_all()
        seen: set[int] = set()
        count = None
        while count is None or len(seen) < count:
            p = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=10)
            if p is None:
                raise SystemExit(f"pymavlink loop: stalled at {len(seen)} of {count}")
            count = p.param_count
            seen.add(p.param_index)
        return time.perf_counter() - t0
    finally:
        m.close()


def mavproxy_download(url: str, work: Path) -> float:
    work.mkdir(parents=True)
    with mavproxy(url, work, timeout=60) as child:
        child.expect(r"online system 1")
        t0 = time.perf_counter()
        child.expect(r"Received (\d+) parameters")
        return time.perf_counter() - t0


def summary(name: str, xs: list[float], unit: float = 1e3, suffix: str = "ms") -> str:
    return (f"{name:<52} median {statistics.median(xs) * unit:8.1f} {suffix}"
            f"  max {max(xs) * unit:8.1f} {suffix}  (n={len(xs)})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--mavproxy-runs", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        lossless = start_twin(tmp / "t0", listen=["tcpin:127.0.0.1:0"], speed=1)
        lossy5 = start_twin(tmp / "t5", listen=["tcpin:127.0.0.1:0"], speed=1, seed=5, extra=["--loss", "0.05"])
        lossy30 = start_twin(tmp / "t30", listen=["tcpin:127.0.0.1:0"], speed=1, seed=30, extra=["--loss", "0.3"])
        try:
            out = tmp / "pull.param"
            gcs_wall, gcs_cpu, gcs_dl = zip(*(gcs_pull(lossless.tcp, out) for _ in range(args.runs)))
            loop = [pymavlink_loop(lossless.tcp) for _ in range(args.runs)]
            mp = [mavproxy_download(lossless.tcp, tmp / f"mp{i}") for i in range(args.mavproxy_runs)]
            g5_wall, _, g5_dl = zip(*(gcs_pull(lossy5.tcp, out) for _ in range(args.runs)))
            files = []
            for name, values in (("a", SET_A), ("b", SET_B)):
                f = tmp / f"gains_{name}.param"
                f.write_text("".join(f"{k} {v}\n" for k, v in values.items()))
                files.append(f)
            push30 = []
            cpu30 = []
            # Alternate B, A, B, A...: every push changes all 12 gains (the twin starts at A).
            for i in range(args.runs):
                w, c = timed([str(DAEMON_BIN), "params", "push", str(files[(i + 1) % 2]), "--link", lossy30.tcp])
                push30.append(w)
                cpu30.append(c)
            g30_wall, _, g30_dl = zip(*(gcs_pull(lossy30.tcp, out) for _ in range(args.runs)))
            n = sum(1 for line in out.read_text().splitlines() if line and not line.startswith("#"))
        finally:
            for t in (lossless, lossy5, lossy30):
                t.stop()
    print(f"full table pull over loopback TCP ({n} parameters)")
    print(summary("vtol-gcs params pull: download (after vehicle found)", list(gcs_dl)))
    print(summary("vtol-gcs params pull: whole process, wall", list(gcs_wall)))
    print(summary("vtol-gcs params pull: whole process, CPU", list(gcs_cpu)))
    print(summary("pymavlink param_fetch_all loop (after heartbeat)", loop))
    print(summary("MAVProxy download (online -> Received)", mp))
    med = statistics.median
    print(f"download: MAVProxy / vtol-gcs {med(mp) / med(gcs_dl):.0f}x, "
          f"vtol-gcs / pymavlink loop {med(gcs_dl) / med(loop):.2f}x; "
          f"whole vtol-gcs process / pymavlink loop {med(gcs_wall) / med(loop):.2f}x")
    print(summary("vtol-gcs download at 5 % loss each way", list(g5_dl)))
    print(summary("vtol-gcs params pull at 5 % loss, whole process", list(g5_wall)))
    print(f"5 % loss / lossless download: {med(g5_dl) / med(gcs_dl):.2f}x")
    print(summary("vtol-gcs download at 30 % loss each way", list(g30_dl)))
    print(summary("vtol-gcs params pull at 30 % loss, whole process", list(g30_wall)))
    print(summary("12-gain push (pull + write + read-back) at 30 %, wall", push30))
    print(summary("12-gain push at 30 %, CPU", cpu30))


if __name__ == "__main__":
    main()
