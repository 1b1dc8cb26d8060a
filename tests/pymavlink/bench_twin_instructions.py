#!/usr/bin/env python3
"""Instructions a twin binary executes for fixed lockstep workloads, counted by valgrind's
callgrind (every thread): a figure that does not move with the load of a shared machine, so two
builds can be compared where wall and CPU time cannot.

    cargo build --profile bench -p firmware-sim --bin firmware-sim
    cp target/release/firmware-sim /tmp/twin-a    # ... and another build as /tmp/twin-b
    .venv/bin/python tests/pymavlink/bench_twin_instructions.py /tmp/twin-a /tmp/twin-b

Workloads, each on `serve --lockstep --ideal-sensors` with one pymavlink client over TCP:
  - start:  start-up, a client connecting and reading the first HEARTBEAT, then SIGINT;
  - flight: 300 PARAM_REQUEST_READs, each answered before the next, then 60 x `advance 1` with
    every frame read (about 7 000 frames out);
  - reads:  the same with 1 300 reads; (reads - flight) / 1 000 is the cost of one request
    received, handled and answered.
Prints instructions (Ir) per workload and binary.
"""

from __future__ import annotations

import glob
import os
import signal
import socket
import subprocess
import sys
import tempfile

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402


def run(binary: str, reads: int, advances: int) -> int:
    out_dir = tempfile.mkdtemp(prefix="twin-callgrind-")
    p = subprocess.Popen(
        ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_dir}/cg.%p", binary, "serve",
         "--lockstep", "--control", "tcpin:127.0.0.1:0", "--listen", "tcpin:127.0.0.1:0", "--ideal-sensors"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
    )
    mav_port = int(p.stdout.readline().decode().strip().rsplit(":", 1)[1])
    ctl_port = int(p.stdout.readline().decode().strip().rsplit(":", 1)[1])
    m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{mav_port}", source_system=255, source_component=190)
    assert m.recv_match(type="HEARTBEAT", blocking=True, timeout=60) is not None, "no HEARTBEAT"
    if reads or advances:
        ctl = socket.create_connection(("127.0.0.1", ctl_port)).makefile("rwb")
        for _ in range(reads):
            m.mav.param_request_read_send(1, 1, b"ALT_KP", -1)
            while True:
                msg = m.recv_match(blocking=True, timeout=60)
                assert msg is not None, "the twin stopped answering"
                if msg.get_type() == "PARAM_VALUE":
                    break
        for _ in range(advances):
            ctl.write(b"advance 1\n")
            ctl.flush()
            assert b"t_us" in ctl.readline()
            while m.recv_match(blocking=False) is not None:
                pass
        # The last advance's frames: read until quiet.
        while m.recv_match(blocking=True, timeout=1.0) is not None:
            pass
    p.send_signal(signal.SIGINT)
    p.wait(timeout=120)
    total = 0
    for f in glob.glob(f"{out_dir}/cg.*"):
        with open(f) as fh:
            for line in fh:
                if line.startswith(("summary:", "totals:")):
                    total += int(line.split()[1])
                    break
    return total


def main() -> None:
    binaries = sys.argv[1:]
    if not binaries:
        sys.exit(__doc__)
    print(f"{'binary':<32} {'start':>12} {'flight':>12} {'reads':>12} {'Ir/request':>11}")
    for b in binaries:
        start = run(b, 0, 0)
        flight = run(b, 300, 60)
        reads = run(b, 1300, 60)
        print(f"{b:<32} {start:>12,} {flight:>12,} {reads:>12,} {(reads - flight) / 1000:>11,.0f}")


if __name__ == "__main__":
    main()
