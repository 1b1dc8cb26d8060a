"""The twin, the daemon and clients on the network test bed (tests/netbed/netbed.py), for the
test_netbed_* modules: the twin in the vehicle namespace (udpin), the delay stage in the link
namespace, the daemon in the ground namespace (its vehicle link a udpout to the delay stage, its
serve ports facing the client namespace), the clients in the client namespace.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import ROOT, TWIN_BIN, VEHICLE_COMPID, VEHICLE_SYSID, Gcs, Twin
from daemon_support import DAEMON_BIN, Daemon, frame_ids, raw_records, script
from procs import STDOUT_TAIL

sys.path.insert(0, str(ROOT / "tests" / "netbed"))
import netbed  # noqa: E402
from netbed import GROUND_CLIENT_SIDE, VEHICLE_ADDR, Bed  # noqa: E402

UNSUPPORTED = netbed.why_unsupported()
# Every netbed module: skipped, with the reason, only where the machine cannot make networks.
needs_bed = pytest.mark.skipif(UNSUPPORTED is not None, reason=UNSUPPORTED or "")

# The daemon's status line, per vehicle link: "vehicle L3 ok 63 Hz loss 9.8%".
STATUS_RE = re.compile(r"\| vehicle (?P<link>\S+) (?P<health>ok|LOST) (?P<hz>\d+) Hz loss (?P<loss>[\d.]+)%")


class NetDaemon(Daemon):
    """The daemon, counting every stdout line it printed (`total`), so that a wait can look only
    at the status lines printed after a moment (`mark()`)."""

    total = 0

    def _drain_stdout(self, rest: bytes) -> None:
        with self._new_lines:
            self.total = len(self.stdout_lines)
        fd = self.proc.stdout.fileno()
        while chunk := os.read(fd, 4096):
            rest += chunk
            *lines, rest = rest.split(b"\n")
            with self._new_lines:
                self.stdout_lines.extend(x.decode(errors="replace") for x in lines)
                del self.stdout_lines[:-STDOUT_TAIL]
                self.total += len(lines)
                self._new_lines.notify_all()
        with self._new_lines:
            self._new_lines.notify_all()

    def mark(self) -> int:
        with self._new_lines:
            return self.total

    def lines_since(self, mark: int) -> list[str]:
        with self._new_lines:
            return self.stdout_lines[max(0, len(self.stdout_lines) - (self.total - mark)):]


class Scene:
    """A bed with the twin, the delay stage and the daemon running."""

    def __init__(self, workdir: Path, delay_ms: float = 0.0, jitter_ms: float = 0.0, seed: int = 1,
                 twin_extra: tuple[str, ...] = (), daemon_extra: tuple[str, ...] = ()):
        self.workdir = workdir
        self.bed = Bed()
        self.twin: Twin | None = None
        self.daemon: NetDaemon | None = None
        self.clients: list[Gcs] = []
        self.capture = workdir / "to-ground.cap"
        try:
            workdir.mkdir(parents=True, exist_ok=True)
            self.twin = Twin.spawn(
                [*Bed.exec_prefix(self.bed.vehicle), str(TWIN_BIN), "serve", "--listen", f"udpin:{VEHICLE_ADDR}:0",
                 "--seed", str(seed), "--param-file", str(workdir / "params.parm"), *twin_extra],
                workdir / "twin", 1, param_file=workdir / "params.parm")
            relay = self.bed.start_relay(self.twin.addr("udpin"), delay_ms, jitter_ms, seed, self.capture)
            self.daemon = NetDaemon.spawn(
                [*Bed.exec_prefix(self.bed.ground), str(DAEMON_BIN), "run", "--vehicle", f"udpout:{relay}",
                 "--headless", "--serve", f"tcpin:{GROUND_CLIENT_SIDE}:0", "--serve", f"udpin:{GROUND_CLIENT_SIDE}:0",
                 "--log-dir", str(workdir / "logs"), *daemon_extra],
                workdir / "daemon", 2, log=True)
            self._stop = threading.Event()
            self.operator = self.client(udp=True)
            self._operator = threading.Thread(target=self._operate, daemon=True)
            self._operator.start()
        except BaseException:
            self.close(check=False)
            raise

    def _operate(self) -> None:
        """The operator's ground station on the daemon's UDP port: reads everything and beats at
        1 Hz. A udpout vehicle link carries nothing until a client speaks: its heartbeat is what
        tells the twin where the ground is."""
        while not self._stop.is_set():
            self.operator.beat()
            self.operator.m.recv_match(blocking=True, timeout=0.2)

    def client(self, udp: bool = False) -> Gcs:
        """A pymavlink script in the client namespace, on the daemon's TCP (or UDP) port."""
        with Bed.inside(self.bed.client):
            g = script(self.daemon.udp if udp else self.daemon.tcp)
        self.clients.append(g)
        return g

    def cli(self, *args: str, timeout: float = 120.0) -> tuple[float, subprocess.CompletedProcess]:
        """`vtol-gcs ARGS --link tcp:<daemon>` in the client namespace: (wall seconds, result)."""
        t0 = time.monotonic()
        r = subprocess.run([*Bed.exec_prefix(self.bed.client), str(DAEMON_BIN), *args, "--link", self.daemon.tcp],
                           capture_output=True, text=True, timeout=timeout, cwd=self.workdir)
        return time.monotonic() - t0, r

    def status(self, pattern: str, timeout: float, since: int = 0) -> re.Match:
        """The first status line printed after `since` (a `daemon.mark()`) that matches `pattern`
        (a regex), waiting with `timeout` as the upper bound."""
        return wait_status(self.daemon, pattern, timeout, since)

    def close(self, check: bool = True) -> None:
        errors = []
        if hasattr(self, "_stop"):
            self._stop.set()
            self._operator.join(timeout=5)
        for g in self.clients:
            g.close()
        for p in (self.daemon, self.twin):
            if p is None:
                continue
            try:
                if check:
                    p.assert_clean_exit()
                else:
                    p.stop()
            except AssertionError as e:
                errors.append(str(e))
        self.bed.close()
        assert not errors, "\n".join(errors)

    # -- what the ground side was given, and what the daemon logged -----------------------------

    def captured_vehicle_frames(self) -> list[bytes]:
        """Every vehicle frame the delay stage sent to the daemon (after the relay stopped)."""
        data = self.capture.read_bytes()
        out, i = [], 0
        while i + 4 <= len(data):
            n = int.from_bytes(data[i:i + 4], "little")
            out.extend(split_frames(data[i + 4:i + 4 + n]))
            i += 4 + n
        return [f for f in out if frame_ids(f)[1:3] == (VEHICLE_SYSID, VEHICLE_COMPID)]

    def logged_vehicle_frames(self) -> list[bytes]:
        """Every vehicle frame in the daemon's tlog (after the daemon stopped)."""
        records, _ = raw_records(self.daemon.tlog.read_bytes())
        return [f for _, f in records if frame_ids(f)[1:3] == (VEHICLE_SYSID, VEHICLE_COMPID)]


