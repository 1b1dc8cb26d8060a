"""The conformance scenarios: scripts that run unchanged against any vehicle URL (ArduPlane SITL,
the twin) and write what the vehicle answered into a `Trace`.

Each scenario expects a freshly started vehicle (no stored mission, parameters at their
defaults). `SCENARIOS` lists them in the order they run: the quick protocol ones first, then
the flights.
"""

from __future__ import annotations

import math

from vehicle import (MAV, MAV_RESULTS, MODE_NAMES, PLANE_MODES, WATCHED, Timeout, Trace, Vehicle, category,
                     phase_summary, prefix)

TAKEOFF_ALT = 20.0
EARTH_R = 6378100.0  # ArduPilot's flat-earth radius


def offset(lat: int, lon: int, north: float, east: float) -> tuple[int, int]:
    """A point `north`, `east` metres from lat/lon (1e-7 degree), ArduPilot's flat-earth way."""
    dlat = math.degrees(north / EARTH_R) * 1e7
    dlon = math.degrees(east / (EARTH_R * math.cos(math.radians(lat / 1e7)))) * 1e7
    return int(round(lat + dlat)), int(round(lon + dlon))


def distance_m(lat1: int, lon1: int, lat2: int, lon2: int) -> float:
    dn = math.radians((lat2 - lat1) * 1e-7) * EARTH_R
    de = math.radians((lon2 - lon1) * 1e-7) * EARTH_R * math.cos(math.radians(lat1 * 1e-7))
    return math.hypot(dn, de)


def reasons(v: Vehicle, mark: int, tr: Trace, key: str) -> None:
    """The STATUSTEXTs since `mark`: the PreArm/Arm reasons by category (protocol), every text
    (info)."""
    texts = v.texts_since(mark)
    tr.proto(key + ".reasons", sorted({category(t) for t in texts if prefix(t) in ("PreArm", "Arm")}))
    tr.info(key + ".texts", texts)


def begin(v: Vehicle, tr: Trace, armable: bool = True) -> None:
    v.heartbeat()
    v.setup_streams()
    if armable:
        v.wait_armable()


# -- protocol scenarios ------------------------------------------------------------------------


def identify(v: Vehicle, tr: Trace) -> None:
    hb = v.heartbeat()
    tr.proto("heartbeat.type", hb.type)
    tr.proto("heartbeat.autopilot", hb.autopilot)
    tr.proto("heartbeat.custom_mode_flag", bool(hb.base_mode & 1))
    tr.proto("heartbeat.armed", bool(hb.base_mode & 128))
    tr.proto("heartbeat.custom_mode", hb.custom_mode)
    tr.proto("heartbeat.mavlink_version", hb.mavlink_version)
    tr.proto("set_message_interval", v.setup_streams())
    tr.proto("request_autopilot_version", v.cmd(MAV.MAV_CMD_REQUEST_MESSAGE, 148))
    av = v.recv("AUTOPILOT_VERSION", timeout=10)
    caps = [name[len("MAV_PROTOCOL_CAPABILITY_"):] for bit, name in
            ((k, e.name) for k, e in MAV.enums["MAV_PROTOCOL_CAPABILITY"].items() if k < 1 << 32)
            if av.capabilities & bit and name.startswith("MAV_PROTOCOL_CAPABILITY_") and not name.endswith("ENUM_END")]
    tr.proto("autopilot_version.capabilities", sorted(caps))
    sw = av.flight_sw_version
    tr.info("autopilot_version.flight_sw_version", f"{sw >> 24}.{(sw >> 16) & 255}.{(sw >> 8) & 255}")
    with v.window() as w:
        v.wait_vehicle_time(5.0)
    tr.proto("streams", sorted({m.get_type() for _, m in w} & set(WATCHED)))
    v.wait_armable()
    v.drain()
    v.m.mav.mission_request_list_send(1, 1, 0)
    tr.proto("mission_count_fresh", v.recv("MISSION_COUNT", timeout=10).count)
    v.m.mav.mission_request_int_send(1, 1, 0, 0)
    item0 = v.recv(["MISSION_ITEM_INT", "MISSION_ACK"], timeout=10)
    tr.proto("mission_item0", [item0.get_type(), getattr(item0, "command", None), getattr(item0, "frame", None)])
    v.drain()
    v.m.mav.mission_request_list_send(1, 1, 1)
    tr.proto("fence_count_fresh", v.recv("MISSION_COUNT", timeout=10).count)
    v.m.mav.mission_request_list_send(1, 1, 2)
    tr.proto("rally_count_fresh", v.recv("MISSION_COUNT", timeout=10).count)
    tr.proto("request_home", v.cmd(MAV.MAV_CMD_REQUEST_MESSAGE, 242))
    home = v.recv("HOME_POSITION", timeout=10)
    gpi = v.last["GLOBAL_POSITION_INT"]
    tr.phys("home_vs_position_m", round(distance_m(home.latitude, home.longitude, gpi.lat, gpi.lon), 2))
    tr.proto("unknown_command", v.cmd(31999))


