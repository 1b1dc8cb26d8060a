"""Connecting: pymavlink scripts over TCP and UDP (several at once), identity fields of the
heartbeat, mode names, target discovery, and a MAVLink-1-first script (no MAVLINK20)."""

import json
import os
import socket
import subprocess
import sys
import textwrap

from conftest import (
    FLAG_ARMED,
    FLAG_CUSTOM_MODE,
    MAV_AUTOPILOT_ARDUPILOTMEGA,
    MAV_TYPE_FIXED_WING,
    MODES,
    VEHICLE_SYSID,
    f32,
)


def check_vehicle_heartbeat(g):
    hb = g.wait_vehicle_heartbeat()
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert hb.type == MAV_TYPE_FIXED_WING
    assert hb.autopilot == MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.base_mode & FLAG_CUSTOM_MODE, hb
    assert not hb.base_mode & FLAG_ARMED, hb
    assert hb.custom_mode in MODES.values(), hb
    assert hb.mavlink_version == 3
    # pymavlink learnt the vehicle from this heartbeat.
    assert g.m.target_system == VEHICLE_SYSID
    mapping = g.m.mode_mapping()
    for name, number in MODES.items():
        assert mapping.get(name) == number, (name, mapping)
    assert g.m.flightmode in MODES, g.m.flightmode
    assert not g.m.motors_armed()
    return hb


def test_two_tcp_and_two_udp_clients_at_once(twin, gcs_factory):
    clients = [gcs_factory(twin.tcp), gcs_factory(twin.tcp), gcs_factory(twin.udp), gcs_factory(twin.udp)]
    for g in clients:
        check_vehicle_heartbeat(g)
    # Each client gets its own answer (the UDP server replies to every peer, not the last one).
    for g in clients:
        p = g.param_get("HOVER_ALT")
        assert p.param_count > 0 and 0 <= p.param_index < p.param_count
    # And every client keeps receiving the vehicle's heartbeats afterwards.
    for g in clients:
        g.wait_vehicle_heartbeat(timeout=10)


def test_tcp_reconnect_after_close(twin, gcs_factory):
    for _ in range(3):
        g = gcs_factory(twin.tcp)
        check_vehicle_heartbeat(g)
        g.close()
    check_vehicle_heartbeat(gcs_factory(twin.tcp))


def test_vehicle_sends_mavlink2_from_the_first_byte(twin):
    host, port = twin.host_port("tcpin")
    with socket.create_connection((host, port), timeout=10) as s:
        first = s.recv(1)
    assert first == b"\xfd", f"first byte from the twin is {first!r}, expected 0xFD (MAVLink 2)"


V1_SCRIPT = textwrap.dedent(
    """
    import json, sys, time
    from pymavlink import mavutil
    url = sys.argv[1]
    m = mavutil.mavlink_connection(url, source_system=255, source_component=190)
    out = {"v2_before": bool(m.mavlink20()), "wire_before": mavutil.mavlink.WIRE_PROTOCOL_VERSION}
    # Sent before anything was received: these go out as MAVLink 1 frames.
    m.mav.param_request_read_send(1, 0, b"HOVER_ALT", -1)
    m.mav.command_long_send(1, 0, 520, 0, 1, 0, 0, 0, 0, 0, 0)  # REQUEST_AUTOPILOT_CAPABILITIES
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and not ("param" in out and "ack" in out):
        msg = m.recv_match(type=["PARAM_VALUE", "COMMAND_ACK"], blocking=True, timeout=0.5)
        if msg is None or msg.get_srcSystem() != 1:
            continue
        if msg.get_type() == "PARAM_VALUE" and msg.param_id == "HOVER_ALT":
            out["param"] = msg.param_value
        if msg.get_type() == "COMMAND_ACK" and msg.command == 520:
            out["ack"] = msg.result
    out["v2_after"] = bool(m.mavlink20())
    print(json.dumps(out))
    """
)


def run_v1_client(url: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("MAVLINK20", "MAVLINK09")}
    r = subprocess.run(
        [sys.executable, "-c", V1_SCRIPT, url], env=env, capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_mavlink1_first_client_is_answered(twin, gcs_factory):
    expected = gcs_factory(twin.tcp).param_get("HOVER_ALT").param_value
    for url in (twin.tcp, twin.udp):
        out = run_v1_client(url)
        assert out["v2_before"] is False and out["wire_before"] == "1.0", out
        assert "param" in out, f"v1 PARAM_REQUEST_READ over {url} not answered: {out}"
        assert out["param"] == f32(expected)
        assert "ack" in out, f"v1 COMMAND_LONG over {url} not acknowledged: {out}"
        # The vehicle's v2 frames switched the script to MAVLink 2.
        assert out["v2_after"] is True, out


def test_heartbeat_is_1hz_of_wall_time_at_any_speed(twin, gcs_factory):
    """HEARTBEAT runs at 1 Hz of wall time whatever the sim speed: the module's twin flies at 4x,
    so 8 s of vehicle time (time_boot_ms) carry about two heartbeats, not eight."""
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    start = g.recv("ATTITUDE").time_boot_ms
    beats = 0
    while True:
        m = g.recv(["HEARTBEAT", "ATTITUDE"], timeout=10)
        if m.get_type() == "HEARTBEAT":
            beats += m.type != 6
        elif m.time_boot_ms - start >= 8000:
            break
    assert 1 <= beats <= 4, f"{beats} heartbeats in 8 s of vehicle time at 4x"


def test_sigterm_exits_cleanly(twin_factory, gcs_factory):
    t = twin_factory(speed=4)
    gcs_factory(t.tcp).wait_vehicle_heartbeat()
    t.proc.terminate()
    assert t.proc.wait(timeout=15) == 0, t.stderr()[-2000:]