def wait_status(d: NetDaemon, pattern: str, timeout: float, since: int = 0) -> re.Match:
    """The first status line `d` printed after `since` (a `d.mark()`) that matches `pattern` (a
    regex), waiting on its new lines with `timeout` as the upper bound."""
    rx = re.compile(pattern)
    deadline = time.monotonic() + timeout
    with d._new_lines:
        while True:
            for line in d.stdout_lines[max(0, len(d.stdout_lines) - (d.total - since)):]:
                if m := rx.search(line):
                    return m
            left = deadline - time.monotonic()
            if left <= 0 or not d.alive():
                raise AssertionError(f"no status line matching {pattern!r} in {timeout} s\n{d.tail()}")
            d._new_lines.wait(left)


def split_frames(datagram: bytes) -> list[bytes]:
    """The MAVLink frames of one datagram (the twin sends whole frames)."""
    out, i = [], 0
    while i < len(datagram):
        magic = datagram[i]
        if magic == 0xFD:
            n = 10 + datagram[i + 1] + 2 + (13 if datagram[i + 2] & 1 else 0)
        elif magic == 0xFE:
            n = 6 + datagram[i + 1] + 2
        else:
            raise AssertionError(f"not a frame start in a datagram: {datagram[i:i + 16].hex()}")
        out.append(datagram[i:i + n])
        i += n
    return out


