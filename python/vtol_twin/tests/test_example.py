"""The README's example: a pymavlink script flown against the twin, the way a user tests one.
It arms, takes off in QHOVER, checks the altitude, is pushed and recovers, and lands, in
lockstep (`advance` moves sim time)."""

import math

import pytest
from pymavlink import mavutil

pytestmark = pytest.mark.vtol_twin(speed="lockstep")

ACCEPTED = mavutil.mavlink.MAV_RESULT_ACCEPTED


def ack_of(m, command):
    ack = m.recv_match(type="COMMAND_ACK", condition=f"COMMAND_ACK.command=={command}",
                       blocking=True, timeout=5)
    assert ack is not None, f"no COMMAND_ACK for command {command}"
    return ack


def attitude_until(m, end_ms):
    """(time_boot_ms, tilt) of every ATTITUDE up to sim time end_ms. Hovering, ATTITUDE is
    ArduPlane's VTOL view of a tailsitter (upright reads roll 0°, pitch 0°): the nose's tilt from
    vertical is acos(cos roll · cos pitch)."""
    out = []
    while not out or out[-1][0] < end_ms:
        a = m.recv_match(type="ATTITUDE", blocking=True, timeout=5)
        assert a is not None, f"ATTITUDE stopped at {out[-1:]}"
        out.append((a.time_boot_ms, math.acos(max(-1.0, min(1.0, math.cos(a.roll) * math.cos(a.pitch))))))
    return out


def test_take_off_push_recover_land(vtol_twin):
    m = mavutil.mavlink_connection(vtol_twin.url, source_system=255)
    m.wait_heartbeat(timeout=5)

    m.set_mode("QHOVER")
    assert ack_of(m, mavutil.mavlink.MAV_CMD_DO_SET_MODE).result == ACCEPTED
    m.arducopter_arm()
    assert ack_of(m, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM).result == ACCEPTED

    # Ten seconds of flight in a few milliseconds; their telemetry is waiting on the link.
    assert vtol_twin.advance(10) == 10.0
    pos = m.recv_match(type="LOCAL_POSITION_NED", condition="LOCAL_POSITION_NED.time_boot_ms >= 9900",
                       blocking=True, timeout=5)
    assert abs(-pos.z - 1.0) < 0.05, f"altitude {-pos.z:.3f} m, HOVER_ALT is 1 m"
    assert abs(vtol_twin.state().altitude_m - 1.0) < 0.05

    # A 0.1 N·m roll push for 200 ms: the vehicle tilts, then levels again.
    attitude_until(m, 9_950)
    vtol_twin.push(roll=0.1)
    vtol_twin.advance(4)
    tilts = attitude_until(m, 13_950)
    peak = max(tilt for _, tilt in tilts)
    assert peak > math.radians(5), f"the push tilted the vehicle only {math.degrees(peak):.1f}°"
    settled = [tilt for t, tilt in tilts if t >= 13_000]
    assert settled and max(settled) < math.radians(2), f"still {math.degrees(max(settled)):.1f}° off level"

    m.set_mode("QLAND")
    assert ack_of(m, mavutil.mavlink.MAV_CMD_DO_SET_MODE).result == ACCEPTED
    vtol_twin.advance(5)
    hb = m.recv_match(type="HEARTBEAT", condition="(HEARTBEAT.base_mode & 128) == 0", blocking=True, timeout=5)
    assert hb is not None, "QLAND never disarmed"
    s = vtol_twin.state()
    assert s.landed and not s.armed and s.altitude_m < 0.01
