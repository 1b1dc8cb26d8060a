#!/usr/bin/env python3
"""The test bed's delay stage (the kernel has no netem): a UDP relay that holds every datagram
for `delay ± jitter` milliseconds (uniform, seeded), each on its own, so that datagrams closer
together than the jitter come out reordered.

    delay.py --listen HOST:PORT --to HOST:PORT [--delay-ms D] [--jitter-ms J] [--seed N]
             [--capture FILE]

Datagrams to --listen go on to --to from one socket of the relay's; the answers go back to the
last sender on --listen. Prints `relay HOST:PORT` (the bound --listen address) when ready; runs
until SIGTERM. The delay is one way: 100 ms here is 200 ms of round trip. With --capture, every
datagram sent back towards --listen is written to FILE (4-byte little-endian length, then the
bytes): what the ground side was given.
"""

from __future__ import annotations

import argparse
import heapq
import random
import select
import signal
import socket
import sys
import time


def addr(text: str) -> tuple[str, int]:
    host, port = text.rsplit(":", 1)
    return host, int(port)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--listen", type=addr, required=True)
    ap.add_argument("--to", type=addr, required=True)
    ap.add_argument("--delay-ms", type=float, default=0.0)
    ap.add_argument("--jitter-ms", type=float, default=0.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--capture", default=None)
    a = ap.parse_args()
    if a.jitter_ms > a.delay_ms:
        ap.error("--jitter-ms must not exceed --delay-ms")
    rng = random.Random(a.seed)
    front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    front.bind(a.listen)
    back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    back.connect(a.to)
    for s in (front, back):
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.setblocking(False)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    capture = open(a.capture, "wb") if a.capture else None  # noqa: SIM115 (closed at exit)
    try:
        relay(a, rng, front, back, capture)
    finally:
        if capture is not None:
            capture.close()


def relay(a, rng, front, back, capture) -> None:
    print(f"relay {front.getsockname()[0]}:{front.getsockname()[1]}", flush=True)

    peer = None  # the last sender on the front socket
    queue: list[tuple[float, int, bool, bytes]] = []  # (due, order, to_back, data)
    order = 0
    while True:
        now = time.monotonic()
        while queue and queue[0][0] <= now:
            _, _, to_back, data = heapq.heappop(queue)
            try:
                if to_back:
                    back.send(data)
                elif peer is not None:
                    front.sendto(data, peer)
                    if capture is not None:
                        capture.write(len(data).to_bytes(4, "little") + data)
            except OSError:
                pass  # the twin not listening yet, or a full buffer: a lost datagram
        wait = max(0.0, queue[0][0] - now) if queue else 1.0
        ready, _, _ = select.select([front, back], [], [], wait)
        for s in ready:
            while True:
                try:
                    data, src = s.recvfrom(65536)
                except (BlockingIOError, ConnectionRefusedError):
                    break
                if s is front:
                    peer = src
                d = (a.delay_ms + rng.uniform(-a.jitter_ms, a.jitter_ms)) / 1000.0
                order += 1
                heapq.heappush(queue, (time.monotonic() + d, order, s is front, data))


if __name__ == "__main__":
    main()
