"""Sixteen twins at once (tests/run.sh runs this suite with pytest-xdist, -n 16): each takes
off in QHOVER and holds HOVER_ALT."""

import pytest
from pymavlink import mavutil

pytestmark = pytest.mark.vtol_twin(speed="lockstep")


@pytest.mark.parametrize("seed", range(1, 17))
def test_one_of_sixteen_twins_hovers(vtol_fleet, seed):
    [twin] = vtol_fleet(1, seed=seed)
    m = twin.connect()
    m.set_mode("QHOVER")
    m.arducopter_arm()
    ack = m.recv_match(type="COMMAND_ACK", condition="COMMAND_ACK.command==400", blocking=True, timeout=5)
    assert ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED
    twin.advance(8)
    s = twin.state()
    assert s.armed and s.mode == "QHOVER"
    assert abs(s.altitude_m - 1.0) < 0.05, s
