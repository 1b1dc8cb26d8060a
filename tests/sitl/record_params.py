#!/usr/bin/env python3
"""Records ArduPlane SITL's parameter table as data for tests/pymavlink/apm_vehicle.py.

    ARDUPILOT_SITL=/path/to/arduplane python tests/sitl/record_params.py [-o tests/pymavlink/data/arduplane_params.json]

Starts SITL (tests/sitl/sitl.py: QuadPlane tailsitter, its own temporary directory, instance 1
unless SITL_INSTANCE says otherwise), then with pymavlink straight on its TCP port:
- PARAM_REQUEST_LIST, every PARAM_VALUE with its arrival time (the stream's pacing);
- which parameters refuse a write ("Param write denied"), among the internal ones (device ids,
  MIS_TOTAL, ground pressures...), by writing each its own value;
- for the enable parameters that add parameters when set (Q_TILT_ENABLE, SOAR_ENABLE), the
  table with it set to 1 (it is set back to 0 afterwards): where the new parameters come in.
Only what SITL answered is written: names, types, values, counts and times.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from pymavlink import mavutil  # noqa: E402

from sitl import Sitl  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = ROOT / "tests" / "pymavlink" / "data" / "arduplane_params.json"
INTERNAL = re.compile(r"(DEVID|_DEV_ID|_ID\d?$|GND_PRESS|^MIS_TOTAL$|^FORMAT_VERSION$|^STAT_)")
ENABLES = ["Q_TILT_ENABLE", "SOAR_ENABLE"]


BANNER: list[str] = []


def fetch(m, timeout: float = 30.0) -> tuple[list, list]:
    """Every index of one PARAM_REQUEST_LIST: rows [name, type, value] in index order, and the
    arrival times (s after the request) in arrival order. The banner it sends first is kept in
    BANNER."""
    while m.recv_match(blocking=False):
        pass
    m.mav.param_request_list_send(m.target_system, m.target_component)
    t0 = time.monotonic()
    seen: dict[int, list] = {}
    times: list[float] = []
    count = None
    while count is None or len(seen) < count:
        msg = m.recv_match(type=["PARAM_VALUE", "STATUSTEXT"], blocking=True,
                           timeout=max(0.1, t0 + timeout - time.monotonic()))
        assert time.monotonic() - t0 < timeout, f"{len(seen)} of {count} in {timeout} s"
        if msg is not None and msg.get_type() == "STATUSTEXT":
            if not BANNER or len(BANNER) < 8 and msg.text not in BANNER:
                BANNER.append(msg.text)
            continue
        if msg is None or msg.param_index == 65535:
            continue
        count = msg.param_count
        times.append(round(time.monotonic() - t0, 6))
        seen.setdefault(msg.param_index, [msg.param_id, msg.param_type, msg.param_value])
    return [seen[i] for i in range(count)], times


def set_and_wait(m, name: str, value: float, ptype: int, timeout: float = 3.0) -> tuple[float | None, str | None]:
    """PARAM_SET; the echo's value and any "denied" text about `name`."""
    m.mav.param_set_send(m.target_system, m.target_component, name.encode(), value, ptype)
    deadline = time.monotonic() + timeout
    echo, text = None, None
    while time.monotonic() < deadline and (echo is None or (text is None and time.monotonic() < deadline - timeout + 0.3)):
        msg = m.recv_match(type=["PARAM_VALUE", "STATUSTEXT"], blocking=True, timeout=0.05)
        if msg is None:
            continue
        if msg.get_type() == "PARAM_VALUE" and msg.param_id == name:
            echo = msg.param_value
        elif msg.get_type() == "STATUSTEXT" and name in msg.text and "denied" in msg.text:
            text = msg.text
    return echo, text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", type=Path, default=DEFAULT_OUT)
    a = ap.parse_args()
    with Sitl() as sitl:
        m = mavutil.mavlink_connection(sitl.url, source_system=255, source_component=190)
        m.wait_heartbeat(timeout=60)
        m.target_component = 1
        m.mav.command_long_send(m.target_system, 1, mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)
        v = m.recv_match(type="AUTOPILOT_VERSION", blocking=True, timeout=5)
        caps = int(v.capabilities) if v else 0
        rows, times = fetch(m)
        runs = [fetch(m)[1][-1] for _ in range(3)]
        print(f"{len(rows)} parameters, full list {statistics.median(runs):.3f} s (median of {runs})")
        version = next((t for t in BANNER if t.startswith("ArduPlane")), "")
        types = {r[0]: r[1] for r in rows}
        values = {r[0]: r[2] for r in rows}
        read_only = []
        for name in sorted(n for n in types if INTERNAL.search(n)):
            echo, text = set_and_wait(m, name, values[name], types[name])
            if text:
                read_only.append(name)
        print(f"read-only: {read_only}")
        variants = {}
        for name in ENABLES:
            if name not in types or values[name] != 0:
                continue
            set_and_wait(m, name, 1, types[name])
            bigger, _ = fetch(m)
            set_and_wait(m, name, 0, types[name])
            before = [r[0] for r in rows]
            inserted = [[i, r[0], r[1], r[2]] for i, r in enumerate(bigger) if r[0] not in types]
            after_names = [r[0] for r in bigger if r[0] in types]
            assert after_names == before, f"{name}: the other parameters moved"
            variants[name] = {"count": len(bigger), "inserted": inserted}
            print(f"{name}=1: {len(rows)} -> {len(bigger)} parameters")
        again, _ = fetch(m)
        assert [r[0] for r in again] == [r[0] for r in rows], "the table did not come back"
        out = {
            "source": "ArduPlane SITL (plane-tailsitter, defaults plane-tailsitter.parm), "
                      "recorded by tests/sitl/record_params.py",
            "version": version,
            "capabilities": caps,
            "param_count": len(rows),
            "params": rows,
            "arrival_s": times,
            "read_only": read_only,
            "variants": variants,
        }
        a.output.parent.mkdir(parents=True, exist_ok=True)
        a.output.write_text(json.dumps(out, separators=(",", ":")) + "\n")
        print(f"written {a.output}")


if __name__ == "__main__":
    main()
