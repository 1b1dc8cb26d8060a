"""The parameter benchmark (bench_params.py) still runs: one run of each measurement, output
checked for every line. Timing is the benchmark's business, never asserted here."""

import subprocess
import sys
from pathlib import Path


def test_bench_params_runs_once():
    bench = Path(__file__).resolve().parent / "bench_params.py"
    r = subprocess.run([sys.executable, str(bench), "--runs", "1", "--mavproxy-runs", "1"],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stdout + r.stderr
    for what in ("vtol-gcs params pull: download", "pymavlink param_fetch_all loop",
                 "MAVProxy download", "at 5 % loss", "at 30 % loss", "12-gain push"):
        assert what in r.stdout, r.stdout
