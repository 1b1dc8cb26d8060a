"""MAVProxy 1.8.75 driven through its console (pexpect): it downloads every parameter, sets one,
arms and changes mode; the effects are checked through our own pymavlink connection."""

import os
import re
import shutil
import signal
import sys
from pathlib import Path

import pexpect
import pytest

from conftest import FLAG_ARMED, MODES, Gcs, f32

MAVPROXY = Path(sys.executable).parent / "mavproxy.py"


@pytest.fixture
def mavproxy(twin_factory, tmp_path):
    twin = twin_factory(speed=2)
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MAVLINK20")}
    env.update(HOME=str(home), TERM="dumb", PYTHONUNBUFFERED="1")
    exe = str(MAVPROXY) if MAVPROXY.exists() else shutil.which("mavproxy.py")
    assert exe, "mavproxy.py not installed in the venv"
    args = [
        exe,
        "--master", twin.tcp,
        "--streamrate=-1",
        "--state-basedir", str(tmp_path / "state"),
        "--aircraft", "twin",
        "--default-modules", "log,signing,ftp,param,arm,mode,cmdlong,misc",
    ]
    log = open(tmp_path / "mavproxy.out", "w")
    child = pexpect.spawn(sys.executable, args, cwd=str(tmp_path), env=env, encoding="utf-8",
                          timeout=60, codec_errors="replace")
    child.logfile_read = log
    try:
        yield twin, child, tmp_path
    finally:
        if child.isalive():
            child.kill(signal.SIGTERM)  # MAVProxy's quit handler sets its stop event…
            child.sendline("")  # …which its console loop checks after the next line
            try:
                child.expect(pexpect.EOF, timeout=15)
            except (pexpect.TIMEOUT, pexpect.EOF):
                pass
        child.close(force=True)
        log.close()


def test_mavproxy_params_arm_mode(mavproxy, gcs_factory):
    twin, child, tmp = mavproxy
    observer: Gcs = gcs_factory(twin.udp)
    observer.wait_vehicle_heartbeat()
    child.expect(r"Received (\d+) parameters", timeout=90)
    n = int(child.match.group(1))
    count = observer.param_get("HOVER_ALT").param_count
    assert n == count, f"MAVProxy got {n} parameters, the twin has {count}"
    # the parameter cache MAVProxy writes (mav.parm, D.3) holds them too
    parms = list((tmp / "state").rglob("mav.parm"))
    assert parms, f"no mav.parm under {tmp / 'state'}"
    text = parms[0].read_text()
    assert re.search(r"^HOVER_ALT\s+1\.0+$", text, re.M), text[:500]

    child.sendline("param set HOVER_ALT 1.2")
    observer.recv("PARAM_VALUE", lambda p: p.param_id == "HOVER_ALT" and p.param_value == f32(1.2), timeout=15,
                  what="HOVER_ALT = 1.2 set by MAVProxy")
    assert observer.param_get("HOVER_ALT").param_value == f32(1.2)

    observer.wait_ready()
    child.sendline("arm throttle")
    observer.wait_vehicle_heartbeat(timeout=15, pred=lambda h: h.base_mode & FLAG_ARMED)
    child.sendline("mode QHOVER")
    observer.wait_vehicle_heartbeat(timeout=15, pred=lambda h: h.custom_mode == MODES["QHOVER"])
    # MAVProxy saw the ACK and the mode change in the heartbeat (not the echo of "mode QHOVER")
    child.expect("Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", timeout=15)
    child.expect(r"Mode QHOVER", timeout=15)
    child.sendline("mode QLAND")
    observer.wait_vehicle_heartbeat(timeout=15, pred=lambda h: h.custom_mode == MODES["QLAND"])
    assert child.isalive()
