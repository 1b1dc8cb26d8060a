"""DroneKit (`dronekit2`, the maintained fork of DroneKit-Python) flies the twin as it flies
ArduPilot SITL, each step written the way DroneKit's documentation writes it: `connect(...,
wait_ready=True)`, `commands.download()` on a fresh twin (home comes from mission item 0),
parameters read and written, the guide's `arm_and_takeoff()` with its `is_armable` wait,
`simple_goto`, a mission built with `commands.add` and uploaded, AUTO to its end, RTL to landed
and disarmed. Directly against the twin and through the daemon, over TCP and UDP.

Where the documentation polls with `time.sleep(1)`, the tests use DroneKit's own
`vehicle.wait_for(condition, timeout=...)`: the same loop, bounded, checking ten times a second.
"""

from __future__ import annotations

import pytest
from dronekit import Command, LocationGlobalRelative, VehicleMode, connect
from pymavlink import mavutil

from conftest import f32, twin_factory  # noqa: F401 (fixture)
from daemon_support import daemon_factory  # noqa: F401 (fixture)
from sdk_targets import distance_m, offset, target  # noqa: F401 (fixture)

TAKEOFF_ALT = 2.0
# Upper bounds, wall seconds (the twin flies at sdk_targets.FLIGHT_SPEED x real time).
STEP_TIMEOUT = 30.0


def arm_and_takeoff(vehicle, a_target_altitude):
    """The DroneKit guide's arm_and_takeoff (examples/simple_goto), its polls bounded."""
    # Don't let the user try to arm until autopilot is ready
    vehicle.wait_for(lambda: vehicle.is_armable, timeout=STEP_TIMEOUT,
                     errmsg="never armable (EKF_STATUS_REPORT, GPS fix)")
    # Copter should arm in GUIDED mode
    vehicle.mode = VehicleMode("GUIDED")
    vehicle.armed = True
    vehicle.wait_for(lambda: vehicle.armed, timeout=STEP_TIMEOUT, errmsg="never armed")
    vehicle.simple_takeoff(a_target_altitude)  # Take off to target altitude
    vehicle.wait_for(
        lambda: (vehicle.location.global_relative_frame.alt or 0.0) >= a_target_altitude * 0.95,
        timeout=STEP_TIMEOUT, errmsg="never reached the take-off altitude")


def test_dronekit_flies_the_twin_as_documented(target):
    vehicle = connect(target.pymavlink_url, wait_ready=True, timeout=STEP_TIMEOUT,
                      heartbeat_timeout=STEP_TIMEOUT)
    try:
        fly_documented_flows(vehicle)
    finally:
        vehicle.close()


