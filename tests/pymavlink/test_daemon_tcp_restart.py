"""The daemon's vehicle link as a TCP client (`--vehicle tcp:127.0.0.1:PORT`) to a standalone twin.
The twin dies (SIGKILL, like a crash) and a new one comes up on the same port: the daemon
reconnects by itself (capped back-off), and its client sees the new vehicle without reconnecting
or restarting anything."""

from __future__ import annotations

import time

from conftest import MAV_TYPE_FIXED_WING
from daemon_support import daemon_factory, script, wait_vehicle_silence  # noqa: F401 (fixture)


def test_daemon_reconnects_to_restarted_twin(twin_factory, daemon_factory):  # noqa: F811
    twin = twin_factory(listen=["tcpin:127.0.0.1:0"], speed=1)
    host, port = twin.host_port("tcpin")
    daemon = daemon_factory(vehicle=f"tcp:{host}:{port}", serve=["tcpin:127.0.0.1:0"], log=False)
    g = script(daemon.tcp)
    try:
        hb = g.wait_vehicle_heartbeat(timeout=20)
        assert hb.type == MAV_TYPE_FIXED_WING, hb
        g.recv("ATTITUDE", timeout=10)

        twin_factory.twins.remove(twin)
        twin.proc.kill()
        twin.proc.wait(timeout=10)
        wait_vehicle_silence(g, quiet_s=1.0, timeout=10)

        started = time.monotonic()
        twin2 = twin_factory(listen=[f"tcpin:{host}:{port}"], speed=1)
        assert twin2.host_port("tcpin") == (host, port)
        hb = g.wait_vehicle_heartbeat(timeout=30)
        assert hb.type == MAV_TYPE_FIXED_WING, hb
        att = g.recv("ATTITUDE", timeout=10)
        # the first twin is dead, so this is the new one: its clock began after it was spawned
        age_ms = (time.monotonic() - started) * 1000
        assert att.time_boot_ms <= age_ms + 100, f"time_boot_ms {att.time_boot_ms} > {age_ms:.0f} ms since spawn"
        ack = g.command(65000, timeout=10)  # both directions work through the new connection
        assert ack.result == 3, ack
        assert daemon.alive(), daemon.tail()
    finally:
        g.close()
