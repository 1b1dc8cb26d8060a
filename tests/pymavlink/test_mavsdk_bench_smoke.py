"""The SDK benchmark (bench_sdk.py) still runs: one DroneKit connect-and-arm and one MAVSDK
connect, 10-item mission upload and download per route, each download checked by the benchmark
itself. Timing is the benchmark's business, never asserted here."""

import subprocess
import sys
from pathlib import Path


def test_bench_sdk_runs():
    bench = Path(__file__).resolve().parent / "bench_sdk.py"
    r = subprocess.run([sys.executable, str(bench), "--runs", "1", "--items", "10"], capture_output=True,
                       text=True, timeout=180)
    assert r.returncode == 0, r.stdout + r.stderr
    for route in ("direct", "daemon"):
        for what in ("DroneKit connect-to-ready", "DroneKit arm-to-armed-seen", "MAVSDK connect-to-is_armable",
                     "MAVSDK mission_raw upload, 10 items", "MAVSDK mission_raw download, 10 items"):
            assert f"{what} ({route})" in r.stdout, r.stdout
