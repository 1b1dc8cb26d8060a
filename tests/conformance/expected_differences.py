"""Where the twin is known to answer otherwise than ArduPlane: each entry names a difference,
the scenario ("*": any) and the observation keys it covers (a regular expression matched in
full against `protocol:KEY`, `physics:KEY` or `error`, see compare.py), what ArduPlane does and
what the twin does. docs/compatibility.md's section "Conformance with ArduPlane" mirrors this
table.

An entry is strict unless it says `strict: False`: once the twin answers as ArduPlane does, the
comparison fails until the entry is removed. Entries whose keys span whole sequences or
flight phases are not strict (they may or may not match on a given run).
"""

# The reference flights: ArduPlane SITL's plane-tailsitter model with its default parameter
# file (rebooted once after its first boot, record.py) hovers upright but drifts 4–6 m/s over
# the ground, climbs at about 2.5 m/s, faces north at boot, and on the wing flies the box at
# about 6 m/s and 17–21° of pitch a few metres above home; ArduPilot's autotest lists the model
# as "unstable in hover; unflyable in cruise" (FlyEachFrame, Tools/autotest/arduplane.py). So a
# flight phase's medians say how that model flew, not how a tailsitter flies.
_SITL_HOVER = ("ArduPlane SITL (plane-tailsitter, default parameters) drifts 4–6 m/s over the ground in "
               "its hover, climbs at 2.5 m/s, faces north at boot, and flies the wing at about 6 m/s, "
               "pitch 17–21°, a few metres up")

