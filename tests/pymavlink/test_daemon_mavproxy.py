"""MAVProxy 1.8.75 as a client of the daemon (embedded twin), headless (`--non-interactive`, so it
reads no console input): it downloads every parameter through the daemon (FTP is NAKed, it falls
back to the parameter protocol), arms and changes mode. The effects are checked through a second
client of the daemon, a pymavlink script.

A non-interactive MAVProxy takes commands only at start (`--cmd`), before it has heard the
vehicle; `repeat add 1 …` re-issues them every second until the vehicle is ready for them (arming
is refused before STANDBY, and `mode QHOVER` needs the vehicle's type from its heartbeat)."""

from __future__ import annotations

import re
import time

import pexpect

from conftest import FLAG_ARMED, MODES
from daemon_support import daemon_factory, script  # noqa: F401 (fixture)
from procs import mavproxy


def test_mavproxy_through_daemon(daemon_factory, tmp_path):  # noqa: F811
    daemon = daemon_factory(serve=["tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"])
    observer = script(daemon.udp)
    observer.wait_vehicle_heartbeat(timeout=15)
    first = observer.wait_vehicle_heartbeat()
    assert not first.base_mode & FLAG_ARMED and first.custom_mode != MODES["QHOVER"], first

    state = tmp_path / "state"
    with observer, mavproxy(daemon.tcp, tmp_path, interactive=False,
                            cmd="repeat add 1 arm throttle; repeat add 1 mode QHOVER") as child:
        # MAVProxy's own view, in whatever order it comes: the download, the armed vehicle, the
        # mode it learnt from the vehicle's heartbeat (not from the daemon's GCS heartbeat)
        patterns = {"params": r"Received (\d+) parameters", "armed": r"(?<!DIS)ARMED", "mode": r"Mode QHOVER"}
        seen: dict[str, str] = {}
        deadline = time.monotonic() + 90
        while len(seen) < len(patterns):
            left = deadline - time.monotonic()
            assert left > 0, f"MAVProxy printed only {sorted(seen)} of {sorted(patterns)} in 90 s"
            try:
                i = child.expect(list(patterns.values()), timeout=left)
            except (pexpect.TIMEOUT, pexpect.EOF) as e:
                raise AssertionError(f"MAVProxy printed only {sorted(seen)} of {sorted(patterns)} "
                                     f"({type(e).__name__}); see {tmp_path / 'mavproxy.out'}") from None
            key = list(patterns)[i]
            seen.setdefault(key, child.match.group(1) if key == "params" else key)
        n = int(seen["params"])
        count = observer.param_get("HOVER_ALT").param_count
        assert n == count, f"MAVProxy got {n} parameters through the daemon, the twin has {count}"
        parms = list(state.rglob("mav.parm"))
        assert parms, f"no mav.parm under {state}"
        text = parms[0].read_text()
        assert len(text.strip().splitlines()) == count, text[:500]
        assert re.search(r"^HOVER_ALT\s+1\.0+$", text, re.M), text[:500]

        observer.wait_vehicle_heartbeat(timeout=30, pred=lambda h: h.base_mode & FLAG_ARMED)
        observer.wait_vehicle_heartbeat(timeout=30, pred=lambda h: h.custom_mode == MODES["QHOVER"])
        assert child.isalive()
        assert daemon.alive(), daemon.tail()