PARAMS_READ = ["WP_RADIUS", "Q_A_RAT_RLL_P", "Q_A_RAT_RLL_I", "Q_A_RAT_RLL_D", "Q_A_RAT_RLL_FF",
               "Q_A_RAT_PIT_P", "Q_A_RAT_PIT_I", "Q_A_RAT_PIT_D", "Q_A_RAT_YAW_P", "Q_A_RAT_YAW_I",
               "Q_A_RAT_YAW_D", "SYSID_THISMAV", "MAV_SYSID", "Q_TAILSIT_ENABLE", "Q_RTL_MODE", "Q_GUIDED_MODE",
               "RTL_ALTITUDE", "Q_WP_SPEED"]


def _param(tr: Trace, key: str, pv) -> None:
    if pv is None:
        tr.proto(key + ".answered", False)
        return
    tr.proto(key + ".answered", True)
    tr.proto(key + ".type", pv.param_type)
    tr.phys(key + ".value", pv.param_value)


def params(v: Vehicle, tr: Trace) -> None:
    begin(v, tr, armable=False)
    first = v.param_read("WP_RADIUS")
    tr.info("param_count", first.param_count if first else None)
    # All reads at once; a name the vehicle does not have gets no answer.
    got = {}
    v.drain()
    for name in PARAMS_READ:
        v.m.mav.param_request_read_send(1, 1, name.encode(), -1)
    try:
        v.collect("PARAM_VALUE", lambda l: (got.update({p.param_id: p for p in l}) or set(PARAMS_READ) <= set(got)),
                  timeout=3)
    except Timeout:
        pass
    for name in PARAMS_READ:
        _param(tr, f"read.{name}", got.get(name))
    _param(tr, "write.WP_RADIUS=0.4", v.param_write("WP_RADIUS", 0.4))
    _param(tr, "reread.WP_RADIUS", v.param_read("WP_RADIUS"))
    _param(tr, "write.WP_RADIUS=25", v.param_write("WP_RADIUS", 25))
    _param(tr, "write.Q_A_RAT_RLL_P=0.3", v.param_write("Q_A_RAT_RLL_P", 0.3, timeout=2))
    _param(tr, "reread.Q_A_RAT_RLL_P", v.param_read("Q_A_RAT_RLL_P", timeout=2))
    _param(tr, "read.NO_SUCH_PARAM", v.param_read("NO_SUCH_PARAM", timeout=2))
    _param(tr, "write.NO_SUCH_PARAM", v.param_write("NO_SUCH_PARAM", 1.0, timeout=2))
    v.drain()
    v.m.mav.param_request_read_send(1, 1, b"", 0)
    pv = v.recv("PARAM_VALUE", timeout=5)
    tr.proto("read_index0.index", pv.param_index)


def prearm(v: Vehicle, tr: Trace) -> None:
    v.heartbeat()
    v.setup_streams()
    mark = len(v.statustexts)
    tr.proto("arm_at_boot", v.arm())
    v.wait_vehicle_time(2.0)
    reasons(v, mark, tr, "arm_at_boot")
    if v.armed():
        v.disarm()
    v.wait_armable()
    for mode in ("QLAND", "QRTL", "RTL", "AUTO"):
        tr.proto(f"mode_{mode}", v.mode(mode))
        mark = len(v.statustexts)
        tr.proto(f"arm_in_{mode}", v.arm())
        v.wait_vehicle_time(1.0)
        reasons(v, mark, tr, f"arm_in_{mode}")
        if v.armed():
            tr.proto(f"disarm_in_{mode}", v.disarm())


