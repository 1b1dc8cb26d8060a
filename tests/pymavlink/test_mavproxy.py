"""MAVProxy 1.8.75 driven through its console (pexpect): it downloads every parameter, sets one,
arms and changes mode; the effects are checked through our own pymavlink connection."""

import re

import pytest

from conftest import FLAG_ARMED, MODES, Gcs, f32
from procs import mavproxy as launch_mavproxy


@pytest.fixture
def mavproxy(twin_factory, tmp_path):
    twin = twin_factory(speed=2)
    with launch_mavproxy(twin.tcp, tmp_path) as child:
        yield twin, child, tmp_path


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
