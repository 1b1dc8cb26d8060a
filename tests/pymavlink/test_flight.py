"""A whole flight through pymavlink: arm, QHOVER take-off and altitude hold, motor PWM, QLAND."""

import statistics

import pytest

from conftest import (
    FLAG_ARMED,
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_SET_MODE,
    MAV_RESULT_ACCEPTED,
    MODES,
    MSG_LOCAL_POSITION_NED,
    MSG_SERVO_OUTPUT_RAW,
    wait_hover,
)

IDLE_US = 1000
HOVER_US = 1680


@pytest.fixture(scope="module")
def flight(module_twin_factory):
    """One flight shared by the steps below (they run in file order)."""
    from conftest import Gcs

    t = module_twin_factory(speed=4)
    g = Gcs(t.tcp)
    g.wait_vehicle_heartbeat()
    g.set_interval(MSG_LOCAL_POSITION_NED, 20)
    g.set_interval(MSG_SERVO_OUTPUT_RAW, 10)
    state = {"twin": t, "gcs": g}
    yield state
    g.close()


def test_idle_pwm_when_disarmed(flight):
    g = flight["gcs"]
    g.wait_ready()
    s = g.recv("SERVO_OUTPUT_RAW")
    assert (s.servo1_raw, s.servo2_raw) == (IDLE_US, IDLE_US), s
    for ch in (s.servo3_raw, s.servo4_raw, s.servo5_raw):
        assert 1000 <= ch <= 2000, s


def test_arm_ack_then_armed_heartbeat(flight):
    g = flight["gcs"]
    g.drain()
    g.m.arducopter_arm()  # pymavlink's own helper: COMMAND_LONG(400, p1=1), target_component 0
    ack = g.recv("COMMAND_ACK", lambda a: a.command == MAV_CMD_COMPONENT_ARM_DISARM)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    hb = g.wait_vehicle_heartbeat(timeout=5)  # the very next one
    assert hb.base_mode & FLAG_ARMED, hb
    assert g.m.motors_armed()
    flight["armed"] = True


def test_qhover_takes_off_and_holds_hover_alt(flight):
    assert flight.get("armed"), "needs the previous step"
    g = flight["gcs"]
    alt = g.param_get("HOVER_ALT").param_value
    g.drain()
    g.m.set_mode("QHOVER")  # pymavlink's helper: DO_SET_MODE(1, 18) by name
    ack = g.recv("COMMAND_ACK", lambda a: a.command == MAV_CMD_DO_SET_MODE)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    hb = g.wait_vehicle_heartbeat(timeout=5, pred=lambda h: h.custom_mode == MODES["QHOVER"])
    assert g.m.flightmode == "QHOVER"
    assert hb.base_mode & FLAG_ARMED
    window = wait_hover(g, alt, tol=0.05, settle_s=2.0, window_s=5.0)
    zs = [-p.z for p in window]
    assert max(abs(z - alt) for z in zs) <= 0.05, (min(zs), max(zs))
    assert abs(statistics.fmean(zs) - alt) <= 0.03
    assert all(abs(p.vz) < 0.1 for p in window), max(abs(p.vz) for p in window)
    flight["hovering"] = True


def test_motor_pwm_rises_when_flying(flight):
    assert flight.get("hovering"), "needs the previous step"
    g = flight["gcs"]
    samples = g.collect("SERVO_OUTPUT_RAW", until=lambda s: len(s) >= 10, timeout=20)
    for s in samples:
        assert IDLE_US + 200 < s.servo1_raw <= 2000, s
        assert IDLE_US + 200 < s.servo2_raw <= 2000, s
    mean = statistics.fmean([(s.servo1_raw + s.servo2_raw) / 2 for s in samples])
    assert abs(mean - HOVER_US) < 150, f"hover PWM {mean:.0f} µs, expected about {HOVER_US}"


def test_disarm_in_flight_refused_without_force(flight):
    assert flight.get("hovering"), "needs the previous step"
    g = flight["gcs"]
    ack = g.command(MAV_CMD_COMPONENT_ARM_DISARM, 0)
    assert ack.result != MAV_RESULT_ACCEPTED, ack
    assert g.wait_vehicle_heartbeat(timeout=5).base_mode & FLAG_ARMED


def test_qland_lands_and_disarms(flight):
    assert flight.get("hovering"), "needs the previous step"
    g = flight["gcs"]
    g.set_mode("QLAND")
    g.wait_vehicle_heartbeat(timeout=5, pred=lambda h: h.custom_mode == MODES["QLAND"])
    hb = g.wait_vehicle_heartbeat(timeout=90, pred=lambda h: not h.base_mode & FLAG_ARMED)
    assert not g.m.motors_armed()
    p = g.recv("LOCAL_POSITION_NED")
    assert -p.z < 0.1, f"disarmed at {-p.z:.2f} m above ground"
    s = g.recv("SERVO_OUTPUT_RAW")
    assert (s.servo1_raw, s.servo2_raw) == (IDLE_US, IDLE_US), s
    assert hb.system_status == 3, f"expected STANDBY after landing: {hb}"
