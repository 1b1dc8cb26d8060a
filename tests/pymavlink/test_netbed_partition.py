"""A partition of the vehicle link on the test bed (docs/network.md): every datagram across the
link dropped for a while, then the link healed.

The daemon shows the vehicle LOST as soon as its heartbeat timeout allows (5 s of silence), a
client has the vehicle's heartbeat and telemetry back within 2 s of the heal, and every vehicle
frame the daemon was given (the delay stage's capture of what it sent to the daemon) is in the
daemon's tlog. The partition lasts NETBED_PARTITION_S seconds (8 by default, to keep the suite
short; 30 for the full scenario).
"""

from __future__ import annotations

import os
import time
from collections import Counter

from netbed_support import Scene, needs_bed

pytestmark = needs_bed

PARTITION_S = float(os.environ.get("NETBED_PARTITION_S", "8"))
# The tracker's heartbeat timeout (src/tracker/state.rs LINK_TIMEOUT).
LINK_TIMEOUT_S = 5.0
# The daemon prints its status line once a second.
STATUS_PERIOD_S = 1.0


def test_partition_shows_lost_at_once_everything_back_within_2_s_and_nothing_missing_from_the_tlog(tmp_path):
    s = Scene(tmp_path, delay_ms=10, jitter_ms=0)
    try:
        g = s.client()
        g.wait_vehicle_heartbeat(timeout=20)
        s.status(r"\| vehicle \S+ ok", timeout=10, since=s.daemon.mark())

        mark = s.daemon.mark()
        cut = time.monotonic()
        s.bed.partition(True)
        s.status(r"sys 1 LINK LOST", timeout=LINK_TIMEOUT_S + 2 * STATUS_PERIOD_S, since=mark)
        lost_after = time.monotonic() - cut
        assert lost_after <= LINK_TIMEOUT_S + 2 * STATUS_PERIOD_S, lost_after
        # Hold the partition, the client beating into it.
        while time.monotonic() - cut < PARTITION_S:
            g.beat()
            g.m.recv_match(blocking=True, timeout=0.2)

        mark = s.daemon.mark()
        g.drain()
        healed = time.monotonic()
        s.bed.partition(False)
        g.wait_vehicle_heartbeat(timeout=2.0)
        g.recv("ATTITUDE", timeout=max(0.1, 2.0 - (time.monotonic() - healed)))
        back_after = time.monotonic() - healed
        assert back_after <= 2.0, back_after
        # The status line follows within its own period.
        s.status(r"^sys 1 (?!LINK LOST)\S+ .*\| vehicle \S+ ok", timeout=2.0 + STATUS_PERIOD_S, since=mark)
        c = s.bed.counters()
        assert c["dropped_from_vehicle"] > 0 and c["dropped_from_ground"] > 0, c
        print(f"LOST shown {lost_after:.2f} s after the cut; telemetry back {back_after:.2f} s after "
              f"the heal of a {PARTITION_S:g} s partition")

        # Everything the daemon was given is in its tlog: the delay stage stops first (its capture
        # complete), then the daemon (its tlog flushed).
        s.bed.stop_relay()
        s.daemon.assert_clean_exit()
        given = Counter(s.captured_vehicle_frames())
        logged = Counter(s.logged_vehicle_frames())
        missing = given - logged
        assert sum(given.values()) > 100, sum(given.values())
        assert not missing, f"{sum(missing.values())} of {sum(given.values())} frames given to the daemon are not in its tlog"
    finally:
        s.close()
