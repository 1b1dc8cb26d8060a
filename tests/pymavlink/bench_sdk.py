#!/usr/bin/env python3
"""How fast the high-level SDKs get going against the twin, directly and through the daemon.

    cargo build --workspace --bins
    FIRMWARE_SIM_BIN=target/debug/firmware-sim VTOL_GCS_BIN=target/debug/vtol-gcs \\
        .venv/bin/python tests/pymavlink/bench_sdk.py [--runs N] [--items 100]

Each figure is measured N times, each time against a fresh twin at real-time speed (behind a fresh
daemon for the "daemon" rows), over loopback TCP:
  - DroneKit connect-to-ready: `connect(url, wait_ready=True)` until it returns (first HEARTBEAT,
    mode, GPS, attitude and every parameter). Targets: 0.3 s direct, 0.6 s through the daemon.
  - MAVSDK connect-to-is_armable: from `Mavsdk(...)` and `add_any_connection` until
    `telemetry.health().is_armable`. Target: 1.5 s.
  - MAVSDK mission_raw upload and download of `--items` items (home slot + waypoints): from the
    call to its return. Targets: 100 ms each.
  - Arm-to-armed-seen: DroneKit's `vehicle.armed = True` until its `armed` attribute (read from
    the HEARTBEAT) turns true, seen by an attribute listener (no polling).
Medians, 95th percentiles and maxima.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("MAVLINK20", "1")

from conftest import start_twin  # noqa: E402
from daemon_support import start_daemon  # noqa: E402
from dronekit import VehicleMode, connect  # noqa: E402
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

HOME = (-353632610, 1491652300)  # SIM_HOME_LAT/LON defaults, 1e-7 degree
TIMEOUT_S = 30.0


class Stack:
    """A fresh twin (and daemon) in `base`: `url(kind)` for pymavlink or MAVSDK."""

    def __init__(self, base: Path, route: str, n: int):
        self.procs = []
        twin = start_twin(base / f"twin{n}", listen=("tcpin:127.0.0.1:0",), speed=None)
        self.procs.append(twin)
        front = twin
        if route == "daemon":
            front = start_daemon(base / f"daemon{n}", vehicle="tcp:" + twin.addr("tcpin"),
                                 serve=("tcpin:127.0.0.1:0",), log=False)
            self.procs.append(front)
        self.host, self.port = front.host_port("tcpin")

    def url(self, sdk: str) -> str:
        return f"tcp:{self.host}:{self.port}" if sdk == "dronekit" else f"tcpout://{self.host}:{self.port}"

    def close(self) -> None:
        for p in reversed(self.procs):
            p.assert_clean_exit()


def dronekit_connect_and_arm(stack: Stack) -> tuple[float, float, int]:
    """(connect-to-ready s, arm-to-armed-seen s, parameters) with DroneKit."""
    t0 = time.perf_counter()
    vehicle = connect(stack.url("dronekit"), wait_ready=True, timeout=TIMEOUT_S, heartbeat_timeout=TIMEOUT_S)
    ready = time.perf_counter() - t0
    try:
        nparams = len(vehicle.parameters)
        vehicle.wait_for(lambda: vehicle.is_armable, timeout=TIMEOUT_S)
        vehicle.mode = VehicleMode("GUIDED")
        vehicle.wait_for(lambda: vehicle.mode.name == "GUIDED", timeout=TIMEOUT_S)
        armed = threading.Event()

        def on_armed(_vehicle, _name, value):
            if value:
                armed.set()

        vehicle.add_attribute_listener("armed", on_armed)
        t1 = time.perf_counter()
        vehicle.armed = True
        assert armed.wait(TIMEOUT_S), "never armed"
        arm_seen = time.perf_counter() - t1
        vehicle.remove_attribute_listener("armed", on_armed)
    finally:
        vehicle.close()
    return ready, arm_seen, nparams


def mission(n: int) -> list[MissionItem]:
    """Home slot, then n - 1 waypoints within a few metres of home at 2 m."""
    items = [MissionItem(seq=0, frame=0, command=16, current=1, autocontinue=1, x=HOME[0], y=HOME[1],
                         z=584.0, mission_type=0)]
    for seq in range(1, n):
        items.append(MissionItem(seq=seq, frame=6, command=16, current=0, autocontinue=1,
                                 x=HOME[0] + 10 * (seq % 20), y=HOME[1] + 10 * (seq // 20), z=2.0,
                                 mission_type=0))
    return items


async def mavsdk_run(stack: Stack, n_items: int) -> tuple[float, float, float]:
    """(connect-to-is_armable s, upload s, download s) with MAVSDK."""
    t0 = time.perf_counter()
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await mavsdk.add_any_connection(stack.url("mavsdk"))
        drone = await mavsdk.first_autopilot(TIMEOUT_S)
        assert drone is not None
        telemetry = TelemetryAsync(drone)
        gen = telemetry.subscribe_health()
        try:
            async def armable():
                async for h in gen:
                    if h.is_armable:
                        return

            await asyncio.wait_for(armable(), TIMEOUT_S)
        finally:
            await gen.aclose()
        connect_s = time.perf_counter() - t0
        raw = MissionRawAsync(drone)
        items = mission(n_items)
        t1 = time.perf_counter()
        await raw.upload_mission(items)
        up = time.perf_counter() - t1
        t2 = time.perf_counter()
        down = await raw.download_mission()
        dn = time.perf_counter() - t2
        assert [(i.seq, i.x, i.y) for i in down] == [(i.seq, i.x, i.y) for i in items], "download differs"
    finally:
        mavsdk.destroy()
    return connect_s, up, dn


def summary(xs: list[float]) -> str:
    xs = sorted(xs)
    p95 = xs[min(len(xs) - 1, round(0.95 * (len(xs) - 1)))]
    return f"median {statistics.median(xs) * 1e3:8.1f} ms  p95 {p95 * 1e3:8.1f} ms  max {xs[-1] * 1e3:8.1f} ms  (n={len(xs)})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=10, help="measurements of each figure (default 10)")
    ap.add_argument("--items", type=int, default=100, help="mission items, home slot included (default 100)")
    args = ap.parse_args()
    rows: dict[str, list[float]] = {}
    nparams = 0
    with tempfile.TemporaryDirectory(prefix="bench_sdk") as tmp:
        base = Path(tmp)
        n = 0
        for route in ("direct", "daemon"):
            for _ in range(args.runs):
                n += 1
                stack = Stack(base, route, n)
                try:
                    ready, arm_seen, nparams = dronekit_connect_and_arm(stack)
                finally:
                    stack.close()
                rows.setdefault(f"DroneKit connect-to-ready ({route})", []).append(ready)
                rows.setdefault(f"DroneKit arm-to-armed-seen ({route})", []).append(arm_seen)
                n += 1
                stack = Stack(base, route, n)
                try:
                    c, up, dn = asyncio.run(mavsdk_run(stack, args.items))
                finally:
                    stack.close()
                rows.setdefault(f"MAVSDK connect-to-is_armable ({route})", []).append(c)
                rows.setdefault(f"MAVSDK mission_raw upload, {args.items} items ({route})", []).append(up)
                rows.setdefault(f"MAVSDK mission_raw download, {args.items} items ({route})", []).append(dn)
    print(f"SDK benchmark: {args.runs} runs per figure, loopback TCP, twin at real time, "
          f"{nparams} parameters")
    width = max(len(k) for k in rows)
    for name, xs in rows.items():
        print(f"{name:<{width}}  {summary(xs)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
