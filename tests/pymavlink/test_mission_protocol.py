"""The mission protocol against the twin, through pymavlink: a mission round-trips byte for byte,
a mission with an item the twin cannot fly is refused and leaves the stored one as it was, a
refusal reason longer than one STATUSTEXT reaches pymavlink whole (chunks with id/chunk_seq),
and the mission survives a restart beside the parameter file."""

from __future__ import annotations

import math
import struct

import pytest

from pymavlink import mavutil

from conftest import VEHICLE_COMPID, VEHICLE_SYSID, Gcs

MAV = mavutil.mavlink
HOME = (-353632610, 1491652300)  # SIM_HOME_LAT/LON defaults, 1e-7 degree


def north_east(north_m: float, east_m: float) -> tuple[int, int]:
    """A point relative to the frame's origin (ArduPilot's flat-earth scaling)."""
    lat = HOME[0] + round(north_m / 0.011131884502145034)
    lon = HOME[1] + round(east_m / (0.011131884502145034 * math.cos(math.radians(HOME[0] * 1e-7))))
    return lat, lon


def item(seq: int, command: int, north: float, east: float, alt: float, p1=0.0, p2=0.0, p4=0.0,
         frame=MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, current=0):
    lat, lon = north_east(north, east) if (north, east) != (0, 0) else (0, 0)
    return MAV.MAVLink_mission_item_int_message(VEHICLE_SYSID, VEHICLE_COMPID, seq, frame, command,
                                                current, 1, p1, p2, 0.0, p4, lat, lon, alt)


def plan():
    # Item 0 is home as the vehicle serves it (ArduPilot writes home into the slot: a download
    # returns the current home whatever was uploaded there), so the round trip is exact.
    home = MAV.MAVLink_mission_item_int_message(VEHICLE_SYSID, VEHICLE_COMPID, 0, MAV.MAV_FRAME_GLOBAL,
                                                MAV.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                                HOME[0], HOME[1], 584.0)
    return [
        home,
        item(1, MAV.MAV_CMD_NAV_VTOL_TAKEOFF, 0, 0, 2.5),
        item(2, MAV.MAV_CMD_NAV_WAYPOINT, 4.0, 1.0, 3.0, p1=1.5, p2=0.25, p4=float("nan")),
        item(3, MAV.MAV_CMD_NAV_LOITER_TIME, -2.0, 3.0, 2.0, p1=5.0),
        item(4, MAV.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, frame=MAV.MAV_FRAME_MISSION),
    ]


def wire_bytes(m) -> bytes:
    """An item's MISSION_ITEM_INT payload in wire order, targets and mission type left out: what
    must survive the round trip bit for bit."""
    return struct.pack("<ffffiifHHBBB", m.param1, m.param2, m.param3, m.param4, m.x, m.y, m.z,
                       m.seq, m.command, m.frame, m.current, m.autocontinue)


def upload(g: Gcs, items) -> tuple[int, list]:
    """Answers the twin's requests; returns the MISSION_ACK result and the STATUSTEXTs seen."""
    g.drain()
    g.mav.mission_count_send(VEHICLE_SYSID, VEHICLE_COMPID, len(items))
    texts = []
    while True:
        m = g.recv(["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK", "STATUSTEXT"], timeout=10,
                   what="mission request or ACK")
        if m.get_type() == "STATUSTEXT":
            texts.append(m)
        elif m.get_type() == "MISSION_ACK":
            # a refusal's reason follows its ACK
            while (t := g.m.recv_match(type="STATUSTEXT", blocking=True, timeout=0.5)) is not None:
                texts.append(t)
                if t.id == 0 or len(t.text) < 50:
                    break
            return m.type, texts
        else:
            g.mav.send(items[m.seq])


def download(g: Gcs) -> list:
    g.drain()
    g.mav.mission_request_list_send(VEHICLE_SYSID, VEHICLE_COMPID)
    count = g.recv("MISSION_COUNT", timeout=10).count
    out = []
    for seq in range(count):
        g.mav.mission_request_int_send(VEHICLE_SYSID, VEHICLE_COMPID, seq)
        out.append(g.recv("MISSION_ITEM_INT", lambda m, s=seq: m.seq == s, timeout=10))
    return out


