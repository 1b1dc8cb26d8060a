"""A partition of a Zenoh peer on the test bed (docs/network.md): the twin and a daemon that
publishes it as `zenoh:bed/v1` in the vehicle namespace, the ground daemon (`--vehicle
'zenoh:bed/*'`, listening for Zenoh peers) in the ground namespace, the two Zenoh peers joined by
TCP routed through the link namespace; every packet across it silently dropped for a while (what
a radio or Wi-Fi partition looks like), then healed. Both daemons run with their own Zenoh
settings: no retry or lease options in the endpoints.

The ground daemon shows the vehicle LOST as soon as either its Zenoh session goes (the daemon's
3 s lease: the vehicle's liveliness token goes with it and its link is down) or its heartbeat
times out (5 s), a client has the vehicle's telemetry back within 2 s of the heal (and its 1 Hz heartbeat
within a second of that),
and the ground daemon's tlog holds the vehicle's frames without a gap but the partition's (Zenoh
carries them in order over TCP: a frame the ground daemon received and did not log would show as
a second gap). The partition lasts NETBED_ZENOH_PARTITION_S seconds (30 by default); with
NETBED_ZENOH_REJECT=1 it answers every packet with ICMP host-unreachable instead.
"""

from __future__ import annotations

import os
import time

from conftest import TWIN_BIN, VEHICLE_COMPID, VEHICLE_SYSID, Twin
from daemon_support import DAEMON_BIN, Daemon, frame_ids, raw_records, script
from netbed_support import NetDaemon, needs_bed, wait_status
from netbed import GROUND_ADDR, GROUND_CLIENT_SIDE, Bed

pytestmark = needs_bed

PARTITION_S = float(os.environ.get("NETBED_ZENOH_PARTITION_S", "30"))
REJECT = os.environ.get("NETBED_ZENOH_REJECT") == "1"
# The tracker's heartbeat timeout (src/tracker/state.rs LINK_TIMEOUT).
LINK_TIMEOUT_S = 5.0
# The daemon's Zenoh lease (link/src/transport/zenoh.rs LIVENESS).
LEASE_S = 3.0
STATUS_PERIOD_S = 1.0
HEARTBEAT_PERIOD_S = 1.0
ZENOH_PORT = 7447  # inside the bed's own ground namespace: always free


def listen(g, seconds: float) -> None:
    """Reads (and beats) for `seconds`: telemetry flows through the ground daemon meanwhile."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        g.beat()
        g.m.recv_match(blocking=True, timeout=0.2)


def seq_gaps(frames: list[bytes]) -> list[tuple[int, int]]:
    """(previous, next) sequence numbers wherever a frame does not follow the one before."""
    seqs = [frame_ids(f)[0] for f in frames]
    return [(a, b) for a, b in zip(seqs, seqs[1:]) if b != (a + 1) % 256]


def test_zenoh_peer_partition_shows_lost_at_once_everything_back_within_2_s_and_no_gap_in_the_tlog(tmp_path):
    bed = Bed()
    procs = []
    try:
        bed.route()
        ground = NetDaemon.spawn(
            [*Bed.exec_prefix(bed.ground), str(DAEMON_BIN), "run", "--vehicle", "zenoh:bed/*", "--headless",
             "--zenoh-listen", f"tcp/{GROUND_ADDR}:{ZENOH_PORT}", "--serve", f"tcpin:{GROUND_CLIENT_SIDE}:0",
             "--log-dir", str(tmp_path / "logs")],
            tmp_path / "ground", 1, log=True)
        procs.append(ground)
        twin = Twin.spawn(
            [*Bed.exec_prefix(bed.vehicle), str(TWIN_BIN), "serve", "--listen", "tcpin:127.0.0.1:0",
             "--param-file", str(tmp_path / "params.parm")],
            tmp_path / "twin", 1, param_file=tmp_path / "params.parm")
        procs.append(twin)
        host, port = twin.host_port("tcpin")
        aboard = Daemon.spawn(
            [*Bed.exec_prefix(bed.vehicle), str(DAEMON_BIN), "run", "--vehicle", f"tcp:{host}:{port}",
             "--headless", "--no-log", "--serve", "zenoh:bed/v1",
             "--zenoh-connect", f"tcp/{GROUND_ADDR}:{ZENOH_PORT}"],
            tmp_path / "aboard", 1, log=False)
        procs.append(aboard)
        with Bed.inside(bed.client):
            g = script(ground.tcp)
        try:
            g.wait_vehicle_heartbeat(timeout=30)
            g.recv("ATTITUDE", timeout=5)
            listen(g, 2.0)

            mark = ground.mark()
            cut = time.monotonic()
            bed.partition_routed(True, reject=REJECT)
            lost_by = min(LEASE_S, LINK_TIMEOUT_S) + 2 * STATUS_PERIOD_S
            wait_status(ground, r"sys 1 LINK LOST", lost_by, mark)
            lost_after = time.monotonic() - cut
            assert lost_after <= lost_by, lost_after
            listen(g, PARTITION_S - (time.monotonic() - cut))

            g.drain()
            healed = time.monotonic()
            bed.partition_routed(False)
            g.recv("ATTITUDE", timeout=10.0)
            back_after = time.monotonic() - healed
            # The heartbeat is 1 Hz: the next one follows the link's return by up to a second.
            g.wait_vehicle_heartbeat(timeout=max(0.1, 10.0 - (time.monotonic() - healed)))
            beat_after = time.monotonic() - healed
            print(f"LOST shown {lost_after:.2f} s after the cut; telemetry back {back_after:.2f} s "
                  f"(heartbeat {beat_after:.2f} s) after the heal of a {PARTITION_S:g} s partition; "
                  f"{bed.counters()['dropped_routed']} packets dropped")
            assert bed.counters()["dropped_routed"] > 0
            assert back_after <= 2.0, back_after
            assert beat_after <= back_after + HEARTBEAT_PERIOD_S + STATUS_PERIOD_S, (back_after, beat_after)
            listen(g, 2.0)
        finally:
            g.close()
        ground.assert_clean_exit()
        records, _ = raw_records(ground.tlog.read_bytes())
        frames = [f for _, f in records if frame_ids(f)[1:3] == (VEHICLE_SYSID, VEHICLE_COMPID)]
        assert len(frames) > 200, len(frames)
        gaps = seq_gaps(frames)
        assert len(gaps) <= 1, f"vehicle frames missing from the ground daemon's tlog: {gaps[:10]}"
    finally:
        for p in reversed(procs):
            p.stop()
        bed.close()

