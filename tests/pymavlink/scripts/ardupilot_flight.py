#!/usr/bin/env python3
"""A user's flight script, written the way ArduPilot's pymavlink examples are and run unchanged
against ArduPlane SITL, the twin, or the twin through the vtol-gcs daemon:

    python ardupilot_flight.py tcp:127.0.0.1:5760

wait for a 3D fix, set Q_GUIDED_MODE 1 (GUIDED targets held in a hover), arm in GUIDED, take
off to 2 m, reposition 5 m north, upload a 5-item mission (a DO_VTOL_TRANSITION to MC after the
take-off, so ArduPlane flies its waypoints in a hover, not on the wing), fly it in AUTO (a
MISSION_ITEM_REACHED for each item), QRTL, wait for the disarm.
Exits 0 when the flight is done, 1 with the reason otherwise. Every wait has a deadline.

Nothing in here knows about the twin: standard messages, ArduPlane mode names, the mission
protocol as ArduPilot's own examples drive it.
"""

import math
import sys
import time

from pymavlink import mavutil

TAKEOFF_ALT = 2.0
REPOSITION_NORTH = 5.0
TIMEOUT = 60.0  # seconds per step, far above what the twin needs


class Failed(Exception):
    pass


def wait(master, mtype, cond=lambda m: True, timeout=TIMEOUT, what=""):
    deadline = time.time() + timeout
    while time.time() < deadline:
        m = master.recv_match(type=mtype, blocking=True, timeout=0.5)
        if m is not None and m.get_srcSystem() == master.target_system and cond(m):
            return m
    raise Failed(f"timed out waiting for {what or mtype}")


def command_ack(master, command):
    ack = wait(master, "COMMAND_ACK", lambda a: a.command == command, 10, f"ACK of {command}")
    if ack.result != mavutil.mavlink.MAV_RESULT_ACCEPTED:
        raise Failed(f"command {command} refused: result {ack.result}")


def set_mode(master, name):
    """Change mode; the ACK is the answer (waiting for the next heartbeat as well would let
    the messages that come meanwhile, a MISSION_ITEM_REACHED among them, go unread)."""
    master.set_mode(master.mode_mapping()[name])
    command_ack(master, mavutil.mavlink.MAV_CMD_DO_SET_MODE)


def offset(lat, lon, north, east):
    """ArduPilot's flat-earth offset, 1e-7 degree."""
    dlat = north / 6378100.0
    dlon = east / (6378100.0 * math.cos(math.radians(lat / 1e7)))
    return int(round(lat + math.degrees(dlat) * 1e7)), int(round(lon + math.degrees(dlon) * 1e7))


def distance(lat1, lon1, lat2, lon2):
    dn = (lat2 - lat1) * 1e-7 * math.radians(1) * 6378100.0
    de = (lon2 - lon1) * 1e-7 * math.radians(1) * 6378100.0 * math.cos(math.radians(lat1 / 1e7))
    return math.hypot(dn, de)


def upload_mission(master, items):
    """The mission upload of ArduPilot's examples: count, then answer each request."""
    master.mav.mission_count_send(master.target_system, master.target_component, len(items))
    sent = set()
    while len(sent) < len(items):
        req = wait(master, ["MISSION_REQUEST", "MISSION_REQUEST_INT"], timeout=10, what="mission request")
        master.mav.send(items[req.seq])
        sent.add(req.seq)
    ack = wait(master, "MISSION_ACK", timeout=10)
    if ack.type != mavutil.mavlink.MAV_MISSION_ACCEPTED:
        raise Failed(f"mission refused: {ack.type}")


def item(master, seq, command, lat, lon, alt, p1=0.0):
    return mavutil.mavlink.MAVLink_mission_item_int_message(
        master.target_system, master.target_component, seq,
        mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, command, 0, 1,
        p1, 0, 0, 0, lat, lon, alt)


