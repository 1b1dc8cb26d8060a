#!/usr/bin/env python3
"""A UDP face for a vehicle that listens on TCP (ArduPlane SITL's `--serial0 tcp:0`): binds
`--listen HOST:0` (UDP), prints `bridge HOST:PORT`, connects to `--to HOST:PORT` (TCP) and
forwards both ways: each datagram into the stream, and each MAVLink frame of the stream as one
datagram to the last peer heard, as a vehicle on UDP sends them (so a datagram lost on the way
is one frame lost, not pieces of several)."""

from __future__ import annotations

import argparse
import select
import socket


def frames(buf: bytearray) -> list[bytes]:
    """Whole MAVLink 1/2 frames off the front of `buf` (bytes before a start marker dropped)."""
    out = []
    while buf:
        if buf[0] not in (0xFE, 0xFD):
            del buf[0]
            continue
        if len(buf) < 3:
            break
        if buf[0] == 0xFE:
            n = buf[1] + 8
        else:
            n = buf[1] + 12 + (13 if buf[2] & 0x01 else 0)
        if len(buf) < n:
            break
        out.append(bytes(buf[:n]))
        del buf[:n]
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--listen", required=True)
    ap.add_argument("--to", required=True)
    a = ap.parse_args()
    host, port = a.listen.rsplit(":", 1)
    u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    u.bind((host, int(port)))
    thost, tport = a.to.rsplit(":", 1)
    t = socket.create_connection((thost, int(tport)), timeout=30)
    t.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    t.setblocking(True)
    print(f"bridge {host}:{u.getsockname()[1]}", flush=True)
    peer = None
    buf = bytearray()
    while True:
        ready, _, _ = select.select([u, t], [], [])
        if u in ready:
            data, peer = u.recvfrom(65536)
            t.sendall(data)
        if t in ready:
            data = t.recv(65536)
            if not data:
                return
            buf += data
            for f in frames(buf):
                if peer is not None:
                    u.sendto(f, peer)


if __name__ == "__main__":
    main()
