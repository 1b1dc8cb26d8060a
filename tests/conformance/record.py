#!/usr/bin/env python3
"""Records the conformance scenarios' traces: what a vehicle answered, as one JSON file per
scenario.

Against ArduPlane SITL, a fresh SITL per scenario (its own temporary directory, so a fresh
eeprom):

    python tests/conformance/record.py --sitl-bin PATH/arduplane \\
        --sitl-defaults PATH/Tools/autotest/default_params/plane-tailsitter.parm \\
        --out tests/conformance/traces/arduplane/

Against the twin, a fresh `firmware-sim serve` per scenario (FIRMWARE_SIM_BIN or
target/debug/firmware-sim):

    python tests/conformance/record.py --twin --out /tmp/twin-traces/

Against a vehicle that is already running (not fresh: a scenario may find what an earlier one
left):

    python tests/conformance/record.py --vehicle tcp:127.0.0.1:5760 --out DIR identify params

Scenario names after the options choose which run (default: all, in their order).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

sys.path.insert(0, str(Path(__file__).resolve().parent))

from scenarios import SCENARIOS, run  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "sitl"))
from sitl import reboot_once  # noqa: E402
from vehicle import suite  # noqa: E402

# The twin's speed per kind of scenario: as fast as its telemetry still samples each flight
# phase (its telemetry rates count wall time: EXTENDED_SYS_STATE at 5 Hz is one report per 2 s
# of flight at 10 times real time, well inside a transition's 4 s).
TWIN_SPEED = {False: 4.0, True: 10.0}


@contextmanager
def sitl(binary: str, defaults: str, instance: int, speedup: float, model: str) -> Iterator[tuple[str, list[str]]]:
    """A fresh ArduPlane SITL in a temporary directory, booting at once (`--serial0 tcp:0`:
    SERIAL0 on its TCP port without waiting for a client); yields that URL and the command line."""
    with tempfile.TemporaryDirectory(prefix="conformance-sitl-") as cwd:
        cmd = [binary, "--model", model, "--speedup", f"{speedup:g}", "--defaults", defaults,
               "-I", str(instance), "--serial0", "tcp:0"]
        with open(Path(cwd) / "sitl.out", "wb") as out:
            proc = subprocess.Popen(cmd, cwd=cwd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT)
        url = f"tcp:127.0.0.1:{5760 + 10 * instance}"
        try:
            reboot_once(url)
            yield url, cmd
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@contextmanager
def twin(speed: float) -> Iterator[tuple[str, list[str]]]:
    with tempfile.TemporaryDirectory(prefix="conformance-twin-") as cwd:
        t = suite.start_twin(Path(cwd), listen=("tcpin:127.0.0.1:0",), speed=speed)
        try:
            yield t.tcp, t.args
        finally:
            t.assert_clean_exit()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    where = ap.add_mutually_exclusive_group(required=True)
    where.add_argument("--vehicle", metavar="URL", help="a running vehicle (pymavlink URL, e.g. tcp:127.0.0.1:5760)")
    where.add_argument("--sitl-bin", metavar="PATH", help="start a fresh ArduPlane SITL (this binary) per scenario")
    where.add_argument("--twin", action="store_true", help="start a fresh twin per scenario")
    ap.add_argument("--sitl-defaults", metavar="PARM", help="SITL's --defaults (plane-tailsitter.parm)")
    ap.add_argument("--sitl-model", default="plane-tailsitter")
    ap.add_argument("--instance", type=int, default=0, help="SITL's -I (ports 5760 + 10 N)")
    ap.add_argument("--speedup", type=float, default=10.0, help="SITL's --speedup")
    ap.add_argument("--out", required=True, type=Path, help="folder for the traces (NAME.json)")
    ap.add_argument("scenarios", nargs="*", help=f"of {', '.join(SCENARIOS)} (default: all)")
    a = ap.parse_args(argv)
    names = a.scenarios or list(SCENARIOS)
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        ap.error(f"unknown scenario(s) {unknown}; known: {', '.join(SCENARIOS)}")
    if a.sitl_bin and not a.sitl_defaults:
        ap.error("--sitl-bin needs --sitl-defaults")
    a.out.mkdir(parents=True, exist_ok=True)
    failed = 0
    for name in names:
        t0 = time.monotonic()
        if a.vehicle:
            trace = run(name, a.vehicle)
            how = {"vehicle": a.vehicle}
        elif a.sitl_bin:
            with sitl(a.sitl_bin, a.sitl_defaults, a.instance, a.speedup, a.sitl_model) as (url, cmd):
                trace = run(name, url)
            how = {"sitl": " ".join(shlex.quote(c) for c in cmd), "cwd": "a fresh temporary directory",
                   "reboot": "once after its first boot, before the scenario (record.py's reboot_once)"}
        else:
            with twin(TWIN_SPEED[SCENARIOS[name][1]]) as (url, cmd):
                trace = run(name, url)
            how = {"twin": " ".join(shlex.quote(c) for c in cmd)}
        trace["recorded_with"] = how
        (a.out / f"{name}.json").write_text(json.dumps(trace, indent=1, sort_keys=False) + "\n")
        status = "error: " + trace["error"] if "error" in trace else "ok"
        failed += "error" in trace
        print(f"{name}: {time.monotonic() - t0:.1f} s, {status}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    os.environ.setdefault("MAVLINK20", "1")
    sys.exit(main())
