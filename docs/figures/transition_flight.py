"""A transition and back, flown by the twin in lockstep and logged to a tlog.

    python docs/figures/transition_flight.py transition.tlog

Hover at 20 m in QLOITER, pick CRUISE (a forward transition, then level flight on the wing),
then QLOITER again (a back transition to a hover). Prints one line per phase as a ground station
sees it. `vtol-gcs log plot transition.tlog --kind transition` draws it; docs/figures/make.sh
makes the README's figure from it. The twin comes from FIRMWARE_SIM_BIN or the PATH.
"""

import json
import os
import socket
import subprocess
import sys

from pymavlink import mavutil

MAV = mavutil.mavlink
VTOL_STATES = {MAV.MAV_VTOL_STATE_MC: "MC", MAV.MAV_VTOL_STATE_TRANSITION_TO_FW: "to FW",
               MAV.MAV_VTOL_STATE_FW: "FW", MAV.MAV_VTOL_STATE_TRANSITION_TO_MC: "to MC"}


def main(tlog: str) -> None:
    twin = subprocess.Popen(
        [os.environ.get("FIRMWARE_SIM_BIN", "firmware-sim"), "serve", "--lockstep",
         "--listen", "tcpin:127.0.0.1:0", "--control", "tcpin:127.0.0.1:0", "--tlog", tlog],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        fly(twin)
    finally:
        twin.terminate()
        twin.wait()


def fly(twin: subprocess.Popen) -> None:
    urls = dict(twin.stdout.readline().split() for _ in range(2))
    host, port = urls["control"].removeprefix("tcpin:").rsplit(":", 1)
    control = socket.create_connection((host, int(port))).makefile("rw")

    def harness(request: str) -> dict:
        control.write(request + "\n")
        control.flush()
        return json.loads(control.readline())

    m = mavutil.mavlink_connection(urls["listening"].replace("tcpin:", "tcp:"), source_system=255)
    m.wait_heartbeat(timeout=5)
    for name, value in (("HOVER_ALT", 20), ("SR0_EXT_STAT", 10), ("SR0_EXTRA2", 10),
                        ("SR0_POSITION", 10), ("SR0_RC_CHAN", 10)):
        m.param_set_send(name, value)
        assert m.recv_match(type="PARAM_VALUE", condition=f"PARAM_VALUE.param_id=='{name}'",
                            blocking=True, timeout=5) is not None, name

    def command(mode: str) -> None:
        m.set_mode(mode)
        ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
        assert ack is not None and ack.result == MAV.MAV_RESULT_ACCEPTED, (mode, ack)

    def fly_for(seconds: int, label: str) -> None:
        """Flies `seconds` of sim time and prints what the ground station saw at its end."""
        harness(f"advance {seconds}")
        hud = state = None
        while (msg := m.recv_match(blocking=False)) is not None:
            if msg.get_type() == "VFR_HUD":
                hud = msg
            elif msg.get_type() == "EXTENDED_SYS_STATE":
                state = VTOL_STATES.get(msg.vtol_state, "?")
        print(f"{label:<26} vtol {state:<5} airspeed {hud.airspeed:4.1f} m/s "
              f"alt {harness('state')['altitude_m']:4.1f} m")

    command("QHOVER")
    m.arducopter_arm()
    assert m.recv_match(type="COMMAND_ACK", blocking=True, timeout=5).result == 0
    fly_for(30, "QHOVER climb to 20 m")
    command("QLOITER")
    fly_for(5, "QLOITER")
    command("CRUISE")
    fly_for(30, "CRUISE: on the wing")
    command("QLOITER")
    fly_for(30, "QLOITER: back to a hover")
    m.close()


if __name__ == "__main__":
    main(sys.argv[1])