def fly(url):
    master = mavutil.mavlink_connection(url)
    master.wait_heartbeat(timeout=30)
    print(f"heartbeat from system {master.target_system}")

    gps = wait(master, "GPS_RAW_INT", lambda g: g.fix_type >= 3, what="3D fix")
    print(f"3D fix, {gps.satellites_visible} satellites")

    # ArduPlane flies GUIDED targets on the wing unless Q_GUIDED_MODE is 1.
    master.mav.param_set_send(master.target_system, master.target_component, b"Q_GUIDED_MODE", 1,
                              mavutil.mavlink.MAV_PARAM_TYPE_INT8)
    wait(master, "PARAM_VALUE", lambda p: p.param_id == "Q_GUIDED_MODE" and p.param_value == 1,
         timeout=10, what="Q_GUIDED_MODE 1")

    set_mode(master, "GUIDED")
    master.arducopter_arm()
    command_ack(master, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
    master.motors_armed_wait()
    print("armed")

    master.mav.command_long_send(master.target_system, master.target_component,
                                 mavutil.mavlink.MAV_CMD_GET_HOME_POSITION, 0, 0, 0, 0, 0, 0, 0, 0)
    home = wait(master, "HOME_POSITION")

    master.mav.command_long_send(master.target_system, master.target_component,
                                 mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, TAKEOFF_ALT)
    command_ack(master, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF)
    wait(master, "GLOBAL_POSITION_INT", lambda p: p.relative_alt >= 0.95 * TAKEOFF_ALT * 1000,
         what=f"{TAKEOFF_ALT} m")
    print("took off")

    lat, lon = offset(home.latitude, home.longitude, REPOSITION_NORTH, 0.0)
    master.mav.command_int_send(master.target_system, master.target_component,
                                mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                mavutil.mavlink.MAV_CMD_DO_REPOSITION, 0, 0,
                                -1, mavutil.mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, 0,
                                lat, lon, TAKEOFF_ALT)
    command_ack(master, mavutil.mavlink.MAV_CMD_DO_REPOSITION)
    wait(master, "GLOBAL_POSITION_INT", lambda p: distance(p.lat, p.lon, lat, lon) < 0.5,
         what="the reposition point")
    print("repositioned")

    # Home slot, then five items; the DO_VTOL_TRANSITION to MC keeps the waypoints in a hover.
    a = offset(home.latitude, home.longitude, 5.0, 3.0)
    b = offset(home.latitude, home.longitude, 2.0, 4.0)
    c = offset(home.latitude, home.longitude, 0.0, 3.0)
    mav = mavutil.mavlink
    to_mc = mavutil.mavlink.MAVLink_mission_item_int_message(
        master.target_system, master.target_component, 2, mav.MAV_FRAME_MISSION,
        mav.MAV_CMD_DO_VTOL_TRANSITION, 0, 1, mav.MAV_VTOL_STATE_MC, 0, 0, 0, 0, 0, 0)
    items = [
        item(master, 0, mav.MAV_CMD_NAV_WAYPOINT, home.latitude, home.longitude, 0),
        item(master, 1, mav.MAV_CMD_NAV_VTOL_TAKEOFF, 0, 0, 3.0),
        to_mc,
        item(master, 3, mav.MAV_CMD_NAV_WAYPOINT, a[0], a[1], 3.0),
        item(master, 4, mav.MAV_CMD_NAV_LOITER_TIME, b[0], b[1], 2.5, p1=2.0),
        item(master, 5, mav.MAV_CMD_NAV_WAYPOINT, c[0], c[1], 2.0),
    ]
    upload_mission(master, items)
    print("mission uploaded")

    set_mode(master, "AUTO")
    reached = []
    while len(reached) < 5:
        m = wait(master, "MISSION_ITEM_REACHED", what=f"item {len(reached) + 1} reached")
        if m.seq not in reached:
            reached.append(m.seq)
            print(f"reached item {m.seq}")
    if reached != [1, 2, 3, 4, 5]:
        raise Failed(f"items reached out of order: {reached}")

    set_mode(master, "QRTL")
    wait(master, "HEARTBEAT", lambda h: not h.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED, what="disarm")
    pos = wait(master, "GLOBAL_POSITION_INT")
    d = distance(pos.lat, pos.lon, home.latitude, home.longitude)
    if d > 1.0 or pos.relative_alt > 200:
        raise Failed(f"landed {d:.2f} m from home at {pos.relative_alt / 1000:.2f} m")
    print(f"landed {d:.2f} m from home and disarmed")


if __name__ == "__main__":
    try:
        fly(sys.argv[1])
    except Failed as e:
        print(f"FAILED: {e}")
        sys.exit(1)