def arm_disarm(v: Vehicle, tr: Trace) -> None:
    begin(v, tr)
    tr.proto("boot_mode", v.modes[-1] if v.modes else None)
    for mode in ("QSTABILIZE", "QHOVER", "QLOITER", "MANUAL", "FBWA"):
        tr.proto(f"{mode}.mode", v.mode(mode))
        if not v.wait_mode(mode, timeout=5):
            continue  # refused: arming here would repeat the previous mode's round
        mark = len(v.statustexts)
        tr.proto(f"{mode}.arm", v.arm())
        tr.proto(f"{mode}.armed_seen", v.until(v.armed, timeout=10, vehicle_s=5, ok_on_time=True))
        tr.proto(f"{mode}.arm_again", v.arm())
        tr.proto(f"{mode}.disarm", v.disarm())
        tr.proto(f"{mode}.disarmed_seen", v.until(lambda: not v.armed(), timeout=10, vehicle_s=5, ok_on_time=True))
        tr.proto(f"{mode}.disarm_again", v.disarm())
        reasons(v, mark, tr, mode)
        if v.armed():  # a refused disarm: end the round on the ground, disarmed
            tr.proto(f"{mode}.force_disarm", v.cmd(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196))
    tr.proto("armed_sequence", v.armed_seen)


GROUND_MODES = ["QSTABILIZE", "QHOVER", "QLOITER", "QLAND", "QRTL", "QACRO", "QAUTOTUNE", "MANUAL",
                "STABILIZE", "ACRO", "FBWA", "FBWB", "CRUISE", "CIRCLE", "LOITER", "RTL", "AUTO", "GUIDED",
                "TAKEOFF", "TRAINING", "AUTOTUNE", "THERMAL"]


def modes_ground(v: Vehicle, tr: Trace) -> None:
    begin(v, tr)  # ArduPlane stalls mode changes while it initialises
    for name in GROUND_MODES:
        mark = len(v.statustexts)
        tr.proto(f"{name}.ack", v.mode(name))
        hb = v.heartbeat()
        tr.proto(f"{name}.heartbeat_mode", MODE_NAMES.get(hb.custom_mode, hb.custom_mode))
        tr.info(f"{name}.texts", v.texts_since(mark))
    v.mode("QSTABILIZE")
    tr.proto("mode_99.ack", v.cmd(MAV.MAV_CMD_DO_SET_MODE, 1, 99))
    v.drain()
    v.m.mav.set_mode_send(1, 1, PLANE_MODES["QHOVER"])
    try:
        ack = v.recv("COMMAND_ACK", timeout=5)
        tr.proto("set_mode_message.ack", [ack.command, MAV_RESULTS.get(ack.result)])
    except Timeout:
        tr.proto("set_mode_message.ack", None)
    tr.proto("set_mode_message.heartbeat_mode", MODE_NAMES.get(v.heartbeat().custom_mode))


# -- missions -------------------------------------------------------------------------------------