# --------------------------------------------------------------------------------------------
# A ground station's retries on a lossy link
# --------------------------------------------------------------------------------------------


def command(g: Gcs, cmd: int, *params: float, timeout: float = 30.0, every: float = 0.7):
    """COMMAND_LONG sent again (confirmation counting up) every `every` s until its COMMAND_ACK
    arrives, as a ground station does on a radio; the ACK, or AssertionError after `timeout`."""
    p = list(params) + [0.0] * (7 - len(params))
    deadline = time.monotonic() + timeout
    confirmation = 0
    g.drain()
    while time.monotonic() < deadline:
        g.mav.command_long_send(VEHICLE_SYSID, VEHICLE_COMPID, cmd, confirmation, *p)
        confirmation = min(confirmation + 1, 255)
        resend = time.monotonic() + every
        while (left := min(resend, deadline) - time.monotonic()) > 0:
            g.beat()
            m = g.m.recv_match(type="COMMAND_ACK", blocking=True, timeout=min(left, 0.25))
            if m is not None and m.get_srcSystem() == VEHICLE_SYSID and m.command == cmd:
                return m
    raise AssertionError(f"no COMMAND_ACK for command {cmd} in {timeout} s")


def upload_mission(g: Gcs, items, timeout: float = 120.0, every: float = 0.4) -> int:
    """The mission protocol's upload with a ground station's retries: MISSION_COUNT again until
    the first request; after `every` s of silence the next item unasked (the twin takes it if
    its request was what got lost, and asks again for the one it needs if not). Returns the
    MISSION_ACK's result."""
    deadline = time.monotonic() + timeout
    g.drain()
    answered = -1  # the last item sent in answer to a request
    last_sent = time.monotonic() - every
    while time.monotonic() < deadline:
        g.beat()
        if time.monotonic() - last_sent >= every:
            if answered < 0:
                g.mav.mission_count_send(VEHICLE_SYSID, VEHICLE_COMPID, len(items))
            else:
                g.mav.send(items[min(answered + 1, len(items) - 1)])
            last_sent = time.monotonic()
        m = g.m.recv_match(type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True,
                           timeout=0.1)
        if m is None or m.get_srcSystem() != VEHICLE_SYSID:
            continue
        if m.get_type() == "MISSION_ACK":
            return m.type
        g.mav.send(items[m.seq])
        answered = max(answered, m.seq)
        last_sent = time.monotonic()
    raise AssertionError(f"mission upload not acknowledged in {timeout} s (last answered {answered})")


def download_mission(g: Gcs, timeout: float = 120.0, every: float = 0.5) -> list:
    """Every item of the stored mission, each asked again until it arrives."""
    deadline = time.monotonic() + timeout

    def ask(send, types, pred):
        while time.monotonic() < deadline:
            send()
            resend = time.monotonic() + every
            while (left := resend - time.monotonic()) > 0:
                g.beat()
                m = g.m.recv_match(type=types, blocking=True, timeout=min(left, 0.25))
                if m is not None and m.get_srcSystem() == VEHICLE_SYSID and pred(m):
                    return m
        raise AssertionError(f"mission download incomplete after {timeout} s")

    g.drain()
    count = ask(lambda: g.mav.mission_request_list_send(VEHICLE_SYSID, VEHICLE_COMPID), "MISSION_COUNT",
                lambda m: True).count
    return [ask(lambda s=seq: g.mav.mission_request_int_send(VEHICLE_SYSID, VEHICLE_COMPID, s),
                "MISSION_ITEM_INT", lambda m, s=seq: m.seq == s) for seq in range(count)]
