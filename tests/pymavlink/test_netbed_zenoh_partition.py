"""A partition of a Zenoh peer on the test bed (docs/network.md): the twin and a daemon that
publishes it as `zenoh:bed/v1` in the vehicle namespace, the ground daemon (`--vehicle
'zenoh:bed/*'`, listening for Zenoh peers) in the ground namespace, the two Zenoh peers joined by
TCP routed through the link namespace; every packet across it dropped for a while, then healed.

The ground daemon shows the vehicle LOST at its heartbeat timeout, a client has the vehicle's
heartbeat and telemetry back within 2 s of the heal, and the ground daemon's tlog holds the
vehicle's frames without a gap but the partition's (Zenoh carries them in order over TCP: a
frame the ground daemon received and did not log would show as a second gap). The partition
lasts NETBED_ZENOH_PARTITION_S seconds (12 by default; 30 for the full scenario).

Zenoh closes a session silent for its lease (10 s); the connecting peer then tries again, after
1 s doubling up to 4 s by default, each try a TCP connect that a silent partition holds in SYN
retransmissions (1 s, 3 s, 7 s) until Zenoh's open timeout (10 s). Measured with every packet
silently dropped: back 2.8 s after an 8 s partition (the session outlived it, TCP's
retransmission backoff decided), 1.8 s after 12 s and 0.8 s after 30 s (with the retries
below): when it comes back depends on where the heal falls in those cycles. Here the partition
answers every packet with ICMP host-unreachable, as a router that knows its route is gone does,
so that a connect fails at once; the vehicle's daemon asks for a retry every 0.1-0.25 s in its
connect endpoint (`#retry_period_init_ms=100;retry_period_max_ms=250`), as a deployment that
wants the link back at once would, and the partition outlasts the lease.
"""

from __future__ import annotations

import os
import time

from conftest import TWIN_BIN, VEHICLE_COMPID, VEHICLE_SYSID, Twin
from daemon_support import DAEMON_BIN, Daemon, frame_ids, raw_records, script
from netbed_support import NetDaemon, needs_bed, wait_status
from netbed import GROUND_ADDR, GROUND_CLIENT_SIDE, Bed

pytestmark = needs_bed

PARTITION_S = float(os.environ.get("NETBED_ZENOH_PARTITION_S", "12"))
# Quick reconnects, in the endpoint's own configuration.
RETRY = "#retry_period_init_ms=100;retry_period_max_ms=250"
LINK_TIMEOUT_S = 5.0
STATUS_PERIOD_S = 1.0
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
             "--zenoh-connect", f"tcp/{GROUND_ADDR}:{ZENOH_PORT}{RETRY}"],
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
            bed.partition_routed(True, reject=True)
            wait_status(ground, r"sys 1 LINK LOST", LINK_TIMEOUT_S + 2 * STATUS_PERIOD_S, mark)
            lost_after = time.monotonic() - cut
            listen(g, PARTITION_S - (time.monotonic() - cut))

            g.drain()
            healed = time.monotonic()
            bed.partition_routed(False)
            g.wait_vehicle_heartbeat(timeout=10.0)
            g.recv("ATTITUDE", timeout=5.0)
            back_after = time.monotonic() - healed
            print(f"LOST shown {lost_after:.2f} s after the cut; telemetry back {back_after:.2f} s after "
                  f"the heal of a {PARTITION_S:g} s partition; {bed.counters()['dropped_routed']} packets dropped")
            assert bed.counters()["dropped_routed"] > 0
            assert back_after <= 2.0, back_after
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

