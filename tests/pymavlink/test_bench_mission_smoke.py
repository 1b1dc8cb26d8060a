"""The mission benchmark (bench_mission.py) still runs: two uploads and downloads of 100 items,
each download checked item by item by the benchmark itself. Timing is the benchmark's business,
never asserted here."""

import subprocess
import sys
from pathlib import Path


def test_bench_mission_runs():
    bench = Path(__file__).resolve().parent / "bench_mission.py"
    r = subprocess.run([sys.executable, str(bench), "--runs", "2"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    for what in ("upload (COUNT -> ACK)", "download (REQUEST_LIST -> last item)", "twin CPU per upload",
                 "client CPU per download", "throughput"):
        assert what in r.stdout, r.stdout
