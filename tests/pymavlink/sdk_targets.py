"""Where the SDK tests (test_dronekit.py, test_mavsdk.py) and bench_sdk.py point their client:
the twin directly, or the daemon (`vtol-gcs run --vehicle tcp:<twin>`) in front of it, over TCP or
UDP. Both are the real binaries on port-0 endpoints (conftest.py, daemon_support.py).

A target is started by `start_target(route, transport, twins, daemons, speed)` and gives the
address each SDK's URL is built from: DroneKit (pymavlink) `tcp:H:P` / `udpout:H:P`, MAVSDK
`tcpout://H:P` / `udpout://H:P`. The twin listens with tcpin and udpin; so does the daemon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

# (route, transport) of every target, and their test ids.
TARGETS = [("direct", "tcp"), ("direct", "udp"), ("daemon", "tcp"), ("daemon", "udp")]
TARGET_IDS = [f"{r}-{t}" for r, t in TARGETS]

# Sim time per wall time for the flying tests: short tests, and still a real-time-paced twin.
FLIGHT_SPEED = 4


@dataclass
class Target:
    route: str
    transport: str
    host: str
    port: int

    @property
    def pymavlink_url(self) -> str:
        """DroneKit's connection string (pymavlink's)."""
        return f"{'tcp' if self.transport == 'tcp' else 'udpout'}:{self.host}:{self.port}"

    @property
    def mavsdk_url(self) -> str:
        """MAVSDK's connection URL."""
        return f"{'tcpout' if self.transport == 'tcp' else 'udpout'}://{self.host}:{self.port}"


def start_target(route: str, transport: str, twins, daemons, speed: float | None = FLIGHT_SPEED,
                 extra: tuple[str, ...] = ()) -> Target:
    """A fresh twin (with `twins`, a twin factory), behind a daemon (with `daemons`) when
    `route` is "daemon"; the endpoint of `transport` a client connects to."""
    twin = twins(speed=speed, extra=extra)
    front = twin
    if route == "daemon":
        front = daemons(vehicle="tcp:" + twin.addr("tcpin"), log=False)
    host, port = front.host_port("tcpin" if transport == "tcp" else "udpin")
    return Target(route, transport, host, port)


@pytest.fixture(params=TARGETS, ids=TARGET_IDS)
def target(request, twin_factory, daemon_factory):
    """Every target in turn, for a test that takes `target` (and imports `twin_factory` and
    `daemon_factory`, the fixtures it starts them with)."""
    route, transport = request.param
    return start_target(route, transport, twin_factory, daemon_factory)


# The origin's metres per degree, for offsets of a few metres (flat Earth is exact enough here).
EARTH_RADIUS_M = 6378137.0


def offset(lat: float, lon: float, north_m: float, east_m: float) -> tuple[float, float]:
    """The point `north_m`, `east_m` from (lat, lon), degrees."""
    dlat = north_m / EARTH_RADIUS_M
    dlon = east_m / (EARTH_RADIUS_M * math.cos(math.radians(lat)))
    return lat + math.degrees(dlat), lon + math.degrees(dlon)


def distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Ground distance between two nearby points, m (DroneKit's get_distance_metres)."""
    dlat = lat2 - lat1
    dlon = lon2 - lon1
    return math.sqrt(dlat * dlat + dlon * dlon) * 1.113195e5
