"""MAVSDK (`mavsdk` 4, the native Python binding, asyncio API) flies the twin as its examples fly
a vehicle: connect and find the autopilot, `telemetry` health and position, `param` get/set,
the flight mode, `mission_raw` upload and download, `action.arm/takeoff/goto_location`,
`mission_raw.start_mission` to the end, `action.return_to_launch` to landed and disarmed.
Directly against the twin and through the daemon, over TCP and UDP.

Every wait is on a telemetry subscription (or MAVSDK's own blocking call) with a deadline.
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

from conftest import twin_factory  # noqa: F401 (fixture)
from daemon_support import daemon_factory  # noqa: F401 (fixture)
from sdk_targets import distance_m, offset, target  # noqa: F401 (fixture)

HERE = Path(__file__).resolve().parent
TAKEOFF_ALT = 2.0
STEP_TIMEOUT = 30.0  # wall seconds; the twin flies at sdk_targets.FLIGHT_SPEED x real time

MAV_FRAME_GLOBAL = 0
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 6
MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_VTOL_TAKEOFF = 84
MAV_FRAME_MISSION = 2
MAV_CMD_DO_VTOL_TRANSITION = 3000
MAV_VTOL_STATE_MC = 3


async def first(gen, pred, what: str, timeout: float = STEP_TIMEOUT):
    """The first value of a subscription that satisfies `pred`, within `timeout`."""

    async def scan():
        async for v in gen:
            if pred(v):
                return v

    try:
        return await asyncio.wait_for(scan(), timeout)
    except asyncio.TimeoutError:
        raise AssertionError(f"no {what} within {timeout} s") from None
    finally:
        await gen.aclose()


async def connect(url: str):
    """As the examples connect: a ground station, then the first autopilot."""
    configuration = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    mavsdk = Mavsdk(configuration)
    await mavsdk.add_any_connection(url)
    drone = await mavsdk.first_autopilot(STEP_TIMEOUT)
    assert drone is not None, f"no autopilot at {url}"
    return mavsdk, drone


def mission_item(seq: int, command: int, lat: float, lon: float, alt: float,
                 frame: int = MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, param1: float = 0.0) -> MissionItem:
    return MissionItem(seq=seq, frame=frame, command=command, current=int(seq == 0),
                       autocontinue=1, param1=param1, param2=0.0, param3=0.0, param4=0.0,
                       x=round(lat * 1e7), y=round(lon * 1e7), z=alt, mission_type=0)


def test_mavsdk_flies_the_twin_as_documented(target):
    # The flows run in a process of their own: MAVSDK aborts the whole process when its Mavsdk
    # instance goes before a System or plugin obtained from it ("must not outlive the Mavsdk
    # instance"), which would take the test worker with it.
    r = subprocess.run([sys.executable, "-c", f"import test_mavsdk; test_mavsdk.fly_in_child({target.mavsdk_url!r})"],
                       cwd=HERE, capture_output=True, text=True, timeout=260)
    assert r.returncode == 0 and FLOWN in r.stdout, f"exit {r.returncode}\n{r.stdout}\n{r.stderr}"


FLOWN = "the documented flows flew"


def fly_in_child(url: str) -> None:
    """The child's whole work: connect, fly every flow (an assertion that fails exits 1 with
    its traceback), say so, and exit at once. The Mavsdk instance is held to the end, past the
    System and the plugins, which go with the coroutine that used them."""
    async def fly():
        mavsdk, drone = await connect(url)
        await fly_documented_flows(drone)
        return mavsdk

    mavsdk = asyncio.run(asyncio.wait_for(fly(), timeout=200))
    print(FLOWN, flush=True)
    os._exit(0 if mavsdk is not None else 1)


async def fly_documented_flows(drone):
    from mavsdk import Autopilot

    assert await drone.autopilot_type() == Autopilot.ARDUPILOT
    telemetry = TelemetryAsync(drone)
    param = ParamAsync(drone)
    mission = MissionRawAsync(drone)
    action = ActionAsync(drone)

    # Health: what the examples wait on before they fly.
    await first(telemetry.subscribe_health(),
                lambda h: h.is_global_position_ok and h.is_home_position_ok and h.is_armable
                and h.is_local_position_ok, "healthy, armable vehicle")
    home = await telemetry.home()  # the latest HOME_POSITION: health says there is one
    assert abs(home.latitude_deg) > 0 and abs(home.longitude_deg) > 0, home
    pos = await first(telemetry.subscribe_position(), lambda p: abs(p.latitude_deg) > 0,
                      "position")
    assert distance_m(pos.latitude_deg, pos.longitude_deg, home.latitude_deg,
                      home.longitude_deg) < 0.5

    # Parameters: a float and an integer, read and written.
    assert await param.get_param_float("Q_WP_RADIUS") == pytest.approx(200.0, abs=1e-6)
    await param.set_param_float("Q_WP_RADIUS", 50.0)
    assert await param.get_param_float("Q_WP_RADIUS") == pytest.approx(50.0, abs=1e-6)
    assert await param.get_param_int("WP_RADIUS") == 90  # ArduPlane's INT16
    assert await param.get_param_int("SYSID_THISMAV") == 1
    # Fly as a VTOL-only QuadPlane is set up on ArduPlane: GUIDED targets held in a hover
    # (Q_GUIDED_MODE 1) and RTL as QRTL (Q_RTL_MODE 3); the defaults fly both on the wing.
    await param.set_param_int("Q_GUIDED_MODE", 1)
    await param.set_param_int("Q_RTL_MODE", 3)

    # A raw mission: home slot, VTOL take-off, two waypoints (ArduPilot's layout).
    lat0, lon0 = home.latitude_deg, home.longitude_deg
    wp1 = offset(lat0, lon0, 3.0, 2.0)
    wp2 = offset(lat0, lon0, 0.0, 2.0)
    items = [
        mission_item(0, MAV_CMD_NAV_WAYPOINT, lat0, lon0, home.absolute_altitude_m, MAV_FRAME_GLOBAL),
        mission_item(1, MAV_CMD_NAV_VTOL_TAKEOFF, 0.0, 0.0, TAKEOFF_ALT),
        # ArduPlane flies the waypoints after a take-off on the wing; to MC keeps them in a hover.
        mission_item(2, MAV_CMD_DO_VTOL_TRANSITION, 0.0, 0.0, 0.0, MAV_FRAME_MISSION,
                     param1=MAV_VTOL_STATE_MC),
        mission_item(3, MAV_CMD_NAV_WAYPOINT, *wp1, TAKEOFF_ALT),
        mission_item(4, MAV_CMD_NAV_WAYPOINT, *wp2, TAKEOFF_ALT),
    ]
    await mission.upload_mission(items)
    down = await mission.download_mission()
    assert [(i.seq, i.command, i.x, i.y) for i in down] == [(i.seq, i.command, i.x, i.y) for i in items]

    # Arm, take off (MAVSDK switches ArduPilot to GUIDED first), go to a point.
    await action.set_takeoff_altitude(TAKEOFF_ALT)
    await action.arm()
    await first(telemetry.subscribe_armed(), bool, "armed")
    await action.takeoff()
    await first(telemetry.subscribe_position(),
                lambda p: p.relative_altitude_m >= TAKEOFF_ALT * 0.95, "take-off altitude")
    target_lat, target_lon = offset(lat0, lon0, 3.0, 0.0)
    await action.goto_location(target_lat, target_lon, home.absolute_altitude_m + TAKEOFF_ALT, 0.0)
    await first(telemetry.subscribe_position(),
                lambda p: distance_m(p.latitude_deg, p.longitude_deg, target_lat, target_lon) < 0.5,
                "goto_location flown")

    # The mission, started by MAVSDK (ArduPilot: AUTO), to its end. The flight mode reads
    # MISSION (MAVSDK's telemetry has no name for ArduPlane's GUIDED or Q modes: UNKNOWN).
    await mission.start_mission()
    await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.MISSION, "AUTO")
    await first(mission.subscribe_mission_progress(), lambda p: p.total > 0 and p.current >= p.total,
                "mission progress to the end")

    # Return to launch (QRTL, Q_RTL_MODE 3) to landed and disarmed.
    await action.return_to_launch()
    await first(telemetry.subscribe_armed(), lambda a: not a, "landed and disarmed")
    pos = await telemetry.position()
    assert distance_m(pos.latitude_deg, pos.longitude_deg, lat0, lon0) < 1.0
    assert pos.relative_altitude_m < 0.3
