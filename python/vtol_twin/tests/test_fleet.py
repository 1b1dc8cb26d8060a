"""The fixtures' options, the fleet factory and their errors."""

import math

import pytest

from vtol_twin import TwinError, TwinOptions


def test_a_fleet_has_one_system_id_each(vtol_fleet):
    twins = vtol_fleet(3)
    assert [t.sysid for t in twins] == [1, 2, 3]
    assert len({t.url for t in twins}) == 3
    m = twins[2].connect()
    assert m.target_system == 3


@pytest.mark.vtol_twin(initial={"x": 2.0, "y": -1.0, "psi": 0.5}, seed=4, speed="lockstep")
def test_the_marker_sets_the_start(vtol_twin):
    s = vtol_twin.state()
    # Paper frame (x, y, z up; psi) → NED: (−x, y, −z). The attitude is ArduPilot's fixed-wing
    # frame: on its tail the pitch is 90° and the yaw the belly's heading, the hover's (−psi)
    # turned half a turn.
    assert s.position_ned_m[:2] == (-2.0, -1.0)
    assert math.isclose(s.pitch_rad, math.pi / 2) and s.roll_rad == 0.0
    assert math.isclose(s.yaw_rad, math.pi - 0.5)
    assert s.system_status == "STANDBY" and s.t_us == 0, "ready to arm at once"


def test_a_param_file_is_copied_not_rewritten(vtol_fleet, tmp_path):
    pf = tmp_path / "gains.parm"
    pf.write_text("HOVER_ALT 2.5\n")
    [twin] = vtol_fleet(1, param_file=pf, params={"LAND_SPEED": 0.8})
    m = twin.connect()
    m.param_fetch_one("HOVER_ALT")
    p = m.recv_match(type="PARAM_VALUE", condition="PARAM_VALUE.param_id=='HOVER_ALT'", blocking=True, timeout=5)
    assert p.param_value == 2.5
    assert twin.set_param("HOVER_ALT", 3) == 3.0
    assert pf.read_text() == "HOVER_ALT 2.5\n"


def test_refusals_say_why(vtol_twin):
    with pytest.raises(TwinError, match="unknown parameter NOPE"):
        vtol_twin.set_param("NOPE", 1)
    with pytest.raises(TwinError, match=r"outside \["):
        vtol_twin.set_param("HOVER_ALT", 1e6)
    with pytest.raises(TwinError, match="push needs"):
        vtol_twin.push()
    with pytest.raises(TypeError, match="unknown vtol_twin option 'sped'"):
        TwinOptions.merged({"sped": 3})


@pytest.mark.vtol_twin(speed=20)
def test_a_twin_in_scaled_time_flies_on_its_own(vtol_twin):
    with pytest.raises(TwinError, match="advance needs a lockstep twin"):
        vtol_twin.advance(1)
    m = vtol_twin.connect()
    # Twenty times real time: four seconds of flight pass in a fifth of a second.
    first = m.recv_match(type="ATTITUDE", blocking=True, timeout=5)
    later = m.recv_match(type="ATTITUDE", condition=f"ATTITUDE.time_boot_ms >= {first.time_boot_ms + 4000}",
                         blocking=True, timeout=10)
    assert later is not None