def fly_documented_flows(vehicle):
    # Identity: ArduPilot (ArduPlane's vehicle type), a release version from AUTOPILOT_VERSION,
    # and the capabilities it really has.
    vehicle.wait_for(lambda: vehicle.version.raw_version is not None, timeout=STEP_TIMEOUT,
                     errmsg="no AUTOPILOT_VERSION")
    version = vehicle.version
    assert version.autopilot_type == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert version.vehicle_type == mavutil.mavlink.MAV_TYPE_FIXED_WING
    assert version.is_stable()
    caps = vehicle.capabilities
    assert caps.mission_int and caps.mission_float and caps.command_int and not caps.ftp
    assert vehicle.mode.name == "QSTABILIZE"

    # A fresh twin: no mission, and home read from item 0 (ArduPilot always serves it).
    cmds = vehicle.commands
    cmds.download()
    cmds.wait_ready(timeout=STEP_TIMEOUT)
    assert cmds.count == 0
    home = vehicle.home_location
    assert home is not None and abs(home.lat) > 0 and abs(home.lon) > 0, home

    # Parameters: all of them came with wait_ready=True; one written and read back.
    assert len(vehicle.parameters) >= 50
    assert vehicle.parameters["WP_RADIUS"] == 90  # ArduPlane's INT16, in metres
    assert vehicle.parameters["Q_WP_RADIUS"] == pytest.approx(200.0, abs=1e-6)  # a float, cm
    vehicle.parameters["Q_WP_RADIUS"] = 50.0
    vehicle.wait_for(lambda: abs(vehicle.parameters["Q_WP_RADIUS"] - 50.0) < 1e-6,
                     timeout=STEP_TIMEOUT, errmsg="Q_WP_RADIUS not written")
    # Fly as a VTOL-only QuadPlane is set up on ArduPlane: GUIDED targets held in a hover
    # (Q_GUIDED_MODE 1) and RTL as QRTL (Q_RTL_MODE 3); the defaults fly both on the wing.
    vehicle.parameters["Q_GUIDED_MODE"] = 1
    vehicle.parameters["Q_RTL_MODE"] = 3
    vehicle.wait_for(lambda: vehicle.parameters["Q_GUIDED_MODE"] == 1
                     and vehicle.parameters["Q_RTL_MODE"] == 3,
                     timeout=STEP_TIMEOUT, errmsg="Q_GUIDED_MODE, Q_RTL_MODE not written")

    arm_and_takeoff(vehicle, TAKEOFF_ALT)
    assert vehicle.mode.name == "GUIDED"

    # simple_goto: MISSION_ITEM with current = 2, ArduPilot's guided waypoint. MISSION_ITEM
    # carries degrees as float32 (about 1 m of longitude here): the target is where those land.
    here = vehicle.location.global_relative_frame
    lat, lon = offset(here.lat, here.lon, 3.0, 0.0)
    vehicle.simple_goto(LocationGlobalRelative(lat, lon, TAKEOFF_ALT))

    def near(lat, lon, tol=0.5):
        loc = vehicle.location.global_relative_frame
        return distance_m(loc.lat, loc.lon, f32(lat), f32(lon)) <= tol

    vehicle.wait_for(lambda: near(lat, lon), timeout=STEP_TIMEOUT, errmsg="simple_goto not flown")

    # A mission built with commands.add and uploaded (the guide's mission_basic), then AUTO.
    cmds.clear()
    frame = mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
    wp1 = offset(home.lat, home.lon, 3.0, 2.0)
    wp2 = offset(home.lat, home.lon, 0.0, 2.0)
    cmds.add(Command(0, 0, 0, frame, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0,
                     0, 0, TAKEOFF_ALT))
    # ArduPlane flies the waypoints after a take-off on the wing; a transition to MC keeps
    # them in a hover.
    cmds.add(Command(0, 0, 0, mavutil.mavlink.MAV_FRAME_MISSION,
                     mavutil.mavlink.MAV_CMD_DO_VTOL_TRANSITION, 0, 0,
                     mavutil.mavlink.MAV_VTOL_STATE_MC, 0, 0, 0, 0, 0, 0))
    cmds.add(Command(0, 0, 0, frame, mavutil.mavlink.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, 0, 0,
                     wp1[0], wp1[1], TAKEOFF_ALT))
    cmds.add(Command(0, 0, 0, frame, mavutil.mavlink.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, 0, 0,
                     wp2[0], wp2[1], TAKEOFF_ALT))
    cmds.upload(timeout=STEP_TIMEOUT)
    cmds.download()
    cmds.wait_ready(timeout=STEP_TIMEOUT)
    assert cmds.count == 4
    assert [c.command for c in cmds] == [22, 3000, 16, 16]

    vehicle.commands.next = 0
    vehicle.mode = VehicleMode("AUTO")
    vehicle.wait_for(lambda: vehicle.mode.name == "AUTO", timeout=STEP_TIMEOUT,
                     errmsg="never in AUTO")
    # To the end: the last waypoint flown, then ArduPlane's end of mission (RTL, QRTL here). The
    # closest approach to it is tracked while waiting: QRTL heads home (2 m away) at once, and
    # DroneKit hears the mode change up to a heartbeat later.
    closest = [float("inf")]

    def mission_over():
        loc = vehicle.location.global_relative_frame
        d = distance_m(loc.lat, loc.lon, f32(wp2[0]), f32(wp2[1]))
        closest[0] = min(closest[0], d)
        return vehicle.mode.name != "AUTO"

    vehicle.wait_for(mission_over, timeout=STEP_TIMEOUT, errmsg="mission never ended")
    assert closest[0] <= 1.0, f"closest to the last waypoint: {closest[0]:.2f} m"  # Q_WP_RADIUS 50 cm

    # RTL (flown as QRTL, Q_RTL_MODE 3) to landed and disarmed.
    vehicle.mode = VehicleMode("RTL")
    vehicle.wait_for(lambda: vehicle.mode.name == "QRTL", timeout=STEP_TIMEOUT,
                     errmsg="never in QRTL")
    vehicle.wait_for(lambda: not vehicle.armed, timeout=STEP_TIMEOUT,
                     errmsg="never landed and disarmed")
    loc = vehicle.location.global_relative_frame
    assert distance_m(loc.lat, loc.lon, home.lat, home.lon) < 1.0
    assert loc.alt < 0.3
