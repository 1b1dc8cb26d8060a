"""The test bed's lossy radio (docs/network.md): 30 % of the datagrams dropped each way on the
vehicle link, 100 ms ± 20 ms each way (200 ms of round trip, with jitter), the daemon between.
A parameter pull and a verified push of the controller gains, a 50-item mission upload, and an
arm, take-off and landing by command all complete through the daemon.
"""

from __future__ import annotations

import math

import pytest
from pymavlink import mavutil

from conftest import VEHICLE_COMPID, VEHICLE_SYSID
from netbed_support import Scene, command, needs_bed, upload_mission

pytestmark = needs_bed
MAV = mavutil.mavlink

LOSS_PCT = 30
ONE_WAY_MS = 100
JITTER_MS = 20

GAINS = {"ALT_KP": 4.5, "ALT_KD": 2.5, "YAW_KP": 4.5, "YAW_KD": 4.5}


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    s = Scene(tmp_path_factory.mktemp("netbed-lossy"), delay_ms=ONE_WAY_MS, jitter_ms=JITTER_MS, seed=7)
    s.bed.loss(LOSS_PCT)
    yield s
    s.close()


def test_parameter_pull_and_a_verified_gain_push_complete(scene):
    pulled = scene.workdir / "pulled.parm"
    wall, r = scene.cli("params", "pull", "-o", str(pulled))
    assert r.returncode == 0, r.stderr
    # QGroundControl's format: vehicle, component, name, value, type.
    table = dict(line.split()[2:4] for line in pulled.read_text().splitlines() if line and not line.startswith("#"))
    assert set(GAINS) <= set(table), sorted(table)
    gains = scene.workdir / "gains.parm"
    gains.write_text("".join(f"{k} {v}\n" for k, v in GAINS.items()))
    wall, r = scene.cli("params", "push", str(gains))
    assert r.returncode == 0, r.stderr
    wall, r = scene.cli("params", "get", *GAINS)
    assert r.returncode == 0, r.stderr
    got = dict(line.split()[:2] for line in r.stdout.splitlines())
    assert {k: float(v) for k, v in got.items()} == pytest.approx(GAINS), r.stdout
    c = scene.bed.counters()
    assert c["dropped_from_vehicle"] > 0 and c["dropped_from_ground"] > 0, c


def north_east(north_m: float, east_m: float) -> tuple[int, int]:
    home = (-353632610, 1491652300)  # the twin's SIM_HOME_LAT/LON, 1e-7 degree
    lat = home[0] + round(north_m / 0.011131884502145034)
    lon = home[1] + round(east_m / (0.011131884502145034 * math.cos(math.radians(home[0] * 1e-7))))
    return lat, lon


def fifty_items():
    items = [MAV.MAVLink_mission_item_int_message(VEHICLE_SYSID, VEHICLE_COMPID, 0, MAV.MAV_FRAME_GLOBAL_INT,
                                                   MAV.MAV_CMD_NAV_WAYPOINT, 1, 1, 0, 0, 0, 0, 0, 0, 0)]
    items.append(MAV.MAVLink_mission_item_int_message(VEHICLE_SYSID, VEHICLE_COMPID, 1,
                                                      MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                      MAV.MAV_CMD_NAV_VTOL_TAKEOFF, 0, 1, 0, 0, 0, 0, 0, 0, 3.0))
    for seq in range(2, 50):
        lat, lon = north_east(2.0 * math.cos(seq / 3), 2.0 * math.sin(seq / 3))
        items.append(MAV.MAVLink_mission_item_int_message(VEHICLE_SYSID, VEHICLE_COMPID, seq,
                                                          MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                          MAV.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0.5, 0, 0, lat, lon,
                                                          3.0 + (seq % 5) * 0.25))
    return items


def test_a_fifty_item_mission_uploads(scene):
    g = scene.client()
    items = fifty_items()
    assert upload_mission(g, items) == MAV.MAV_MISSION_ACCEPTED
    # What the twin stored (it saves an accepted mission beside its parameter file): every item,
    # in order. (A download over the same radio checks the same items, at twice the time.)
    stored = (scene.workdir / "params.waypoints").read_text().splitlines()
    assert stored[0] == "QGC WPL 110"
    rows = [line.split("\t") for line in stored[1:]]
    assert [(int(r[0]), int(r[3]), round(float(r[8]) * 1e7), round(float(r[9]) * 1e7), float(r[10]))
            for r in rows] == [(m.seq, m.command, m.x, m.y, pytest.approx(m.z)) for m in items]


def test_arm_take_off_and_land_by_command(scene):
    g = scene.client()
    g.wait_ready(timeout=60)
    guided = 15
    ack = command(g, MAV.MAV_CMD_DO_SET_MODE, 1, guided)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED, ack
    ack = command(g, MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED, ack
    mark = scene.daemon.mark()
    # A repeat of an accepted take-off (its ACK lost) may be refused: the climb is what counts.
    command(g, MAV.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 3.0)
    scene.status(r"ARMED .*\| alt \+(2\.[5-9]\d|[3-9]\.\d\d) m", timeout=60, since=mark)
    qland = 20
    ack = command(g, MAV.MAV_CMD_DO_SET_MODE, 1, qland)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED, ack
    mark = scene.daemon.mark()
    # QLAND touches down and disarms: the daemon shows it.
    scene.status(r"QLAND disarmed .*\| alt [+-]0\.[0-2]\d m", timeout=90, since=mark)