EXPECTED_DIFFERENCES: list[dict] = [
    # -- every scenario --------------------------------------------------------------------
    {"name": "boot-mode", "scenario": "*", "strict": False,
     "keys": r"protocol:(mode_sequence|boot_mode|heartbeat\.custom_mode|after\.heartbeat_mode)",
     "arduplane": "boots in INITIALISING (16), then MANUAL (0, INITIAL_MODE)",
     "twin": "boots in QSTABILIZE (17)"},
    {"name": "vtol-state-on-ground", "scenario": "*", "strict": False,
     "keys": r"protocol:extended_sys_state",
     "arduplane": "EXTENDED_SYS_STATE vtol_state follows the mode: FW (4) in MANUAL and the other "
                  "fixed-wing modes, MC (3) in the Q modes, also on the ground",
     "twin": "vtol_state MC (3) whatever the mode, and so ATTITUDE in the VTOL view on the ground in "
             "FBWA and CRUISE too (ArduPlane: the fixed-wing frame)"},
    # -- identify ----------------------------------------------------------------------------
    {"name": "capabilities", "scenario": "identify", "keys": r"protocol:autopilot_version\.capabilities",
     "arduplane": "adds FTP, MISSION_FENCE, MISSION_RALLY, COMPASS_CALIBRATION, TERRAIN, SET_ATTITUDE_TARGET; "
                  "no PARAM_ENCODE_C_CAST, SET_POSITION_TARGET_LOCAL_NED",
     "twin": "claims only what it serves (no FTP, fences, rally, terrain)"},
    {"name": "streams", "scenario": "identify", "keys": r"protocol:streams",
     "arduplane": "also streams AHRS, MEMINFO, POWER_STATUS, SCALED_PRESSURE, VIBRATION; "
                  "no LOCAL_POSITION_NED or NAV_CONTROLLER_OUTPUT on the ground",
     "twin": "streams LOCAL_POSITION_NED and NAV_CONTROLLER_OUTPUT, not the others"},
    {"name": "mission-count-home", "scenario": "identify", "keys": r"protocol:mission_count_fresh",
     "arduplane": "a fresh vehicle with a home counts 1 item (the home slot)",
     "twin": "counts 0 (item 0 is still readable)"},
    # -- params ------------------------------------------------------------------------------
    {"name": "param-defaults", "scenario": "params",
     "keys": r"physics:read\.(WP_RADIUS|Q_WP_SPEED|Q_RTL_MODE)\.value",
     "arduplane": "WP_RADIUS 50 m (set by plane-tailsitter.parm; ArduPlane's own default is 90 m), "
                  "Q_WP_SPEED 500 cm/s",
     "twin": "WP_RADIUS 90 m (ArduPlane's own default), Q_WP_SPEED 150 cm/s"},
    {"name": "q-a-rat-gains", "scenario": "params",
     "keys": r"(protocol|physics):(read|reread|write)\.Q_A_RAT_.*",
     "arduplane": "has the VTOL rate gains Q_A_RAT_{RLL,PIT,YAW}_{P,I,D,FF} (REAL32; P/I 0.25, D 0.0036 roll and pitch)",
     "twin": "has no Q_A_RAT_* (its attitude law is the nested saturations, gains LAT_SAT_*, LON_SAT_*)"},
    {"name": "sysid-name", "scenario": "params",
     "keys": r"(protocol|physics):read\.(SYSID_THISMAV|MAV_SYSID)\..*",
     "arduplane": "4.7 names the system id MAV_SYSID (no SYSID_THISMAV)",
     "twin": "SYSID_THISMAV (INT16), no MAV_SYSID"},
    # -- prearm ------------------------------------------------------------------------------
    {"name": "arm-at-boot", "scenario": "prearm", "keys": r"protocol:arm_at_boot(\.reasons)?",
     "arduplane": "refuses to arm until it has initialised and its EKF has a home: FAILED, with reasons "
                  "that depend on how far the boot is (\"Arm: AHRS: waiting for home\", \"Arm: System not initialised\")",
     "twin": "is ready at once (gyros calibrated before sim time 0) and arms"},
    {"name": "arm-mode-text", "scenario": "prearm", "keys": r"protocol:arm_in_(QLAND|QRTL|RTL)\.reasons",
     "arduplane": "\"Arm: QLAND mode not armable\" (QRTL, RTL alike)",
     "twin": "\"Arm: mode QLAND cannot take off\" (RTL read as QRTL)"},
    {"name": "auto-empty-mission", "scenario": "prearm",
     "keys": r"protocol:(arm_in_AUTO(\.reasons)?|disarm_in_AUTO|mode_sequence_commanded)",
     "arduplane": "AUTO with no mission completes at once and changes to RTL, where arming is refused",
     "twin": "stays in AUTO and arms"},
    # -- arm_disarm --------------------------------------------------------------------------
    {"name": "fixed-wing-modes-ground", "scenario": "arm_disarm",
     "keys": r"protocol:((MANUAL|FBWA)\..*|armed_sequence|mode_sequence_commanded)",
     "arduplane": "MANUAL and FBWA are accepted and a tailsitter arms in them",
     "twin": "MANUAL is refused (\"Mode 0 not available\"); FBWA is accepted, arming in it refused"},
    # -- modes_ground ------------------------------------------------------------------------
    {"name": "modes-ground", "scenario": "modes_ground",
     "keys": r"protocol:((QACRO|MANUAL|STABILIZE|ACRO|FBWB|CIRCLE|LOITER|RTL|AUTO|TAKEOFF|TRAINING|AUTOTUNE|THERMAL)\..*|QAUTOTUNE\.heartbeat_mode|mode_sequence_commanded)",
     "arduplane": "accepts every mode but QAUTOTUNE and THERMAL; RTL reads RTL; AUTO with no mission "
                  "goes on to RTL",
     "twin": "refuses QACRO, MANUAL, STABILIZE, ACRO, FBWB, CIRCLE, LOITER, TAKEOFF, TRAINING, AUTOTUNE; "
             "RTL reads QRTL; AUTO stays AUTO"},
    {"name": "set-mode-message-ack", "scenario": "modes_ground", "keys": r"protocol:set_mode_message\.ack",
     "arduplane": "changes mode on the SET_MODE message without a COMMAND_ACK",
     "twin": "answers SET_MODE with a COMMAND_ACK (command 11)"},
    # -- mission_errors ----------------------------------------------------------------------
    {"name": "unsolicited-item", "scenario": "mission_errors", "keys": r"protocol:unsolicited_item",
     "arduplane": "answers a mission item sent outside an upload with MISSION_ACK ERROR",
     "twin": "ignores it"},
    # -- reboot ------------------------------------------------------------------------------
    {"name": "reboot-armed-result", "scenario": "reboot", "keys": r"protocol:armed\.reboot",
     "arduplane": "FAILED while armed", "twin": "DENIED while armed"},
    {"name": "reboot-boot-modes", "scenario": "reboot", "keys": r"protocol:mode_sequence_commanded",
     "arduplane": "comes back from a reboot through INITIALISING (16) to MANUAL",
     "twin": "comes back in QSTABILIZE, with no INITIALISING"},
    {"name": "reboot-clock", "scenario": "reboot", "keys": r"protocol:after\.clock_restarted",
     "arduplane": "restarts the process: time_boot_ms starts again from 0 and the TCP link drops",
     "twin": "keeps its clock and its link over the 1.5 s of silence"},
    # -- flights -----------------------------------------------------------------------------
    {"name": "nav-vtol-takeoff-command", "scenario": "*", "strict": False,
     "keys": r"protocol:takeoff\.nav_(vtol_)?takeoff",
     "arduplane": "MAV_CMD_NAV_VTOL_TAKEOFF as a command is UNSUPPORTED; MAV_CMD_NAV_TAKEOFF in GUIDED "
                  "takes off vertically",
     "twin": "accepts MAV_CMD_NAV_VTOL_TAKEOFF in GUIDED"},
    {"name": "do-vtol-transition", "scenario": "do_vtol_transition", "keys": r"protocol:(ground|hover)\.to_(fw|mc)",
     "arduplane": "FAILED outside AUTO (\"VTOL transition only in AUTO\"), to either state",
     "twin": "DENIED to FW outside AUTO; ACCEPTED to MC (already there)"},
    {"name": "sitl-hover", "scenario": "*", "strict": False, "keys": r"physics:.*_(deg|m_s|m|s)",
     "arduplane": _SITL_HOVER, "twin": "holds its point in the hover, climbs at 1 m/s, faces south at boot, "
                                       "cruises at 11–12 m/s and about 6° of pitch"},
    {"name": "qrtl-return", "scenario": "qrtl",
     "keys": r"protocol:(QRTL\.disarmed_within_360s|land\..*|mode_sequence_commanded)",
     "arduplane": "in the recording QRTL did not land within 360 s (the SITL model drifting in its "
                  "hover, above), and QLAND finished it",
     "twin": "flies home, lands and disarms in QRTL"},
    {"name": "box-mission-flight", "scenario": "box_mission",
     "keys": r"protocol:(items_reached|landed_and_disarmed)",
     "arduplane": "after VTOL_TAKEOFF transitions to fixed wing for the NAV_WAYPOINTs and reaches them; "
                  "in the recording the SITL model had not landed and disarmed when the scenario ended",
     "twin": "flies the box on the wing, lands at home and disarms"},
    {"name": "box-transition-flight", "scenario": "box_transition_mission", "strict": False,
     "keys": r"protocol:(items_reached|landed_and_disarmed|vtol_states|land\..*|mode_sequence_commanded)",
     "arduplane": "the DO_VTOL_TRANSITION item after the take-off starts the forward transition (reached "
                  "as item 2); in the recording the SITL model then hit the ground again and again on the "
                  "wing (\"SIM Hit ground\"), reached item 3 only, and QLAND ended the scenario",
     "twin": "flies the box on the wing, back to MC at the second DO_VTOL_TRANSITION, lands at home and "
             "disarms"},
    {"name": "disarm-in-flight-text", "scenario": "air_arm_modes", "keys": r"protocol:air\.disarm\.reasons",
     "arduplane": "refuses a disarm in flight (FAILED) without a STATUSTEXT",
     "twin": "refuses it (FAILED) and says why: \"Disarm: refusing to disarm in flight (use force)\", "
             "so an operator knows what a forced disarm would do"},
    {"name": "sitl-back-transition", "scenario": "air_arm_modes", "strict": False,
     "keys": r"protocol:air\.back\.vtol_states",
     "arduplane": "in the recording the SITL model had hit the ground in CRUISE and its back transition "
                  "ended at once (\"Transition VTOL done, roll error\"): MC with no TRANSITION_TO_MC "
                  "between (in AUTO, auto_vtol_transition, it reports TRANSITION_TO_MC)",
     "twin": "TRANSITION_TO_MC, then MC"},
]
