"""Fleets over Zenoh: three twins, each behind its own `vtol-gcs run --serve zenoh:test/vN`, and
one ground `vtol-gcs run --vehicle 'zenoh:test/*'` with a pymavlink script on its serve port.

The Zenoh sessions find each other through explicit endpoints on free ports, never through
multicast scouting: peers (the ground listens, the vehicles connect) in one test, a Zenoh router
with every daemon its client in the other."""

import socket
import time

from daemon_support import daemon_factory, script  # noqa: F401 (fixture)
from test_fleet_twins import arm_only, count_gaps, gcs_cli, heartbeats_by_sysid

IDS = {1, 2, 3}


def free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def vehicle_daemon(twin_factory, daemon_factory, n: int, zenoh: list[str],  # noqa: F811
                   twin_extra: list[str] = ()):
    """Twin n (system id n, more twin flags in `twin_extra`) and its own daemon publishing it
    as zenoh:test/vn."""
    twin = twin_factory(
        listen=["tcpin:127.0.0.1:0"], speed=1, extra=["--sysid", str(n), *twin_extra]
    )
    host, port = twin.host_port("tcpin")
    d = daemon_factory(
        vehicle=f"tcp:{host}:{port}", serve=[f"zenoh:test/v{n}"], log=False, extra=zenoh
    )
    return twin, d


def test_three_vehicles_over_zenoh_peers(twin_factory, daemon_factory):  # noqa: F811
    port = free_tcp_port()
    ground = daemon_factory(
        vehicle="zenoh:test/*",
        serve=["tcpin:127.0.0.1:0"],
        log=False,
        extra=["--zenoh-listen", f"tcp/127.0.0.1:{port}"],
    )
    joins = ["--zenoh-connect", f"tcp/127.0.0.1:{port}"]
    vehicles = {n: vehicle_daemon(twin_factory, daemon_factory, n, joins) for n in sorted(IDS)}
    g = script(ground.tcp)
    try:
        heartbeats_by_sysid(g, IDS, timeout=30)
        # Raw frames over Zenoh: every vehicle's own sequence numbers, none missing in 10 s.
        last, gaps = count_gaps(g, IDS, 10.0)
        assert set(last) == IDS and gaps == 0, (last, gaps)

        # Arm vehicle 2 through the fleet: its ACK, and only it arms.
        arm_only(g, IDS, 2)

        # Vehicle 3's daemon dies: the ground shows it LOST within 5 s, the others go on.
        twin3, d3 = vehicles[3]
        daemon_factory.forget(d3)
        d3.proc.kill()
        d3.proc.wait(timeout=10)
        killed = time.monotonic()
        ground.wait_line(r"\[3 LOST\]", timeout=10)
        assert time.monotonic() - killed < 5.0
        g.drain()
        heartbeats_by_sysid(g, {1, 2}, timeout=5)

        # Its daemon again: vehicle 3 is back, nothing else restarted.
        host, port3 = twin3.host_port("tcpin")
        daemon_factory(
            vehicle=f"tcp:{host}:{port3}", serve=["zenoh:test/v3"], log=False, extra=joins
        )
        g.drain()
        heartbeats_by_sysid(g, IDS, timeout=15)
        assert ground.alive(), ground.tail()
    finally:
        g.close()


def test_parameters_through_a_zenoh_router(twin_factory, daemon_factory, tmp_path):  # noqa: F811
    """Every daemon a client of one Zenoh router (a daemon in router mode): a pull and a
    verified push reach vehicle 2 only; a ground end for vehicle 1 alone hears only it."""
    port = free_tcp_port()
    router_ep = f"tcp/127.0.0.1:{port}"
    daemon_factory(
        vehicle="zenoh:unused/*",
        serve=["udpin:127.0.0.1:0"],
        log=False,
        extra=["--zenoh-mode", "router", "--zenoh-listen", router_ep],
    )
    client = ["--zenoh-mode", "client", "--zenoh-connect", router_ep]
    ground = daemon_factory(
        vehicle="zenoh:test/*", serve=["tcpin:127.0.0.1:0"], log=False, extra=client
    )
    twins = {n: vehicle_daemon(twin_factory, daemon_factory, n, client)[0] for n in (1, 2)}
    g = script(ground.tcp)
    try:
        heartbeats_by_sysid(g, {1, 2}, timeout=30)
    finally:
        g.close()
    pulled = tmp_path / "sys2.param"
    r = gcs_cli("params", "pull", "-o", str(pulled), "--target", "2", link=ground.tcp)
    assert r.returncode == 0 and "HOVER_ALT" in pulled.read_text(), r.stdout + r.stderr
    wanted = tmp_path / "hover.parm"
    wanted.write_text("HOVER_ALT 2.75\n")
    r = gcs_cli("params", "push", str(wanted), "--target", "2", link=ground.tcp)
    assert r.returncode == 0 and "1 changed" in r.stdout, r.stdout + r.stderr
    assert "2.75" in twins[2].param_file.read_text()
    assert not twins[1].param_file.exists() or "2.75" not in twins[1].param_file.read_text()
    assert ground.alive(), ground.tail()

    # A ground end for one vehicle of the fleet hears that vehicle only.
    one = daemon_factory(
        vehicle="zenoh:test/v1", serve=["tcpin:127.0.0.1:0"], log=False, extra=client
    )
    g = script(one.tcp)
    try:
        heartbeats_by_sysid(g, {1}, timeout=30)
        last, _ = count_gaps(g, {1, 2}, 2.0)
        assert set(last) == {1}, last
    finally:
        g.close()


def test_a_fleet_url_the_end_cannot_take_is_one_clear_error(tmp_path):
    import subprocess

    from daemon_support import DAEMON_BIN

    r = subprocess.run(
        [str(DAEMON_BIN), "run", "--headless", "--no-log", "--vehicle", "tcp:127.0.0.1:9",
         "--serve", "zenoh:test/*", "--zenoh-listen", f"tcp/127.0.0.1:{free_tcp_port()}"],
        capture_output=True, text=True, timeout=30,
    )
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "names no vehicle" in lines[0], r.stderr
    r = subprocess.run(
        [str(DAEMON_BIN), "run", "--headless", "--no-log", "--vehicle", "zenoh:test/*",
         "--zenoh-connect", "udp/127.0.0.1:7447"],
        capture_output=True, text=True, timeout=30,
    )
    assert r.returncode == 2 and "tcp only" in r.stderr, r.stderr
    # Zenoh flags with no zenoh: link would do nothing: refused, not ignored.
    r = subprocess.run(
        [str(DAEMON_BIN), "run", "--headless", "--no-log", "--vehicle", "tcp:127.0.0.1:9",
         "--serve", "udpin:127.0.0.1:0", "--zenoh-listen", "tcp/127.0.0.1:7447"],
        capture_output=True, text=True, timeout=30,
    )
    lines = r.stderr.strip().splitlines()
    assert r.returncode != 0 and len(lines) == 1 and "need a zenoh: link" in lines[0], r.stderr
