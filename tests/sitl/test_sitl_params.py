"""`vtol-gcs params` against real ArduPlane SITL (QuadPlane tailsitter), through `vtol-gcs run`
as a user runs it. Skipped unless `ARDUPILOT_SITL` names the arduplane binary (tests/sitl/sitl.py).

    ARDUPILOT_SITL=.../build/sitl/bin/arduplane VTOL_GCS_BIN=target/release/vtol-gcs \\
        .venv/bin/python -m pytest -s tests/sitl

Each check is made independently with pymavlink on SITL's second serial port. The times of
each command are printed (`-s` shows them).
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "pymavlink"))
os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

from daemon_support import DAEMON_BIN, start_daemon  # noqa: E402
from sitl import SITL_BIN, Sitl  # noqa: E402

pytestmark = pytest.mark.skipif(not SITL_BIN, reason="ARDUPILOT_SITL does not name an arduplane binary")

GAINS = ["Q_A_RAT_RLL_P", "Q_A_RAT_RLL_I", "Q_A_RAT_RLL_D", "Q_A_RAT_PIT_P", "Q_A_RAT_PIT_I",
         "Q_A_RAT_PIT_D", "Q_A_RAT_YAW_P", "Q_A_RAT_YAW_I"]
# An internal parameter ArduPilot refuses to set over MAVLink ("Param write denied").
DENIED = "MIS_TOTAL"


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


class Direct:
    """pymavlink on SITL's SERIAL1: the independent view."""

    def __init__(self, url: str):
        self.m = mavutil.mavlink_connection(url, source_system=250, source_component=190)
        self.m.wait_heartbeat(timeout=30)

    def get(self, name: str, timeout: float = 5.0) -> float:
        """A fresh read: what came before (the echoes ArduPilot sends every link) is dropped."""
        while self.m.recv_match(blocking=False) is not None:
            pass
        deadline = time.monotonic() + timeout
        while True:
            self.m.mav.param_request_read_send(self.m.target_system, 1, name.encode(), -1)
            msg = self.m.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            while msg is not None and msg.param_id != name:
                msg = self.m.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            if msg is not None:
                return msg.param_value
            assert time.monotonic() < deadline, f"no answer for {name}"

    def close(self) -> None:
        self.m.close()


@pytest.fixture(scope="module")
def sitl():
    with Sitl() as s:
        yield s


@pytest.fixture(scope="module")
def link(sitl, tmp_path_factory):
    d = start_daemon(tmp_path_factory.mktemp("daemon"), vehicle=sitl.url, serve=["tcpin:127.0.0.1:0"], log=False)
    yield f"tcp:{d.serving[0][1]}"
    d.stop()


@pytest.fixture(scope="module")
def direct(sitl):
    d = Direct(sitl.url1)
    yield d
    d.close()


def gcs(*args: str, link: str, timeout: float = 120.0) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    r = subprocess.run([str(DAEMON_BIN), *args, "--link", link], capture_output=True, text=True, timeout=timeout)
    took = time.monotonic() - t0
    print(f"\n  vtol-gcs {' '.join(args)}: exit {r.returncode} in {took:.2f} s")
    return r, took


def qgc_table(path: Path) -> dict[str, float]:
    rows = [line.split("\t") for line in path.read_text().splitlines() if line and not line.startswith("#")]
    return {r[2]: float(r[3]) for r in rows}


def test_pull_reads_every_parameter(link, direct, tmp_path):
    out = tmp_path / "all.params"
    r, took = gcs("params", "pull", "-o", str(out), link=link)
    assert r.returncode == 0, r.stderr
    got = qgc_table(out)
    assert len(got) > 1000, len(got)
    for name in [*GAINS, "Q_TAILSIT_ENABLE", "Q_ENABLE"]:
        assert f32(got[name]) == f32(direct.get(name)), name
    print(f"  {len(got)} parameters; {r.stderr.strip()}")


def test_get_alone_and_while_another_pull_runs(link, direct):
    r, _ = gcs("params", "get", "Q_A_RAT_RLL_P", "Q_TAILSIT_ENABLE", link=link)
    assert r.returncode == 0, r.stderr
    words = r.stdout.split()
    assert f32(float(words[1])) == f32(direct.get("Q_A_RAT_RLL_P"))
    pulls = []
    t = threading.Thread(target=lambda: pulls.append(gcs("params", "pull", link=link)))
    t.start()
    r, _ = gcs("params", "get", "Q_A_RAT_RLL_P", "Q_TAILSIT_ENABLE", link=link)
    t.join(timeout=120)
    assert r.returncode == 0, r.stderr
    assert pulls and pulls[0][0].returncode == 0


def test_set_is_verified_and_kept(link, direct):
    before = direct.get("Q_A_RAT_RLL_P")
    r, _ = gcs("params", "set", "Q_A_RAT_RLL_P", "0.26", link=link)
    assert r.returncode == 0, r.stderr + r.stdout
    assert direct.get("Q_A_RAT_RLL_P") == f32(0.26)
    r, _ = gcs("params", "set", "Q_A_RAT_RLL_P", f"{before:.9g}", link=link)
    assert r.returncode == 0, r.stderr + r.stdout
    assert direct.get("Q_A_RAT_RLL_P") == before


def test_save_and_diff(link, tmp_path):
    saved = tmp_path / "saved.params"
    r, _ = gcs("params", "save", str(saved), link=link)
    assert r.returncode == 0, r.stderr
    r, _ = gcs("params", "diff", str(saved), link=link)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.strip().endswith("0 differ"), r.stdout


def test_push_with_a_refused_value_is_rolled_back_exactly(link, direct, tmp_path):
    before = {n: direct.get(n) for n in [*GAINS, DENIED]}
    f = tmp_path / "gains.parm"
    lines = [f"{n} {before[n] * 1.5 + 0.01:.6g}" for n in GAINS] + [f"{DENIED} {before[DENIED] + 1:g}"]
    f.write_text("\n".join(lines) + "\n")
    r, _ = gcs("params", "push", str(f), link=link)
    assert r.returncode == 1, r.stderr + r.stdout
    assert f"{DENIED} refused" in r.stderr, r.stderr
    print(f"  {r.stderr.strip()}")
    after = {n: direct.get(n) for n in before}
    assert after == before
