"""Robustness of the twin's parser: garbage, truncated frames and bad-CRC frames on raw TCP and
UDP sockets, between valid requests. The twin keeps flying and answering."""

import random
import socket
import time

import pytest
from pymavlink.dialects.v20 import all as mavlink2

from conftest import FLAG_ARMED, Gcs, take_off

# A run of bytes that are never a start-of-frame (0xFD/0xFE): whatever candidate frame the
# garbage opened (up to 280 bytes long) is complete and fails its CRC before the next valid frame.
FLUSH = b"\x00" * 300


def encoder(seq_src=255):
    return mavlink2.MAVLink(None, srcSystem=seq_src, srcComponent=190)


def request_frame(mav, name=b"HOVER_ALT") -> bytes:
    return mav.param_request_read_encode(1, 1, name, -1).pack(mav)


def heartbeat_frame(mav) -> bytes:
    return mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav)


def garbage_pieces(rng: random.Random, mav) -> list[bytes]:
    good = request_frame(mav)
    pieces = [
        bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 600))),  # noise
        good[: rng.randint(1, len(good) - 1)],  # truncated v2 frame
        good[:-2] + bytes([good[-2] ^ 0xFF, good[-1]]),  # bad CRC
        bytes([0xFD, 0xFF]) + bytes(rng.getrandbits(8) for _ in range(40)),  # claims 255 bytes
        bytes([0xFE, 0x05, 0, 255, 190, 0, 1, 2, 3, 4, 5, 0xAA, 0xBB]),  # v1 bad CRC
        bytes([0xFD, 9, 0x80, 0, 0, 255, 190, 0, 0, 0]) + bytes(11),  # unknown incompat flag
        bytes([0xFD, 1, 0, 0, 0, 255, 190, 0x39, 0x30, 0x00, 0, 0, 0]),  # unknown msg id 12345
        b"\xfd" * 50 + b"\xfe" * 50,  # start bytes only
    ]
    corrupt = bytearray(good)
    corrupt[12] ^= 0x55  # payload bit flips: CRC no longer matches
    pieces.append(bytes(corrupt))
    return pieces


class RawReader:
    """Parses what the twin sends on a raw socket with pymavlink's parser."""

    def __init__(self):
        self.mav = mavlink2.MAVLink(None)
        self.mav.robust_parsing = True

    def feed(self, data: bytes) -> list:
        return [m for m in (self.mav.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]


def wait_raw(sock_recv, reader, pred, timeout=10.0):
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        try:
            data = sock_recv()
        except (socket.timeout, BlockingIOError):
            continue
        assert data, "the twin closed the connection"
        for m in reader.feed(data):
            seen.append(m.get_type())
            if pred(m):
                return m
    raise AssertionError(f"no matching message within {timeout} s (saw {seen[-20:]})")


def is_hover_alt(m):
    return m.get_type() == "PARAM_VALUE" and m.param_id == "HOVER_ALT"


def is_vehicle_heartbeat(m):
    return m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1


@pytest.fixture(scope="module")
def flying(module_twin_factory):
    t = module_twin_factory(speed=4, seed=3)
    g = Gcs(t.tcp)
    g.wait_vehicle_heartbeat()
    alt = g.param_get("HOVER_ALT").param_value
    take_off(g, alt)
    yield t, g, alt
    g.close()


def assert_still_flying(g, alt):
    hb = g.wait_vehicle_heartbeat(timeout=10)
    assert hb.base_mode & FLAG_ARMED, hb
    p = g.recv("LOCAL_POSITION_NED")
    assert abs(-p.z - alt) < 0.1, f"altitude {-p.z:.3f}, expected {alt}"


def test_tcp_garbage(flying):
    twin, g, alt = flying
    rng = random.Random(1234)
    mav = encoder()
    with socket.create_connection(twin.host_port("tcpin"), timeout=0.5) as s:
        reader = RawReader()
        for round_ in range(5):
            for piece in garbage_pieces(rng, mav):
                s.sendall(piece + FLUSH)
                s.sendall(request_frame(mav))
                wait_raw(lambda: s.recv(65536), reader, is_hover_alt)
            # a big block of noise in one write
            s.sendall(bytes(rng.getrandbits(8) for _ in range(20000)) + FLUSH)
            s.sendall(request_frame(mav))
            wait_raw(lambda: s.recv(65536), reader, is_hover_alt)
        wait_raw(lambda: s.recv(65536), reader, is_vehicle_heartbeat)
    assert twin.alive()
    assert_still_flying(g, alt)


def test_udp_garbage(flying):
    twin, g, alt = flying
    rng = random.Random(5678)
    mav = encoder()
    host, port = twin.host_port("udpin")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(0.5)
        s.connect((host, port))
        reader = RawReader()
        s.send(heartbeat_frame(mav))
        wait_raw(lambda: s.recv(65536), reader, is_vehicle_heartbeat)
        for round_ in range(5):
            for piece in garbage_pieces(rng, mav):
                s.send(piece)
                s.send(FLUSH)
                s.send(request_frame(mav))
                wait_raw(lambda: s.recv(65536), reader, is_hover_alt)
            # garbage glued in front of a valid frame in the same datagram
            s.send(bytes(rng.getrandbits(8) for _ in range(100)) + FLUSH + request_frame(mav))
            wait_raw(lambda: s.recv(65536), reader, is_hover_alt)
            # an empty datagram and a maximum-size one
            s.send(b"")
            s.send(bytes(rng.getrandbits(8) for _ in range(65000)))
            s.send(FLUSH)
            s.send(request_frame(mav))
            wait_raw(lambda: s.recv(65536), reader, is_hover_alt)
        wait_raw(lambda: s.recv(65536), reader, is_vehicle_heartbeat)
    assert twin.alive()
    assert_still_flying(g, alt)