def reassemble(texts) -> list[str]:
    """STATUSTEXT chunks put together as MAVProxy does: same id, in chunk_seq order, complete
    at a chunk shorter than 50 characters; id 0 is a text of its own."""
    whole, parts = [], {}
    for t in texts:
        if t.id == 0:
            whole.append(t.text)
            continue
        parts.setdefault(t.id, {})[t.chunk_seq] = t.text
        if len(t.text) < 50:
            chunks = parts.pop(t.id)
            assert sorted(chunks) == list(range(len(chunks))), f"chunks missing: {sorted(chunks)}"
            whole.append("".join(chunks[k] for k in sorted(chunks)))
    return whole


def test_round_trip_refusal_and_long_reason(twin_factory, gcs_factory):
    twin = twin_factory(speed=4)
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    sent = plan()
    result, _ = upload(g, sent)
    assert result == MAV.MAV_MISSION_ACCEPTED
    got = download(g)
    assert [wire_bytes(m) for m in got] == [wire_bytes(m) for m in sent]
    assert math.isnan(got[2].param4), "NaN survives"
    assert all((m.target_system, m.target_component) == (255, 190) for m in got)

    # An item the twin cannot fly (DO_SET_SERVO): refused with UNSUPPORTED, nothing changes.
    bad = plan()
    bad[3] = MAV.MAVLink_mission_item_int_message(VEHICLE_SYSID, VEHICLE_COMPID, 3, MAV.MAV_FRAME_MISSION,
                                                  MAV.MAV_CMD_DO_SET_SERVO, 0, 1, 5, 1500, 0, 0, 0, 0, 0)
    result, texts = upload(g, bad)
    assert result == MAV.MAV_MISSION_UNSUPPORTED
    assert "Mission item 3: DO_SET_SERVO is not supported" in reassemble(texts)
    assert [wire_bytes(m) for m in download(g)] == [wire_bytes(m) for m in sent]

    # A waypoint 120 m out with the envelope set to the hover's 100 m (the default is sized for
    # forward flight): refused, and the 64-character reason arrives whole, in two chunks.
    g.param_set("NAV_RADIUS_MAX", 100)
    far = plan()
    far[2] = item(2, MAV.MAV_CMD_NAV_WAYPOINT, 120.0, 0, 3.0)
    result, texts = upload(g, far)
    assert result == MAV.MAV_MISSION_INVALID_PARAM5_X
    chunked = [t for t in texts if t.id != 0]
    assert [t.chunk_seq for t in chunked] == [0, 1], texts
    reason = "Mission item 2 is 120.0 m from home, beyond NAV_RADIUS_MAX 100 m"
    assert len(reason) >= 60
    assert reason in reassemble(texts), reassemble(texts)
    assert [wire_bytes(m) for m in download(g)] == [wire_bytes(m) for m in sent]


def test_mission_survives_a_restart(twin_factory, gcs_factory, tmp_path):
    param_file = tmp_path / "twin.parm"
    twin = twin_factory(speed=4, param_file=param_file)
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    sent = plan()
    assert upload(g, sent)[0] == MAV.MAV_MISSION_ACCEPTED
    g.close()
    twin_factory.stop(twin)
    assert (tmp_path / "twin.waypoints").read_text().startswith("QGC WPL 110\n")

    again = twin_factory(speed=4, param_file=param_file)
    g2 = gcs_factory(again.tcp)
    g2.wait_vehicle_heartbeat()
    assert [wire_bytes(m) for m in download(g2)] == [wire_bytes(m) for m in sent]


def test_item_0_downloads_as_the_current_home(twin_factory, gcs_factory):
    """MAVSDK uploads the home slot with altitude 0; ArduPlane's download returns home as it has
    it (584 m above sea level here), never the slot as sent."""
    twin = twin_factory(speed=4)
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    sent = plan()
    sent[0] = MAV.MAVLink_mission_item_int_message(VEHICLE_SYSID, VEHICLE_COMPID, 0,
                                                   MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                   MAV.MAV_CMD_NAV_WAYPOINT, 1, 1, 0, 0, 0, 0,
                                                   HOME[0], HOME[1], 0.0)
    assert upload(g, sent)[0] == MAV.MAV_MISSION_ACCEPTED
    got = download(g)
    assert (got[0].frame, got[0].x, got[0].y) == (MAV.MAV_FRAME_GLOBAL, HOME[0], HOME[1])
    assert got[0].z == pytest.approx(584.0, abs=0.01), got[0]
    assert [wire_bytes(m) for m in got[1:]] == [wire_bytes(m) for m in sent[1:]]
