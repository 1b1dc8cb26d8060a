"""FBWA flown on the sticks by a ground station's joystick (RC_CHANNELS_OVERRIDE), with
pymavlink against the twin in lockstep (`docs/forward-flight.md`): a GUIDED take-off, FBWA
transitions to the wing, the roll stick turns the aircraft, QLOITER brings it back to a hover.
Attitude and heading are ArduPlane's for a tailsitter: ATTITUDE in its VTOL view while hovering
(upright reads pitch 0°), in the fixed-wing body frame on the wing (the angle of attack and the
course, the bank as the roll).
"""

import math
import time

import pytest
from pymavlink import mavutil

pytestmark = pytest.mark.vtol_twin(speed="lockstep", params={"SR0_EXT_STAT": 10, "SR0_POSITION": 10})

MAV = mavutil.mavlink
THROTTLE_US = 1100  # 10 % of the rotors' thrust: near level flight at 12 m/s


def ack_of(m, command):
    ack = m.recv_match(type="COMMAND_ACK", condition=f"COMMAND_ACK.command=={command}",
                       blocking=True, timeout=5)
    assert ack is not None, f"no COMMAND_ACK for command {command}"
    return ack.result


def record(msg, seen: dict) -> None:
    if msg.get_type() == "EXTENDED_SYS_STATE":
        seen["states"].append(msg.vtol_state)
    elif msg.get_type() == "GLOBAL_POSITION_INT":
        seen["course"].append(math.atan2(msg.vy, msg.vx))
        seen["alt"].append(msg.relative_alt / 1000.0)
    elif msg.get_type() == "ATTITUDE":
        seen["roll"].append(math.degrees(msg.roll))
        seen["pitch"].append(math.degrees(msg.pitch))
    elif msg.get_type() == "VFR_HUD" and seen["course"]:
        # The heading against the latest course, degrees in [−180, 180).
        seen["heading_off"].append((msg.heading - math.degrees(seen["course"][-1]) + 180) % 360 - 180)


def sync(m, seen: dict) -> None:
    """Asks the twin for a parameter and reads up to its answer, recording what comes before it:
    the twin has then taken everything sent before (the sticks have no answer of their own),
    and every frame it sent before has arrived."""
    m.mav.param_request_read_send(1, 1, b"SYSID_THISMAV", -1)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        msg = m.recv_match(blocking=True, timeout=0.5)
        if msg is None:
            continue
        if msg.get_type() == "PARAM_VALUE" and msg.param_id == "SYSID_THISMAV":
            return
        record(msg, seen)
    raise AssertionError("no PARAM_VALUE for SYSID_THISMAV in 10 s")


def fly(vtol_twin, m, seconds: int, roll_us: int) -> dict:
    """Flies `seconds` on the sticks (sent every second, each taken before the twin flies on);
    what the ground station saw in those seconds."""
    seen = {key: [] for key in ("states", "course", "alt", "roll", "pitch", "heading_off")}
    for _ in range(seconds):
        m.mav.rc_channels_override_send(1, 1, roll_us, 1500, THROTTLE_US, 1500, 0, 0, 0, 0)
        sync(m, {key: [] for key in seen})
        vtol_twin.advance(1)
        sync(m, seen)
    return seen


def turned(courses: list) -> float:
    """The course change along `courses`, unwrapped, rad (positive: to the right)."""
    return sum(math.remainder(b - a, math.tau) for a, b in zip(courses, courses[1:]))


def test_fbwa_on_the_sticks_turns_with_the_roll_stick(vtol_twin):
    m = vtol_twin.connect()
    vtol_twin.advance(2)  # the gyros calibrate for 1 s after power-up
    m.set_mode("GUIDED")
    assert ack_of(m, MAV.MAV_CMD_DO_SET_MODE) == MAV.MAV_RESULT_ACCEPTED
    m.arducopter_arm()
    assert ack_of(m, MAV.MAV_CMD_COMPONENT_ARM_DISARM) == MAV.MAV_RESULT_ACCEPTED
    m.mav.command_long_send(1, 1, MAV.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 20)
    assert ack_of(m, MAV.MAV_CMD_NAV_TAKEOFF) == MAV.MAV_RESULT_ACCEPTED
    for _ in range(60):
        vtol_twin.advance(1)
        if vtol_twin.state().altitude_m > 19.8:
            break
    assert vtol_twin.state().altitude_m > 19.8, vtol_twin.state()
    hover = fly(vtol_twin, m, 1, 1500)
    assert max(map(abs, hover["pitch"])) < 10, f"upright in the VTOL view the pitch is near 0°: {hover['pitch']}"

    m.mav.rc_channels_override_send(1, 1, 1500, 1500, THROTTLE_US, 1500, 0, 0, 0, 0)
    m.set_mode("FBWA")
    assert ack_of(m, MAV.MAV_CMD_DO_SET_MODE) == MAV.MAV_RESULT_ACCEPTED
    transition = fly(vtol_twin, m, 15, 1500)
    assert MAV.MAV_VTOL_STATE_TRANSITION_TO_FW in transition["states"], transition["states"]
    assert transition["states"][-1] == MAV.MAV_VTOL_STATE_FW, transition["states"]

    straight = fly(vtol_twin, m, 5, 1500)
    right = fly(vtol_twin, m, 8, 1750)
    fly(vtol_twin, m, 3, 1500)
    left = fly(vtol_twin, m, 8, 1250)
    assert abs(turned(straight["course"])) < 0.1, turned(straight["course"])
    # Level on the wing: the pitch is the angle of attack, the heading the course, the wings level.
    print(f"on the wing: pitch {min(straight['pitch']):.1f}° to {max(straight['pitch']):.1f}°, "
          f"heading off the course by at most {max(map(abs, straight['heading_off'])):.1f}°, "
          f"roll within {max(map(abs, straight['roll'])):.1f}°; banked right up to "
          f"{max(right['roll']):.1f}°, left {min(left['roll']):.1f}°")
    assert 0 < min(straight["pitch"]) and max(straight["pitch"]) < 20, straight["pitch"]
    assert max(map(abs, straight["heading_off"])) < 10, straight["heading_off"]
    assert max(map(abs, straight["roll"])) < 5, straight["roll"]
    # The roll stick banks right (positive roll), within LIM_ROLL_CD (45°), and left.
    assert 10 < max(right["roll"]) <= 46, right["roll"]
    assert -46 <= min(left["roll"]) < -10, left["roll"]
    assert turned(right["course"]) > 1.5, turned(right["course"])
    assert turned(left["course"]) < -1.5, turned(left["course"])
    alts = straight["alt"] + right["alt"] + left["alt"]
    assert 15.0 < min(alts) and max(alts) < 30.0, (min(alts), max(alts))

    m.set_mode("QLOITER")
    assert ack_of(m, MAV.MAV_CMD_DO_SET_MODE) == MAV.MAV_RESULT_ACCEPTED
    back = fly(vtol_twin, m, 15, 1500)
    assert MAV.MAV_VTOL_STATE_TRANSITION_TO_MC in back["states"], back["states"]
    assert back["states"][-1] == MAV.MAV_VTOL_STATE_MC, back["states"]
    truth = vtol_twin.state()
    assert truth.armed and truth.system_status != "EMERGENCY", truth
