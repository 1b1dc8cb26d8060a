"""A network test bed of network namespaces: the twin, the link, the daemon and the clients each
in a namespace of its own, joined by veth pairs, with nftables for loss, duplication and
partitions, `tc` tbf for rate limits and a user-space stage (delay.py) for delay and jitter.

    vehicle ns            link ns                      ground ns             client ns
    twin  10.99.1.1 ─ v ═ mv 10.99.1.2                 g 10.99.2.2 ═ gc 10.99.3.1 ─ c 10.99.3.2
                          delay.py relay
                          mg 10.99.2.1 ═══════════════ g (the daemon's vehicle link: udpout to the relay)

Every address is one of the bed's own, inside namespaces it creates and deletes; the namespaces
have no route to anything else. Needs root, iproute2 and nftables (tests/run.sh installs them).
The link's impairments act in the link namespace on what enters it, so each direction is
impaired once: `loss(30)` drops 30 % of the datagrams each way. docs/network.md describes it.
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

HERE = Path(__file__).resolve().parent
DELAY = HERE / "delay.py"

CLONE_NEWNET = 0x40000000
_libc = ctypes.CDLL(None, use_errno=True)
_counter = itertools.count()

VEHICLE_ADDR = "10.99.1.1"
LINK_VEHICLE_SIDE = "10.99.1.2"
LINK_GROUND_SIDE = "10.99.2.1"
GROUND_ADDR = "10.99.2.2"
GROUND_CLIENT_SIDE = "10.99.3.1"
CLIENT_ADDR = "10.99.3.2"

# nft set-up of the link namespace: counters of what enters from each side, then the rules the
# scenarios switch (each chain flushed and refilled by the methods below).
LINK_RULESET = """
table ip bed {
    counter from_vehicle {}
    counter from_ground {}
    counter dropped_from_vehicle {}
    counter dropped_from_ground {}
    counter duplicated_to_ground {}
    counter dropped_routed {}
    chain input {
        type filter hook input priority 0; policy accept;
        iifname "mv" meta l4proto udp counter name from_vehicle
        iifname "mg" meta l4proto udp counter name from_ground
        jump impair
    }
    chain impair {
    }
    chain output {
        type filter hook output priority 0; policy accept;
        jump duplicate
    }
    chain duplicate {
    }
    chain forward {
        type filter hook forward priority 0; policy accept;
        jump impair_routed
    }
    chain impair_routed {
    }
}
"""

# The ground namespace counts what reaches the daemon's vehicle link (after the delay stage).
GROUND_RULESET = """
table ip bed {
    counter to_daemon {}
    chain input {
        type filter hook input priority 0; policy accept;
        iifname "g" meta l4proto udp counter name to_daemon
    }
}
"""


def why_unsupported() -> str | None:
    """Why the bed cannot run here, or None."""
    if os.geteuid() != 0:
        return "the network test bed needs root (network namespaces, nftables)"
    for tool in ("ip", "nft", "tc"):
        if shutil.which(tool) is None:
            return f"{tool} missing (tests/run.sh installs iproute2 and nftables)"
    probe = f"nbprobe{os.getpid()}"
    try:
        run(["ip", "netns", "add", probe])
        run(["ip", "netns", "exec", probe, "nft", "add", "table", "inet", "probe"])
        run(["ip", "netns", "exec", probe, "nft", "add", "chain", "inet", "probe", "c",
             "{ type filter hook input priority 0; }"])
        run(["ip", "netns", "exec", probe, "nft", "add", "rule", "inet", "probe", "c",
             "meta", "l4proto", "udp", "numgen", "random", "mod", "100", "<", "30", "drop"])
    except subprocess.CalledProcessError as e:
        return f"the kernel lacks network namespaces or nftables numgen: {e.stderr.strip()}"
    finally:
        subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def run(args: list[str], ns: str | None = None, stdin: str | None = None) -> str:
    if ns is not None:
        args = ["ip", "netns", "exec", ns, *args]
    r = subprocess.run(args, input=stdin, capture_output=True, text=True, check=False)
    if r.returncode != 0:
        raise subprocess.CalledProcessError(r.returncode, args, r.stdout, r.stderr)
    return r.stdout


class Bed:
    """Four namespaces and the links between them; `close()` deletes them (and with them every
    interface, rule and qdisc)."""

    def __init__(self) -> None:
        tag = f"nb{os.getpid() % 100000}x{next(_counter)}"
        self.vehicle, self.link, self.ground, self.client = (f"{tag}{s}" for s in "vlgc")
        self.namespaces = [self.vehicle, self.link, self.ground, self.client]
        self.relay: subprocess.Popen | None = None
        self.relay_addr: str | None = None
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    def _build(self) -> None:
        for ns in self.namespaces:
            run(["ip", "netns", "add", ns])
            run(["ip", "link", "set", "lo", "up"], ns)
        pairs = [
            (self.vehicle, "v", VEHICLE_ADDR, self.link, "mv", LINK_VEHICLE_SIDE),
            (self.link, "mg", LINK_GROUND_SIDE, self.ground, "g", GROUND_ADDR),
            (self.ground, "gc", GROUND_CLIENT_SIDE, self.client, "c", CLIENT_ADDR),
        ]
        for ns_a, a, addr_a, ns_b, b, addr_b in pairs:
            run(["ip", "link", "add", a, "netns", ns_a, "type", "veth", "peer", "name", b, "netns", ns_b])
            for ns, dev, addr in ((ns_a, a, addr_a), (ns_b, b, addr_b)):
                run(["ip", "addr", "add", f"{addr}/24", "dev", dev], ns)
                run(["ip", "link", "set", dev, "up"], ns)
        run(["nft", "-f", "-"], self.link, stdin=LINK_RULESET)
        run(["nft", "-f", "-"], self.ground, stdin=GROUND_RULESET)

    def close(self) -> None:
        self.stop_relay()
        for ns in self.namespaces:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)

    def __enter__(self) -> "Bed":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- processes and sockets in a namespace ---------------------------------------------------

    @staticmethod
    def exec_prefix(ns: str) -> list[str]:
        """Arguments that run a command in `ns` (ip execs the command: the pid is the command's)."""
        return ["ip", "netns", "exec", ns]

    @staticmethod
    @contextlib.contextmanager
    def inside(ns: str) -> Iterator[None]:
        """Sockets this thread creates within the block live in `ns` (and stay there): a
        pymavlink connection made here is a client in that namespace."""
        own = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
        target = os.open(f"/var/run/netns/{ns}", os.O_RDONLY)
        try:
            if _libc.setns(target, CLONE_NEWNET) != 0:
                raise OSError(ctypes.get_errno(), f"setns into {ns}")
            try:
                yield
            finally:
                if _libc.setns(own, CLONE_NEWNET) != 0:
                    raise OSError(ctypes.get_errno(), "setns back")
        finally:
            os.close(own)
            os.close(target)

    def start_relay(self, to: str, delay_ms: float = 0.0, jitter_ms: float = 0.0, seed: int = 1,
                    capture: Path | None = None) -> str:
        """The delay stage in the link namespace, forwarding to the twin at `to` (HOST:PORT);
        returns the address the daemon's vehicle link sends to."""
        assert self.relay is None
        self.relay = subprocess.Popen(
            [*self.exec_prefix(self.link), sys.executable, str(DELAY), "--listen", f"{LINK_GROUND_SIDE}:0",
             "--to", to, "--delay-ms", str(delay_ms), "--jitter-ms", str(jitter_ms), "--seed", str(seed),
             *(["--capture", str(capture)] if capture else [])],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
        line = self.relay.stdout.readline()
        assert line.startswith("relay "), f"the delay stage did not start: {line!r}"
        self.relay_addr = line.split()[1]
        return self.relay_addr

    def stop_relay(self) -> None:
        if self.relay is not None and self.relay.poll() is None:
            self.relay.terminate()
            self.relay.wait(timeout=10)
        self.relay = None

    # -- impairments ------------------------------------------------------------------------------

    def _impair(self, rules: list[str], chain: str = "impair") -> None:
        script = f"flush chain ip bed {chain}\n" + "".join(f"add rule ip bed {chain} {r}\n" for r in rules)
        run(["nft", "-f", "-"], self.link, stdin=script)

    def loss(self, percent: int, deterministic: bool = False, only_from_vehicle: bool = False) -> None:
        """Drops `percent` % of the UDP datagrams entering the link (each direction); random
        (`numgen random`), or exactly so many of every cycle (`numgen inc`) when `deterministic`,
        the cycle as short as the share allows (10 %: one of every 10), so that any stretch of
        traffic loses the share."""
        gen = "inc" if deterministic else "random"
        cycle, share = 100, percent
        if deterministic and percent > 0:
            g = math.gcd(percent, 100)
            cycle, share = 100 // g, percent // g
        rules = []
        sides = [("mv", "dropped_from_vehicle")] + ([] if only_from_vehicle else [("mg", "dropped_from_ground")])
        if percent > 0:
            for dev, counter in sides:
                rules.append(f'iifname "{dev}" meta l4proto udp numgen {gen} mod {cycle} < {share} '
                             f"counter name {counter} drop")
        self._impair(rules)

    def route(self) -> None:
        """Routes between the vehicle and the ground namespaces through the link namespace, for
        links that do not go through the delay stage (a Zenoh session over TCP)."""
        run(["sysctl", "-qw", "net.ipv4.ip_forward=1"], self.link)
        run(["ip", "route", "add", "10.99.2.0/24", "via", LINK_VEHICLE_SIDE], self.vehicle)
        run(["ip", "route", "add", "10.99.1.0/24", "via", LINK_GROUND_SIDE], self.ground)

    def partition_routed(self, on: bool = True, reject: bool = False) -> None:
        """Drops every packet routed across the link (on) or none (off); with `reject`, answers
        each with ICMP host-unreachable, as a router that knows its route is gone does."""
        verdict = "reject with icmp type host-unreachable" if reject else "drop"
        self._impair([f"counter name dropped_routed {verdict}"] if on else [], chain="impair_routed")

    def partition(self, on: bool = True) -> None:
        """Drops every datagram across the link (on) or none (off: no impairment at all)."""
        self._impair([f'iifname "{dev}" meta l4proto udp counter name {counter} drop'
                      for dev, counter in (("mv", "dropped_from_vehicle"), ("mg", "dropped_from_ground"))]
                     if on else [])

    def duplicate(self, every: int) -> None:
        """Sends every `every`-th datagram towards the ground twice (0: none)."""
        rules = []
        if every > 0:
            rules.append(f'oifname "mg" meta l4proto udp numgen inc mod {every} == 0 '
                         f'counter name duplicated_to_ground dup to {GROUND_ADDR} device "mg"')
        self._impair(rules, chain="duplicate")

    def rate_limit(self, bits_per_s: int, queue_bytes: int, burst_bytes: int = 1600) -> None:
        """tbf on both directions of the link: the rate and a small queue (bytes)."""
        for dev in ("mv", "mg"):
            run(["tc", "qdisc", "replace", "dev", dev, "root", "tbf", "rate", f"{bits_per_s}bit",
                 "burst", str(burst_bytes), "limit", str(queue_bytes)], self.link)

    def lift_rate_limit(self) -> None:
        """Takes the tbf off both directions of the link: the radio's limit gone."""
        for dev in ("mv", "mg"):
            run(["tc", "qdisc", "del", "dev", dev, "root"], self.link)

    def rate_limit_drops(self) -> int:
        """Packets the link's tbf queues dropped (both directions)."""
        out = "".join(run(["tc", "-s", "qdisc", "show", "dev", dev], self.link) for dev in ("mv", "mg"))
        return sum(int(m) for m in re.findall(r"dropped (\d+)", out))

    def client_tcp_loss(self, port: int, percent: int) -> None:
        """Drops `percent` % of the TCP segments to local `port` in the client namespace: one
        client's lossy link."""
        run(["nft", "-f", "-"], self.client, stdin=(
            "table ip client {\n chain input {\n  type filter hook input priority 0; policy accept;\n"
            f"  tcp dport {port} numgen random mod 100 < {percent} drop\n }}\n}}\n"))

    def counters(self) -> dict[str, int]:
        """Packets counted by the named counters of the link and ground namespaces."""
        got = {}
        for ns in (self.link, self.ground):
            out = json.loads(run(["nft", "-j", "list", "counters", "table", "ip", "bed"], ns))
            got.update({c["counter"]["name"]: c["counter"]["packets"] for c in out["nftables"] if "counter" in c})
        return got


def wait_for(cond, timeout: float, what: str, step: float = 0.05):
    """Polls `cond()` until it is truthy (returned) or `timeout` s pass (AssertionError)."""
    deadline = time.monotonic() + timeout
    while True:
        v = cond()
        if v:
            return v
        if time.monotonic() >= deadline:
            raise AssertionError(f"{what}: not within {timeout} s")
        time.sleep(step)
