"""The fixture's default runs a script written as tutorials write them, unchanged: wait for the
armed heartbeat, then poll the altitude against a wall-clock deadline. (Under lockstep sim time
would never move and the deadline would pass on the ground.)"""

import time

from pymavlink import mavutil


def test_a_tutorial_script_runs_under_the_default(vtol_twin):
    m = mavutil.mavlink_connection(vtol_twin.url, source_system=255)
    m.wait_heartbeat(timeout=10)
    m.set_mode("QHOVER")
    m.arducopter_arm()

    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
        if hb is not None and hb.get_srcSystem() == m.target_system and hb.base_mode & 128:
            break
    else:
        raise AssertionError("never armed")

    m.mav.request_data_stream_send(m.target_system, m.target_component,
                                   mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    deadline = time.monotonic() + 15
    altitude = 0.0
    while time.monotonic() < deadline and altitude < 0.9:
        pos = m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=1)
        if pos is not None:
            altitude = -pos.z
    assert altitude >= 0.9, f"altitude {altitude:.2f} m after 15 s of wall-clock time"
