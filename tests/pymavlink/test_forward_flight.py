"""Forward flight as a ground station sees it: a mission that takes off vertically, transitions,
flies a 400 m × 150 m rectangle on the wing in AUTO, transitions back and lands vertically, flown with
pymavlink against the twin in lockstep (`docs/forward-flight.md`).

The twin flies on its noisy sensors and its estimators (the hover's, and the forward-flight
attitude filter from the forward transition to the end of the back transition).
"""

import math

import pytest
from pymavlink import mavutil

pytestmark = pytest.mark.vtol_twin(
    speed="lockstep",
    params={"SR0_EXT_STAT": 10, "SR0_EXTRA2": 10, "SR0_POSITION": 10},
)

MAV = mavutil.mavlink
EARTH_RADIUS_M = 6_378_100.0  # the twin's globe (nav::globe)
VTOL_STATE_NAMES = {
    MAV.MAV_VTOL_STATE_MC: "MC",
    MAV.MAV_VTOL_STATE_TRANSITION_TO_FW: "TRANSITION_TO_FW",
    MAV.MAV_VTOL_STATE_FW: "FW",
    MAV.MAV_VTOL_STATE_TRANSITION_TO_MC: "TRANSITION_TO_MC",
}
RECT_LONG_M = 400.0  # the rectangle's long side, south from home
RECT_SHORT_M = 150.0  # its short side, east
LAND_NE_M = (-60.0, 50.0)


def ack_of(m, command):
    ack = m.recv_match(type="COMMAND_ACK", condition=f"COMMAND_ACK.command=={command}",
                       blocking=True, timeout=5)
    assert ack is not None, f"no COMMAND_ACK for command {command}"
    return ack


def rectangle_mission(lat0: float, lon0: float) -> list:
    """(command, frame, params, lat_e7, lon_e7, alt) of every item; item 0 is home."""

    def at(north_m: float, east_m: float) -> tuple:
        lat = lat0 + math.degrees(north_m / EARTH_RADIUS_M)
        lon = lon0 + math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(lat0))))
        return round(lat * 1e7), round(lon * 1e7)

    rel = MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    wp = MAV.MAV_CMD_NAV_WAYPOINT
    return [
        (wp, rel, (0, 0, 0, 0), *at(0, 0), 0.0),
        (MAV.MAV_CMD_NAV_VTOL_TAKEOFF, rel, (0, 0, 0, 0), 0, 0, 20.0),
        (MAV.MAV_CMD_DO_VTOL_TRANSITION, MAV.MAV_FRAME_MISSION, (MAV.MAV_VTOL_STATE_FW, 0, 0, 0), 0, 0, 0.0),
        (wp, rel, (0, 0, 0, 0), *at(-RECT_LONG_M, 0), 20.0),
        (wp, rel, (0, 0, 0, 0), *at(-RECT_LONG_M, RECT_SHORT_M), 20.0),
        # Its own acceptance radius: 5 m (WP_RADIUS elsewhere).
        (wp, rel, (0, 5, 0, 0), *at(0, RECT_SHORT_M), 20.0),
        (wp, rel, (0, 0, 0, 0), *at(0, 0), 20.0),
        (MAV.MAV_CMD_NAV_VTOL_LAND, rel, (0, 0, 0, 0), *at(*LAND_NE_M), 0.0),
    ]


def upload(m, items) -> None:
    m.mav.mission_count_send(1, 1, len(items), MAV.MAV_MISSION_TYPE_MISSION)
    while True:
        msg = m.recv_match(type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"],
                           blocking=True, timeout=5)
        assert msg is not None, "the upload stalled"
        if msg.get_type() == "MISSION_ACK":
            assert msg.type == MAV.MAV_MISSION_ACCEPTED, msg
            return
        command, frame, p, lat, lon, alt = items[msg.seq]
        m.mav.mission_item_int_send(1, 1, msg.seq, frame, command, 0, 1, *p, lat, lon, alt,
                                    MAV.MAV_MISSION_TYPE_MISSION)


def test_vtol_take_off_rectangle_on_the_wing_and_vtol_landing(vtol_twin):
    fly_rectangle(vtol_twin)


def test_without_the_transition_item_the_waypoints_are_flown_on_the_wing(vtol_twin):
    """ArduPlane flies the waypoints after a VTOL take-off on the wing with or without a
    DO_VTOL_TRANSITION item: the same phases, the same rectangle."""
    fly_rectangle(vtol_twin, transition_item=False)


def test_a_vtol_landing_too_short_stops_arming_and_item_0_is_home(vtol_twin):
    """ArduPlane's pre-arm mission check (a VTOL landing under 0.75 v² / (2 Q_TRANS_DECEL), 9 m at
    12 m/s and 6 m/s², after its waypoint) and its home slot: item 0 downloads as home, whatever was
    uploaded there."""
    m = vtol_twin.connect()
    start = m.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=5)
    assert start is not None
    items = rectangle_mission(start.lat / 1e7, start.lon / 1e7)
    # The last waypoint, then the landing 5 m from it.
    last = items[6]
    land = (MAV.MAV_CMD_NAV_VTOL_LAND, last[1], (0, 0, 0, 0), last[3] + round(math.degrees(
        5.0 / EARTH_RADIUS_M) * 1e7), last[4], 0.0)
    upload(m, items[:7] + [land])
    vtol_twin.advance(2)
    m.set_mode("AUTO")
    assert ack_of(m, MAV.MAV_CMD_DO_SET_MODE).result == MAV.MAV_RESULT_ACCEPTED
    m.arducopter_arm()
    texts = []  # the refusal's reason ("Arm:", as ArduPilot's arming command says) before its ACK
    while (msg := m.recv_match(type=["STATUSTEXT", "COMMAND_ACK"], blocking=True, timeout=5)) is not None:
        if msg.get_type() == "STATUSTEXT":
            texts.append(msg.text)
        elif msg.command == MAV.MAV_CMD_COMPONENT_ARM_DISARM:
            assert msg.result == MAV.MAV_RESULT_FAILED, msg
            break
    assert msg is not None, "no COMMAND_ACK for the arming"
    assert "Arm: VTOL land too short, min 9m" in texts, texts
    m.mav.mission_request_int_send(1, 1, 0, MAV.MAV_MISSION_TYPE_MISSION)
    home = m.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=5)
    assert home is not None and home.seq == 0
    assert home.frame == MAV.MAV_FRAME_GLOBAL and home.z == pytest.approx(584.0, abs=0.01), home