def upload(v: Vehicle, items: list[tuple], mission_type: int = 0, timeout: float = 15.0) -> dict:
    """Uploads `items` (frame, command, p1..p4, lat, lon, alt) as MISSION_ITEM_INT, answering
    each request; returns how the vehicle asked and how it ended."""
    v.drain()
    v.m.mav.mission_count_send(1, 1, len(items), mission_type)
    asked: list[str] = []
    while True:
        msg = v.recv(["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], timeout=timeout)
        if msg.get_type() == "MISSION_ACK":
            return {"requests": sorted(set(asked)), "ack": _ack_name(msg.type), "asked": len(asked)}
        asked.append(msg.get_type())
        frame, cmd, p1, p2, p3, p4, x, y, z = items[msg.seq]
        v.m.mav.mission_item_int_send(1, 1, msg.seq, frame, cmd, 0, 1, p1, p2, p3, p4, x, y, z, mission_type)


def _ack_name(t: int) -> str:
    e = MAV.enums["MAV_MISSION_RESULT"].get(t)
    return e.name[len("MAV_MISSION_"):] if e else str(t)


def mission_count(v: Vehicle, mission_type: int = 0) -> int:
    v.drain()
    v.m.mav.mission_request_list_send(1, 1, mission_type)
    return v.recv("MISSION_COUNT", timeout=10).count


def where(v: Vehicle) -> tuple[int, int, int]:
    v.until(lambda: "GLOBAL_POSITION_INT" in v.last, timeout=30, what="GLOBAL_POSITION_INT")
    g = v.last["GLOBAL_POSITION_INT"]
    return g.lat, g.lon, g.alt


REL = MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT


def box_items(lat: int, lon: int, alt_msl_mm: int, land_north: float, land_east: float) -> list[tuple]:
    """Home, VTOL_TAKEOFF 20 m, the four corners of a 200 m box north of home, VTOL_LAND."""
    items = [(MAV.MAV_FRAME_GLOBAL, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, lat, lon, alt_msl_mm / 1000.0),
             (REL, MAV.MAV_CMD_NAV_VTOL_TAKEOFF, 0, 0, 0, 0, lat, lon, TAKEOFF_ALT)]
    for n, e in ((50, -100), (250, -100), (250, 100), (50, 100)):
        items.append((REL, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *offset(lat, lon, n, e), TAKEOFF_ALT))
    items.append((REL, MAV.MAV_CMD_NAV_VTOL_LAND, 0, 0, 0, 0, *offset(lat, lon, land_north, land_east), 0))
    return items


def mission_errors(v: Vehicle, tr: Trace) -> None:
    begin(v, tr)
    lat, lon, alt = where(v)
    home = (MAV.MAV_FRAME_GLOBAL, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, lat, lon, alt / 1000.0)
    wp = (REL, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *offset(lat, lon, 30, 0), 10.0)
    r = upload(v, [home, wp])
    tr.proto("good.requests", r["requests"])
    tr.proto("good.ack", r["ack"])
    tr.proto("good.count", mission_count(v))
    bad = {
        "unknown_command": (REL, 31999, 0, 0, 0, 0, *offset(lat, lon, 30, 0), 10.0),
        "bad_frame": (99, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *offset(lat, lon, 30, 0), 10.0),
        "latitude_out_of_range": (REL, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, 950000000, lon, 10.0),
    }
    for name, item in bad.items():
        mark = len(v.statustexts)
        r = upload(v, [home, wp, item])
        tr.proto(f"{name}.ack", r["ack"])
        tr.proto(f"{name}.count_after", mission_count(v))
        tr.info(f"{name}.texts", v.texts_since(mark))
    # A download past the end.
    v.drain()
    v.m.mav.mission_request_int_send(1, 1, 5, 0)
    reply = v.recv(["MISSION_ACK", "MISSION_ITEM_INT"], timeout=10)
    tr.proto("request_past_end", [reply.get_type(), _ack_name(reply.type) if reply.get_type() == "MISSION_ACK" else None])
    # An item sent without being asked for (no upload going on).
    v.drain()
    v.m.mav.mission_item_int_send(1, 1, 1, *wp[:2], 0, 1, *wp[2:], 0)
    try:
        reply = v.recv("MISSION_ACK", timeout=3)
        tr.proto("unsolicited_item", _ack_name(reply.type))
    except Timeout:
        tr.proto("unsolicited_item", None)
    v.drain()
    v.m.mav.mission_clear_all_send(1, 1, 0)
    tr.proto("clear_all.ack", _ack_name(v.recv("MISSION_ACK", timeout=10).type))
    tr.proto("clear_all.count", mission_count(v))
    r = upload(v, [])
    tr.proto("empty_upload.ack", r["ack"])


def box_short_land(v: Vehicle, tr: Trace) -> None:
    begin(v, tr)
    # The check's landing airspeed, set alike on both (ArduPlane SITL's AIRSPEED_CRUISE is 22 m/s,
    # the twin's cruise 12): 0.75 · 22² / (2 · Q_TRANS_DECEL 6) is a minimum of 30 m.
    _param(tr, "write.TECS_LAND_ARSPD=22", v.param_write("TECS_LAND_ARSPD", 22))
    lat, lon, alt = where(v)
    # The reasons from the upload on: ArduPlane announces a check that starts failing at its next
    # 1 Hz arming update, which may come after the arm attempt; the twin at once.
    mark = len(v.statustexts)
    r = upload(v, box_items(lat, lon, alt, 50, 70))  # 30 m from the last corner (50 N, 100 E)
    tr.proto("upload.ack", r["ack"])
    tr.proto("mode_auto", v.mode("AUTO"))
    tr.proto("arm", v.arm())
    v.wait_vehicle_time(2.0)
    reasons(v, mark, tr, "arm")
    if v.armed():
        v.disarm()


def reboot(v: Vehicle, tr: Trace) -> None:
    begin(v, tr)
    v.mode("QSTABILIZE")
    v.arm()
    tr.proto("armed.reboot", v.cmd(MAV.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1))
    v.disarm()
    v.until(lambda: not v.armed(), timeout=10, what="disarmed")
    pv = v.param_write("WP_RADIUS", 25)
    tr.proto("param_written", pv is not None)
    tr.proto("shutdown", v.cmd(MAV.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 2))
    before = v.t_ms
    tr.proto("reboot", v.cmd(MAV.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1))
    tr.proto("after.clock_restarted",
             v.until(lambda: 0 < v.t_ms < before, timeout=90, vehicle_s=10, ok_on_time=True))
    hb = v.heartbeat(timeout=30)
    tr.proto("after.heartbeat_mode", MODE_NAMES.get(hb.custom_mode, hb.custom_mode))
    tr.proto("after.armed", bool(hb.base_mode & 128))
    pv = v.param_read("WP_RADIUS", timeout=10)
    tr.phys("after.WP_RADIUS", pv.param_value if pv else None)
    v.setup_streams()
    v.wait_armable()
    tr.proto("after.arm", v.arm())
    if v.armed():
        v.disarm()


# -- flights --------------------------------------------------------------------------------------


def take_off(v: Vehicle, tr: Trace) -> bool:
    """GUIDED, arm, VTOL take-off to 20 m (MAV_CMD_NAV_VTOL_TAKEOFF, else MAV_CMD_NAV_TAKEOFF);
    the climb and a 10 s hover as phases. False if the vehicle did not take off."""
    begin(v, tr)
    tr.proto("takeoff.mode_guided", v.mode("GUIDED"))
    tr.proto("takeoff.arm", v.arm())
    vt = v.cmd(MAV.MAV_CMD_NAV_VTOL_TAKEOFF, 0, 0, 0, 0, 0, 0, TAKEOFF_ALT)
    tr.proto("takeoff.nav_vtol_takeoff", vt)
    if vt != "ACCEPTED":
        tr.proto("takeoff.nav_takeoff", v.cmd(MAV.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, TAKEOFF_ALT))
    with v.window() as w:
        up = v.until(lambda: v.rel_alt() >= TAKEOFF_ALT - 1.0, timeout=120, vehicle_s=90, ok_on_time=True)
    tr.proto("takeoff.reached", up)
    tr.phys("takeoff.climb", phase_summary(w))
    if not up:
        return False
    with v.window() as w:
        v.wait_vehicle_time(10.0)
    tr.phys("takeoff.hover", phase_summary(w))
    return True


def land_here(v: Vehicle, tr: Trace, key: str = "land") -> None:
    tr.proto(f"{key}.mode_qland", v.mode("QLAND"))
    with v.window() as w:
        down = v.until(lambda: not v.armed(), timeout=240, vehicle_s=240, ok_on_time=True)
    tr.proto(f"{key}.disarmed", down)
    tr.phys(f"{key}.descent", phase_summary(w))


def guided_takeoff(v: Vehicle, tr: Trace) -> None:
    if take_off(v, tr):
        land_here(v, tr)


def do_vtol_transition(v: Vehicle, tr: Trace) -> None:
    begin(v, tr)
    mark = len(v.statustexts)
    tr.proto("ground.to_fw", v.cmd(MAV.MAV_CMD_DO_VTOL_TRANSITION, MAV.MAV_VTOL_STATE_FW))
    tr.info("ground.texts", v.texts_since(mark))
    if not take_off(v, tr):
        return
    mark = len(v.statustexts)
    tr.proto("hover.to_fw", v.cmd(MAV.MAV_CMD_DO_VTOL_TRANSITION, MAV.MAV_VTOL_STATE_FW))
    with v.window() as w:
        v.wait_vehicle_time(20.0)
    tr.phys("after_to_fw", phase_summary(w))
    tr.proto("hover.to_mc", v.cmd(MAV.MAV_CMD_DO_VTOL_TRANSITION, MAV.MAV_VTOL_STATE_MC))
    tr.info("hover.texts", v.texts_since(mark))
    with v.window() as w:
        v.wait_vehicle_time(10.0)
    tr.phys("after_to_mc", phase_summary(w))
    land_here(v, tr)


def _return(v: Vehicle, tr: Trace, mode: str) -> None:
    if not take_off(v, tr):
        return
    lat, lon, _ = v.home()
    tr.proto(f"{mode}.ack", v.mode(mode))
    with v.window() as w:
        v.wait_vehicle_time(60.0)
    tr.phys(f"{mode}.first_60s", phase_summary(w))
    tr.proto(f"{mode}.modes_after", [MODE_NAMES.get(m, m) for m in v.modes[v.modes.index(PLANE_MODES[mode]):]]
             if PLANE_MODES[mode] in v.modes else [])
    with v.window() as w:
        down = v.until(lambda: not v.armed(), timeout=240, vehicle_s=300, ok_on_time=True)
    tr.proto(f"{mode}.disarmed_within_360s", down)
    tr.phys(f"{mode}.rest", phase_summary(w))
    if not down:
        land_here(v, tr)
    g = v.last["GLOBAL_POSITION_INT"]
    tr.phys(f"{mode}.landed_from_home_m", round(distance_m(lat, lon, g.lat, g.lon), 1))


def qrtl(v: Vehicle, tr: Trace) -> None:
    _return(v, tr, "QRTL")


def rtl_hover(v: Vehicle, tr: Trace) -> None:
    _return(v, tr, "RTL")


def box_mission(v: Vehicle, tr: Trace) -> None:
    begin(v, tr)
    lat, lon, alt = where(v)
    items = box_items(lat, lon, alt, 0, 0)
    r = upload(v, items)
    tr.proto("upload.requests", r["requests"])
    tr.proto("upload.ack", r["ack"])
    tr.proto("mode_auto", v.mode("AUTO"))
    mark = len(v.statustexts)
    tr.proto("arm", v.arm())
    reasons(v, mark, tr, "arm")
    if not v.armed() and not v.until(v.armed, timeout=10, vehicle_s=3, ok_on_time=True):
        return
    reached: list[int] = []
    with v.window() as w:
        def done():
            m = v.last.get("MISSION_ITEM_REACHED")
            if m is not None and (not reached or reached[-1] != m.seq):
                reached.append(m.seq)
            return not v.armed()
        landed = v.until(done, timeout=400, vehicle_s=1500, ok_on_time=True)
    tr.proto("landed_and_disarmed", landed)
    tr.proto("items_reached", reached)
    # One phase per mission item: the messages while it was the current one (MISSION_CURRENT,
    # or the item after the last MISSION_ITEM_REACHED, whichever is further on).
    cur, phases = None, {}
    for t, m in w:
        if m.get_type() == "MISSION_CURRENT":
            cur = m.seq if cur is None else max(cur, m.seq)
        elif m.get_type() == "MISSION_ITEM_REACHED":
            cur = m.seq + 1 if cur is None else max(cur, m.seq + 1)
        if cur is not None:
            phases.setdefault(cur, []).append((t, m))
    for seq, msgs in sorted(phases.items()):
        if seq < len(items):
            tr.phys(f"item{seq}", phase_summary(msgs))
    g = v.last["GLOBAL_POSITION_INT"]
    tr.phys("landed_from_land_point_m", round(distance_m(lat, lon, g.lat, g.lon), 1))


def _states_since(v: Vehicle, mark: int) -> list[str]:
    """The VTOL states EXTENDED_SYS_STATE reported since `mark` (an index into `ext_states`),
    by name, repeats merged."""
    names = []
    for vtol, _landed in v.ext_states[mark:]:
        e = MAV.enums["MAV_VTOL_STATE"].get(vtol)
        name = e.name[len("MAV_VTOL_STATE_"):] if e else str(vtol)
        if not names or names[-1] != name:
            names.append(name)
    return names


def _to_wing(v: Vehicle, tr: Trace, key: str, mode: str = "FBWA") -> bool:
    """From a hover to the wing in `mode`, with a pilot's throttle held at cruise; True once the
    vehicle reports FW (or 20 s of its time have passed)."""
    mark = len(v.ext_states)
    tr.proto(f"{key}.mode_{mode}", v.mode(mode))
    fw = v.until(lambda: any(s[0] == MAV.MAV_VTOL_STATE_FW for s in v.ext_states[mark:]),
                 timeout=60, vehicle_s=20, ok_on_time=True)
    tr.proto(f"{key}.vtol_states", _states_since(v, mark))
    return fw


def air_arm_modes(v: Vehicle, tr: Trace) -> None:
    """In the air: arm again, disarm (refused in flight), then the Q modes and CRUISE with a
    pilot's throttle held at mid stick, with the vehicle's VTOL state after each change; back to
    QHOVER, QLAND to end."""
    if not take_off(v, tr):
        return
    mark = len(v.statustexts)
    tr.proto("air.arm_again", v.arm())
    tr.proto("air.disarm", v.disarm())
    v.wait_vehicle_time(1.0)
    tr.proto("air.still_armed", v.armed())
    tr.proto("air.disarm.reasons", sorted({category(t) for t in v.texts_since(mark) if prefix(t) == "Disarm"}))
    v.hold_sticks(1500)
    for i, mode in enumerate(("QHOVER", "QLOITER", "QSTABILIZE", "QHOVER")):
        mark_s = len(v.ext_states)
        tr.proto(f"air.{i}.{mode}.ack", v.mode(mode))
        v.wait_vehicle_time(2.0)
        tr.proto(f"air.{i}.{mode}.heartbeat_mode", MODE_NAMES.get(v.heartbeat().custom_mode))
        tr.proto(f"air.{i}.{mode}.vtol_states", _states_since(v, mark_s))
    tr.proto("air.armed_after_q_modes", v.armed())
    if v.armed():
        _to_wing(v, tr, "air.wing", "CRUISE")
        tr.proto("air.CRUISE.heartbeat_mode", MODE_NAMES.get(v.heartbeat().custom_mode))
        mark_s = len(v.ext_states)
        tr.proto("air.back.QHOVER", v.mode("QHOVER"))
        v.until(lambda: any(s[0] == MAV.MAV_VTOL_STATE_MC for s in v.ext_states[mark_s:]),
                timeout=60, vehicle_s=20, ok_on_time=True)
        tr.proto("air.back.vtol_states", _states_since(v, mark_s))
    v.hold_sticks(None)
    if v.armed():
        land_here(v, tr)


def guided_waypoint(v: Vehicle, tr: Trace) -> None:
    """GUIDED take-off, then a point 200 m north at 30 m sent as DroneKit's `simple_goto` sends
    it (MISSION_ITEM_INT with current = 2): ArduPlane (Q_GUIDED_MODE 0) flies it on the wing."""
    if not take_off(v, tr):
        return
    lat, lon, _ = v.home()
    tlat, tlon = offset(lat, lon, 200, 0)
    v.drain()
    mark = len(v.ext_states)
    v.m.mav.mission_item_int_send(1, 1, 0, REL, MAV.MAV_CMD_NAV_WAYPOINT, 2, 0, 0, 0, 0, 0, tlat, tlon, 30.0)
    try:
        ack = v.recv("MISSION_ACK", timeout=10)
        tr.proto("goto.ack", _ack_name(ack.type))
    except Timeout:
        tr.proto("goto.ack", None)
    with v.window() as w:
        v.until(lambda: any(s[0] == MAV.MAV_VTOL_STATE_FW for s in v.ext_states[mark:]),
                timeout=60, vehicle_s=30, ok_on_time=True)
    tr.proto("goto.vtol_states", _states_since(v, mark))
    tr.phys("goto.first_30s", phase_summary(w))
    tr.proto("goto.heartbeat_mode", MODE_NAMES.get(v.heartbeat().custom_mode))
    if v.armed():
        land_here(v, tr)


def rtl_wing(v: Vehicle, tr: Trace) -> None:
    """GUIDED take-off, to the wing in CRUISE, then RTL: the modes and VTOL states it goes
    through (Q_RTL_MODE 0: home on the wing)."""
    if not take_off(v, tr):
        return
    _to_wing(v, tr, "wing", "CRUISE")
    # The first seconds on the wing in still air: the attitude and heading a ground station
    # draws (the fixed-wing frame, heading along the course).
    with v.window() as w:
        v.wait_vehicle_time(10.0)
    tr.phys("wing.first_10s", phase_summary(w))
    mark = len(v.ext_states)
    tr.proto("RTL.ack", v.mode("RTL"))
    with v.window() as w:
        v.wait_vehicle_time(30.0)
    tr.phys("RTL.first_30s", phase_summary(w))
    tr.proto("RTL.vtol_states", _states_since(v, mark))
    tr.proto("RTL.heartbeat_mode", MODE_NAMES.get(v.heartbeat().custom_mode))
    if v.armed():
        land_here(v, tr)


def _mission_run(v: Vehicle, tr: Trace, items: list[tuple], key: str, vehicle_s: float) -> None:
    r = upload(v, items)
    tr.proto(f"{key}.upload", r["ack"])
    tr.proto(f"{key}.mode_auto", v.mode("AUTO"))
    mark = len(v.statustexts)
    tr.proto(f"{key}.arm", v.arm())
    reasons(v, mark, tr, f"{key}.arm")


def auto_vtol_transition(v: Vehicle, tr: Trace) -> None:
    """DO_VTOL_TRANSITION as a command in AUTO: a mission of a VTOL take-off and a far
    waypoint; once on the wing, to MC and back to FW, each answered and followed."""
    begin(v, tr)
    lat, lon, alt = where(v)
    items = [(MAV.MAV_FRAME_GLOBAL, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, lat, lon, alt / 1000.0),
             (REL, MAV.MAV_CMD_NAV_VTOL_TAKEOFF, 0, 0, 0, 0, lat, lon, TAKEOFF_ALT),
             (REL, MAV.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *offset(lat, lon, 600, 0), TAKEOFF_ALT),
             (REL, MAV.MAV_CMD_NAV_VTOL_LAND, 0, 0, 0, 0, lat, lon, 0)]
    _mission_run(v, tr, items, "mission", 0)
    if not v.until(v.armed, timeout=10, vehicle_s=3, ok_on_time=True):
        return
    mark = len(v.ext_states)
    fw = v.until(lambda: any(s[0] == MAV.MAV_VTOL_STATE_FW for s in v.ext_states[mark:]),
                 timeout=120, vehicle_s=90, ok_on_time=True)
    tr.proto("takeoff.vtol_states", _states_since(v, mark))
    if not fw:
        return
    for state, key in ((MAV.MAV_VTOL_STATE_MC, "to_mc"), (MAV.MAV_VTOL_STATE_FW, "to_fw")):
        mark = len(v.ext_states)
        smark = len(v.statustexts)
        tr.proto(f"{key}.ack", v.cmd(MAV.MAV_CMD_DO_VTOL_TRANSITION, state))
        v.until(lambda: any(s[0] == state for s in v.ext_states[mark:]), timeout=60, vehicle_s=15, ok_on_time=True)
        v.wait_vehicle_time(3.0)
        tr.proto(f"{key}.vtol_states", _states_since(v, mark))
        tr.proto(f"{key}.heartbeat_mode", MODE_NAMES.get(v.heartbeat().custom_mode))
        tr.info(f"{key}.texts", v.texts_since(smark))
    if v.armed():
        land_here(v, tr)


def box_transition_mission(v: Vehicle, tr: Trace) -> None:
    """The box mission with DO_VTOL_TRANSITION items: to FW after the take-off, to MC before
    the VTOL_LAND; the items reached and the VTOL states flown, until disarmed."""
    begin(v, tr)
    lat, lon, alt = where(v)
    box = box_items(lat, lon, alt, 0, 0)
    to = lambda state: (REL, MAV.MAV_CMD_DO_VTOL_TRANSITION, state, 0, 0, 0, 0, 0, 0)  # noqa: E731
    items = box[:2] + [to(MAV.MAV_VTOL_STATE_FW)] + box[2:-1] + [to(MAV.MAV_VTOL_STATE_MC)] + box[-1:]
    _mission_run(v, tr, items, "mission", 0)
    if not v.armed() and not v.until(v.armed, timeout=10, vehicle_s=3, ok_on_time=True):
        return
    mark = len(v.ext_states)
    reached: list[int] = []

    def done():
        m = v.last.get("MISSION_ITEM_REACHED")
        if m is not None and (not reached or reached[-1] != m.seq):
            reached.append(m.seq)
        return not v.armed()
    landed = v.until(done, timeout=400, vehicle_s=900, ok_on_time=True)
    tr.proto("landed_and_disarmed", landed)
    tr.proto("items_reached", reached)
    tr.proto("vtol_states", _states_since(v, mark))
    if v.armed():
        land_here(v, tr)


# name -> (function, is a flight)
SCENARIOS = {
    "identify": (identify, False),
    "params": (params, False),
    "prearm": (prearm, False),
    "arm_disarm": (arm_disarm, False),
    "modes_ground": (modes_ground, False),
    "mission_errors": (mission_errors, False),
    "box_short_land": (box_short_land, False),
    "reboot": (reboot, False),
    "guided_takeoff": (guided_takeoff, True),
    "do_vtol_transition": (do_vtol_transition, True),
    "qrtl": (qrtl, True),
    "rtl_hover": (rtl_hover, True),
    "box_mission": (box_mission, True),
    "air_arm_modes": (air_arm_modes, True),
    "guided_waypoint": (guided_waypoint, True),
    "rtl_wing": (rtl_wing, True),
    "auto_vtol_transition": (auto_vtol_transition, True),
    "box_transition_mission": (box_transition_mission, True),
}


def run(name: str, url: str) -> dict:
    """Runs scenario `name` against the vehicle at `url`; its trace as a dict."""
    fn, _ = SCENARIOS[name]
    tr = Trace(name)
    v = Vehicle(url)
    try:
        fn(v, tr)
    except (AssertionError, OSError, AttributeError, KeyError, TypeError, ValueError) as e:
        # Kept in the trace: the comparison reports it, the recording keeps what came before.
        tr.data["error"] = f"{type(e).__name__}: {e}"
    finally:
        tr.proto("mode_sequence", [MODE_NAMES.get(m, m) for m in v.modes])
        # From the mode the vehicle was in when the scenario first set one: the boot modes
        # (ArduPlane's INITIALISING and INITIAL_MODE) left out.
        if v.first_commanded is not None:
            tr.proto("mode_sequence_commanded", [MODE_NAMES.get(m, m) for m in v.modes[v.first_commanded:]])
        tr.proto("extended_sys_state", [list(s) for s in v.ext_states])
        tr.info("statustext", [f"{s['t_ms'] / 1000:.1f} s [{s['severity']}] {s['text']}" for s in v.statustexts])
        try:
            v.hold_sticks(None)
        except OSError:
            pass
        v.close()
    return tr.data
