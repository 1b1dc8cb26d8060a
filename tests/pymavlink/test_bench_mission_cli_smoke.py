"""The mission upload comparison (bench_mission_cli.py) still runs: one run of 5 items with each of
vtol-gcs, the pymavlink loop and MAVProxy, each upload checked by a download. Timing is the
benchmark's business, never asserted here."""

import subprocess
import sys
from pathlib import Path


def test_bench_mission_cli_runs():
    bench = Path(__file__).resolve().parent / "bench_mission_cli.py"
    r = subprocess.run([sys.executable, str(bench), "--items", "5", "--runs", "1"], capture_output=True, text=True,
                       timeout=180)
    assert r.returncode == 0, r.stdout + r.stderr
    for what in ("vtol-gcs mission upload: whole process incl. verify", "pymavlink loop: upload + download",
                 "MAVProxy wp load: command -> 'Sent all'", "vtol-gcs upload / pymavlink upload"):
        assert what in r.stdout, r.stdout
