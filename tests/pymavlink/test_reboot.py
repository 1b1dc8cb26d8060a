"""The controller on the wire (NAMED_VALUE_FLOAT) and the reboot command clearing a crash, the
battery drawn as it was."""

import time

from conftest import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_RESULT_ACCEPTED,
    MAV_STATE_STANDBY,
)

MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN = 246
MAV_RESULT_DENIED = 2
MAV_STATE_EMERGENCY = 6
FORCE_MAGIC = 21196


def test_controller_outputs_and_reboot_after_a_crash(twin_factory, gcs_factory):
    g = gcs_factory(twin_factory(speed=4).tcp)
    g.wait_ready()
    g.arm()
    g.set_mode("QHOVER")
    # τ̃φ, τ̃θ, τ̃ψ and f_z arrive while it flies; the thrust carries the weight (0.5 kg).
    values = {}
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and (len(values) < 4 or values.get("FZ", 0) < 3.0):
        m = g.recv("NAMED_VALUE_FLOAT", timeout=5)
        values[m.name] = m.value
    assert set(values) == {"TAU_PHI", "TAU_THETA", "TAU_PSI", "FZ"}, values
    assert values["FZ"] > 3.0, values

    # Armed, the reboot is refused.
    assert g.command(MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1).result == MAV_RESULT_DENIED
    # Wait to be in the air, then cut the motors: the drop is a crash, and it latches.
    g.recv("LOCAL_POSITION_NED", lambda p: p.z < -0.8, timeout=30)
    ack = g.command(MAV_CMD_COMPONENT_ARM_DISARM, 0, FORCE_MAGIC)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    g.wait_vehicle_heartbeat(timeout=20, pred=lambda h: h.system_status == MAV_STATE_EMERGENCY)

    drawn = g.recv("BATTERY_STATUS", timeout=10)
    assert drawn.current_consumed > 0, drawn

    ack = g.command(MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    # Back on the ground, calibrated, ready to arm again: the crash is cleared.
    g.wait_ready(timeout=30)
    # A reboot does not refill the pack: the charge drawn in the flight stays drawn.
    after = g.recv("BATTERY_STATUS", timeout=10)
    assert after.current_consumed >= drawn.current_consumed, (drawn, after)
    assert after.battery_remaining <= drawn.battery_remaining, (drawn, after)
    g.arm()
