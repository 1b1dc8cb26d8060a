"""QLOITER holds where it is entered, as ArduPlane's does: a push in QHOVER (which holds no
position) sends the vehicle drifting; QLOITER entered then brakes it (an overshoot of a few
metres at the drift's speed) and brings it back to the entry point, where it holds within 1 m,
instead of flying back to an earlier target."""

from __future__ import annotations

import math

from conftest import take_off


def test_qloiter_entered_after_a_push_holds_the_entry_point(twin_factory, gcs_factory):
    g = gcs_factory(twin_factory(speed=4).tcp)
    take_off(g)
    g.param_set("SIM_PUSH_ROLL", 0.1)  # the terminal UI's push
    # Drifting east: wait until 1.5 m from the start.
    start = g.recv("LOCAL_POSITION_NED", timeout=5)
    g.recv("LOCAL_POSITION_NED",
           lambda p: math.hypot(p.x - start.x, p.y - start.y) > 1.5, timeout=30,
           what="the drift after the push")
    g.set_mode("QLOITER")
    entry = g.recv("LOCAL_POSITION_NED", timeout=5)
    # From 10 s to 20 s of vehicle time after the entry: within 1 m of it, horizontally.
    far = 0.0
    while True:
        p = g.recv("LOCAL_POSITION_NED", timeout=5)
        age_ms = p.time_boot_ms - entry.time_boot_ms
        if age_ms > 10_000:
            far = max(far, math.hypot(p.x - entry.x, p.y - entry.y))
        if age_ms > 20_000:
            break
    assert far < 1.0, f"held {far:.2f} m from the QLOITER entry point"
    # And it stays away from where it started (it did not fly back to the old target).
    assert math.hypot(p.x - start.x, p.y - start.y) > 1.0, (p, start)
