"""A stalled client on a lossy link of its own (docs/network.md): a TCP client in the client
namespace that never reads, with a 4 KiB receive buffer and 30 % of its segments dropped. The
daemon's queue for it overflows (its status line counts the drops) while the vehicle link loses
nothing and another client on the same daemon gets every vehicle frame, in order, without a gap.
ATTITUDE at 250 Hz makes the traffic heavy enough to fill the stalled client's buffers quickly.
"""

from __future__ import annotations

import re
import socket
import time

from conftest import MSG_ATTITUDE, VEHICLE_COMPID, VEHICLE_SYSID
from netbed_support import STATUS_RE, Scene, needs_bed
import netbed
from netbed import Bed

pytestmark = needs_bed

STALL_S = 12.0


def test_a_stalled_client_on_a_lossy_link_delays_neither_the_vehicle_link_nor_the_other_clients(tmp_path):
    s = Scene(tmp_path, delay_ms=5)
    stalled = None
    try:
        g = s.client()
        g.wait_vehicle_heartbeat(timeout=20)
        g.set_interval(MSG_ATTITUDE, 250)
        host, port = s.daemon.host_port("tcpin")
        with Bed.inside(s.bed.client):
            stalled = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            stalled.connect((host, port))
        s.bed.client_tcp_loss(stalled.getsockname()[1], 30)
        g.drain()
        mark = s.daemon.mark()
        seqs, last_seq, gaps, start = 0, None, [], time.monotonic()
        last_at, longest_silence = start, 0.0
        while time.monotonic() - start < STALL_S:
            g.beat()
            m = g.m.recv_match(blocking=True, timeout=0.25)
            now = time.monotonic()
            if m is None or (m.get_srcSystem(), m.get_srcComponent()) != (VEHICLE_SYSID, VEHICLE_COMPID):
                continue
            longest_silence = max(longest_silence, now - last_at)
            last_at = now
            seq = m.get_seq()
            if last_seq is not None and seq != (last_seq + 1) % 256:
                gaps.append((last_seq, seq))
            last_seq = seq
            seqs += 1
        lines = s.daemon.lines_since(mark)
        figures = [m for line in lines if (m := STATUS_RE.search(line))]
        dropped = [int(m[1]) for line in lines if (m := re.search(r"\| links \d+ client\(s\), (\d+) dropped", line))]
        print(f"other client: {seqs} vehicle frames, {len(gaps)} gaps, longest silence {longest_silence:.3f} s; "
              f"vehicle link {[(f['hz'], f['loss']) for f in figures]}; dropped for the stalled client {dropped}")
        # The stall reached the daemon: its socket to the stalled client holds unsent data (or
        # its queue overflowed and the status line counts the drops).
        queued = netbed.run(["ss", "-tnH", "state", "established", "sport", f"= :{port}"], s.bed.ground)
        backlog = max((int(line.split()[1]) for line in queued.splitlines() if line.strip()), default=0)
        print(f"daemon's send queues on its TCP port: {queued.strip()!r}")
        assert backlog >= 8192 or (dropped and dropped[-1] > 0), (queued, lines[-1:])
        assert not gaps, f"the other client missed vehicle frames: {gaps[:10]}"
        assert seqs > 50 * STALL_S, seqs
        assert longest_silence < 0.5, longest_silence
        assert figures and all(float(f["loss"]) == 0.0 for f in figures), [f.group(0) for f in figures]
    finally:
        if stalled is not None:
            stalled.close()
        s.close()
