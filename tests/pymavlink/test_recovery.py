"""Recovery from a crash with the ground station's own tools: `vtol-gcs arm` on a crashed
vehicle fails and says how to recover, `vtol-gcs reboot` clears the crash (and is refused while
armed), after which the vehicle arms again. Checked independently with pymavlink."""

from __future__ import annotations

import subprocess

from conftest import MAV_CMD_COMPONENT_ARM_DISARM, MAV_RESULT_ACCEPTED, MAV_STATE_STANDBY
from daemon_support import DAEMON_BIN

MAV_STATE_EMERGENCY = 6
FORCE_MAGIC = 21196


def gcs(*args: str, link: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(DAEMON_BIN), *args, "--link", link], capture_output=True,
                          text=True, timeout=60)


def test_cli_reboot_clears_a_crash(twin_factory, gcs_factory):
    twin = twin_factory(speed=4)
    g = gcs_factory(twin.tcp)
    g.wait_ready()
    g.set_mode("QHOVER")
    g.arm()
    # Armed: the reboot is refused, exit status 1, with the reason.
    r = gcs("reboot", link=twin.tcp)
    assert r.returncode == 1, r
    assert "disarmed" in r.stderr, r.stderr
    # In the air, cut the motors: a crash.
    g.recv("LOCAL_POSITION_NED", lambda p: p.z < -0.8, timeout=30)
    ack = g.command(MAV_CMD_COMPONENT_ARM_DISARM, 0, FORCE_MAGIC)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    g.wait_vehicle_heartbeat(timeout=20, pred=lambda h: h.system_status == MAV_STATE_EMERGENCY)

    r = gcs("arm", link=twin.tcp)
    assert r.returncode == 1, r
    assert "crashed" in r.stderr and "vtol-gcs reboot" in r.stderr, r.stderr

    r = gcs("reboot", link=twin.tcp)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "rebooting"
    g.wait_vehicle_heartbeat(timeout=30, pred=lambda h: h.system_status == MAV_STATE_STANDBY)
    r = gcs("arm", link=twin.tcp)
    assert r.returncode == 0, r.stderr