def test_the_same_mission_in_a_3_m_s_wind_with_gusts(vtol_twin):
    """3 m/s from 45° with 0.5 m/s gusts: after the back transition the hover turns its span
    into the wind estimated on the wing, where the wind needs 9° of lean, not 34° on the face."""
    vtol_twin.wind(3.0, direction_deg=45, turbulence_m_s=0.5)
    fly_rectangle(vtol_twin)


def fly_rectangle(vtol_twin, transition_item: bool = True) -> None:
    """Flies the rectangle mission (without its DO_VTOL_TRANSITION item if not
    `transition_item`) and checks what a ground station sees of it."""
    m = vtol_twin.connect()
    start = m.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=5)
    assert start is not None
    items = rectangle_mission(start.lat / 1e7, start.lon / 1e7)
    if not transition_item:
        del items[2]
    upload(m, items)

    m.set_mode("AUTO")
    assert ack_of(m, MAV.MAV_CMD_DO_SET_MODE).result == MAV.MAV_RESULT_ACCEPTED
    m.arducopter_arm()
    assert ack_of(m, MAV.MAV_CMD_COMPONENT_ARM_DISARM).result == MAV.MAV_RESULT_ACCEPTED

    states = ["MC"]
    alt_at_start = None  # relative altitude when the current transition began, m
    worst = {"TRANSITION_TO_FW": 0.0, "TRANSITION_TO_MC": 0.0}
    alt = 0.0
    fw_airspeeds = []
    fw_aoa = []
    fw_reach = [0.0, 0.0]  # farthest south and east on the wing, m from home
    armed = True
    for _ in range(300):  # two-second steps: at most 600 s of sim time
        vtol_twin.advance(2)
        while (msg := m.recv_match(blocking=False)) is not None:
            kind = msg.get_type()
            if kind == "GLOBAL_POSITION_INT":
                alt = msg.relative_alt / 1000.0
                if states[-1] == "FW":
                    south = math.radians(start.lat / 1e7 - msg.lat / 1e7) * EARTH_RADIUS_M
                    east = (math.radians(msg.lon / 1e7 - start.lon / 1e7) * EARTH_RADIUS_M
                            * math.cos(math.radians(start.lat / 1e7)))
                    fw_reach = [max(fw_reach[0], south), max(fw_reach[1], east)]
                if states[-1] in worst and alt_at_start is not None:
                    worst[states[-1]] = max(worst[states[-1]], abs(alt - alt_at_start))
            elif kind == "EXTENDED_SYS_STATE":
                name = VTOL_STATE_NAMES[msg.vtol_state]
                if name != states[-1]:
                    states.append(name)
                    alt_at_start = alt
            elif kind == "VFR_HUD" and states[-1] == "FW":
                fw_airspeeds.append(msg.airspeed)
            elif kind == "AOA_SSA" and states[-1] == "FW":
                fw_aoa.append(msg.AOA)
            elif kind == "HEARTBEAT" and msg.get_srcSystem() == 1:
                armed = bool(msg.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED)
        if not armed:
            break

    truth = vtol_twin.state()
    assert not truth.armed and truth.landed, f"still flying: {truth}"
    assert truth.system_status != "EMERGENCY", truth
    assert states == ["MC", "TRANSITION_TO_FW", "FW", "TRANSITION_TO_MC", "MC"], states
    # The whole rectangle is flown on the wing (each turn starts up to the L1 distance, 28.6 m,
    # short of its corner, and swings out past the line).
    for reach, side in zip(fw_reach, (RECT_LONG_M, RECT_SHORT_M)):
        assert side - 30.0 < reach < side + 30.0, f"the rectangle reached {fw_reach} m (south, east)"
    print(f"on the wing: reached {fw_reach[0]:.1f} m south, {fw_reach[1]:.1f} m east; airspeed >= "
          f"{min(fw_airspeeds, default=0):.1f} m/s; transitions moved the altitude "
          f"{worst['TRANSITION_TO_FW']:.2f} m and {worst['TRANSITION_TO_MC']:.2f} m")
    assert fw_airspeeds and min(fw_airspeeds) >= 10.0, f"airspeed on the wing down to {min(fw_airspeeds):.1f}"
    # AOA_SSA: the wing flies at a small positive angle of attack.
    assert fw_aoa, "no AOA_SSA on the wing"
    median_aoa = sorted(fw_aoa)[len(fw_aoa) // 2]
    assert 0.0 < median_aoa < 15.0, f"angle of attack on the wing {median_aoa:.1f}°"
    for phase, dz in worst.items():
        assert dz <= 3.0, f"{phase} moved the altitude {dz:.2f} m"
    north, east, _ = truth.position_ned_m
    miss = math.hypot(north - LAND_NE_M[0], east - LAND_NE_M[1])
    print(f"landed {miss:.2f} m from the target")
    assert miss <= 2.0, f"landed {miss:.2f} m from the target"
