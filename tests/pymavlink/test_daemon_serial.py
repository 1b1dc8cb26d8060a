"""The daemon's vehicle link over a serial pseudo-terminal pair (socat with fixed link names):
the twin on one end, the daemon on the other, a pymavlink script on the daemon's tcpin. When the
pty pair vanishes (socat killed) and comes back under the same names, both the twin and the
daemon reopen their devices by themselves: the script sees vehicle heartbeats again, with the
same daemon and twin processes, the first frame less than a second after the devices return.
"""

from __future__ import annotations

import time

from conftest import MAV_TYPE_FIXED_WING, VEHICLE_SYSID
from daemon_support import Socat, daemon_factory, script, wait_vehicle_silence  # noqa: F401 (fixture)


def test_serial_vehicle_link_survives_pty_restart(twin_factory, daemon_factory, tmp_path):  # noqa: F811
    vehicle_end, gcs_end = tmp_path / "vehicle", tmp_path / "gcs"
    socat = Socat(vehicle_end, gcs_end)
    socat.start()
    try:
        twin = twin_factory(listen=[f"serial:{vehicle_end}:115200"], speed=1)
        daemon = daemon_factory(vehicle=f"serial:{gcs_end}:115200", serve=["tcpin:127.0.0.1:0"], log=False)
        g = script(daemon.tcp)
        try:
            hb = g.wait_vehicle_heartbeat(timeout=20)
            assert hb.type == MAV_TYPE_FIXED_WING, hb
            before = g.recv("ATTITUDE", timeout=10)

            socat.stop()  # both ptys close under the twin and the daemon
            assert not vehicle_end.exists() and not gcs_end.exists()
            wait_vehicle_silence(g, quiet_s=1.0, timeout=10)

            socat.start()  # same link names, new /dev/pts devices
            back = time.monotonic()  # the devices exist again from here
            first = None
            while first is None:
                assert time.monotonic() - back < 10, "no vehicle frame within 10 s of the replug"
                m = g.m.recv_match(blocking=True, timeout=0.05)
                if m is not None and m.get_srcSystem() == VEHICLE_SYSID:
                    first = time.monotonic() - back
            # both ends reopen their device within SERIAL_REOPEN_MAX (250 ms) of its return
            assert first < 1.0, f"the link resumed {first * 1000:.0f} ms after the device returned"
            print(f"link resumed {first * 1000:.0f} ms after the device returned")
            hb = g.wait_vehicle_heartbeat(timeout=30)
            assert hb.type == MAV_TYPE_FIXED_WING, hb
            after = g.recv("ATTITUDE", timeout=10)
            # the same twin, still running: its clock went on
            assert after.time_boot_ms > before.time_boot_ms, (before, after)
            # and the link keeps working both ways: a command is answered through it
            ack = g.command(65000, timeout=10)
            assert ack.result == 3, ack
            assert twin.alive(), twin.stderr()[-3000:]
            assert daemon.alive(), daemon.tail()
        finally:
            g.close()
    finally:
        socat.stop()
