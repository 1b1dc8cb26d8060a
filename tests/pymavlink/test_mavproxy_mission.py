"""MAVProxy 1.8.75 with its own default modules (wp, fence, rally, battery… all loaded) against
the twin, through its console: it connects without a warning (no fence breach), `wp list` lists
the (empty) mission, `wp load FILE` uploads one, `mode AUTO` and `arm throttle` fly it, and `rtl`
brings the vehicle home to land. What the vehicle does is checked through our own pymavlink
connection; the twin runs at 10x."""

from __future__ import annotations

import math
import re

import pexpect

from conftest import FLAG_ARMED, Gcs
from procs import mavproxy

QRTL = 21
AUTO = 10
HOME = (-353632610, 1491652300)

# Anything MAVProxy says when something is wrong: the fence bit, arming checks, protocol trouble.
WARNING = re.compile(r"breach|unhealthy|checks disabled|fail|error|timed? ?out|stale|re-request|"
                     r"unexpected|bad |unknown|not available|prearm|warning|denied", re.I)

MISSION = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t-35.3632610\t149.1652300\t584.000000\t1
1\t0\t3\t84\t0\t0\t0\t0\t0\t0\t2.000000\t1
2\t0\t2\t3000\t3\t0\t0\t0\t0\t0\t0\t1
3\t0\t3\t19\t60\t0\t0\t0\t-35.3632340\t149.1652300\t2.000000\t1
4\t0\t2\t20\t0\t0\t0\t0\t0\t0\t0\t1
"""
# Item 2 (DO_VTOL_TRANSITION to MC) keeps the loiter in a hover, as on ArduPlane.
LOITER = (-353632340, 1491652300)  # item 3: 3 m north of home, held for 60 s


def metres(lat: int, lon: int, ref: tuple[int, int]) -> float:
    dn = (lat - ref[0]) * 0.011131884502145034
    de = (lon - ref[1]) * 0.011131884502145034 * math.cos(math.radians(ref[0] * 1e-7))
    return math.hypot(dn, de)


def expect(child, pattern: str, timeout: float = 30):
    try:
        child.expect(pattern, timeout=timeout)
    except (pexpect.TIMEOUT, pexpect.EOF) as e:
        raise AssertionError(f"MAVProxy did not print {pattern!r} ({type(e).__name__}); "
                             f"last output: {child.before[-2000:]!r}") from None


def test_mavproxy_wp_list_load_auto_rtl(twin_factory, gcs_factory, tmp_path):
    twin = twin_factory(speed=10)
    observer: Gcs = gcs_factory(twin.udp)
    observer.wait_vehicle_heartbeat()
    plan = tmp_path / "plan.waypoints"
    plan.write_text(MISSION)
    with mavproxy(twin.tcp, tmp_path, modules=None) as child:
        expect(child, r"Received \d+ parameters", timeout=60)
        child.sendline("wp list")
        expect(child, r"Requesting 0 waypoints")
        connect_output = child.before + child.after
        warnings = [line for line in connect_output.splitlines() if WARNING.search(line)]
        assert not warnings, f"MAVProxy warned at connect: {warnings}"

        child.sendline(f"wp load {plan}")
        expect(child, r"Loaded 5 waypoints")
        expect(child, r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED")
        child.sendline("wp list")
        expect(child, r"Requesting 5 waypoints")
        expect(child, r"Saved 5 waypoints")

        observer.wait_ready()
        child.sendline("mode AUTO")
        observer.wait_vehicle_heartbeat(pred=lambda h: h.custom_mode == AUTO)
        child.sendline("arm throttle")
        # The take-off is the first item reached (waiting for an armed heartbeat first could
        # read past it: heartbeats come once a wall second, the flight runs at 10x).
        assert observer.recv("MISSION_ITEM_REACHED", timeout=30).seq == 1, "the take-off"
        observer.recv("GLOBAL_POSITION_INT", lambda p: metres(p.lat, p.lon, LOITER) < 0.5, timeout=30,
                      what="at the loiter point")

        # RTL as QRTL always (Q_RTL_MODE 3; ArduPlane's default 0 flies home on the wing).
        child.sendline("param set Q_RTL_MODE 3")
        observer.recv("PARAM_VALUE", lambda p: p.param_id == "Q_RTL_MODE" and p.param_value == 3,
                      timeout=30, what="Q_RTL_MODE 3")
        child.sendline("rtl")
        expect(child, r"Mode QRTL")
        observer.wait_vehicle_heartbeat(pred=lambda h: h.custom_mode == QRTL)
        observer.wait_vehicle_heartbeat(timeout=60, pred=lambda h: not h.base_mode & FLAG_ARMED)
        p = observer.recv("GLOBAL_POSITION_INT")
        assert metres(p.lat, p.lon, HOME) < 0.3 and p.relative_alt < 100, p
        assert child.isalive()
    text = (tmp_path / "mavproxy.out").read_text(errors="replace")
    assert "fence breach" not in text, text[-3000:]
