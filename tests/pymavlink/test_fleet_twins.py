"""`firmware-sim serve --count 3`: three twins behind one endpoint, each its own vehicle.

A pymavlink script on the shared TCP listener hears three vehicles, arms one of them (only that
one arms) and writes a parameter of another (only that one's file changes)."""

import subprocess
import time

from daemon_support import daemon_factory, script  # noqa: F401 (fixture)
from conftest import (
    FLAG_ARMED,
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_RESULT_ACCEPTED,
    MAV_TYPE_GCS,
    Timeout,
    f32,
)

COUNT = 3


def heartbeats_by_sysid(g, want: set[int], pred=lambda h: True, timeout: float = 15.0) -> dict:
    """The first vehicle HEARTBEAT satisfying pred from each sysid in `want`."""
    seen: dict = {}
    deadline = time.monotonic() + timeout
    while set(seen) != want:
        left = deadline - time.monotonic()
        if left <= 0:
            raise Timeout(f"heartbeats from {sorted(seen)} only, wanted {sorted(want)}")
        hb = g.recv("HEARTBEAT", sysid=None, timeout=left, pred=lambda h: h.type != MAV_TYPE_GCS)
        s = hb.get_srcSystem()
        if s in want and s not in seen and pred(hb):
            seen[s] = hb
    return seen


def count_gaps(g, ids: set[int], seconds: float) -> tuple[dict, int]:
    """Last sequence number per vehicle in `ids` over `seconds`, and the frames missing between
    consecutive ones (each vehicle's own sequence)."""
    last: dict = {}
    gaps = 0
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        m = g.m.recv_match(blocking=True, timeout=0.25)
        if m is None or m.get_srcSystem() not in ids or m.get_type() == "BAD_DATA":
            continue
        s, seq = m.get_srcSystem(), m.get_seq()
        if s in last:
            gaps += (seq - last[s] - 1) % 256
        last[s] = seq
    return last, gaps


def arm_only(g, ids: set[int], target: int) -> None:
    """Arms `target`: its COMMAND_ACK is ACCEPTED, and afterwards only it of `ids` reports armed."""
    g.drain()
    g.mav.command_long_send(target, 1, MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    ack = g.recv("COMMAND_ACK", sysid=target, pred=lambda a: a.command == MAV_CMD_COMPONENT_ARM_DISARM)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    g.drain()
    after = heartbeats_by_sysid(g, ids)
    assert {s for s, hb in after.items() if hb.base_mode & FLAG_ARMED} == {target}, after


def test_three_twins_one_endpoint(twin_factory, gcs_factory, tmp_path):
    twin = twin_factory(speed=4, extra=["--count", str(COUNT)])
    g = gcs_factory(twin.tcp)
    ids = {1, 2, 3}
    first = heartbeats_by_sysid(g, ids)
    assert all(not hb.base_mode & FLAG_ARMED for hb in first.values())

    # Arm vehicle 2 only: its ACK comes from system 2, and only it reports armed afterwards.
    arm_only(g, ids, 2)

    # A parameter written on vehicle 3 changes vehicle 3 and its own file, nothing else.
    g.drain()
    g.mav.param_set_send(3, 1, b"HOVER_ALT", 3.25, 9)
    echo = g.recv("PARAM_VALUE", sysid=3, pred=lambda p: p.param_id == "HOVER_ALT")
    assert echo.param_value == f32(3.25)
    g.mav.param_request_read_send(1, 1, b"HOVER_ALT", -1)
    other = g.recv("PARAM_VALUE", sysid=1, pred=lambda p: p.param_id == "HOVER_ALT")
    assert other.param_value != f32(3.25)
    base = twin.param_file
    mine = base.with_name(f"{base.stem}-sys3{base.suffix}")
    assert mine.exists() and "HOVER_ALT" in mine.read_text()
    assert not base.with_name(f"{base.stem}-sys1{base.suffix}").exists()
    assert not base.exists()


def test_count_with_control_is_refused(tmp_path):
    from conftest import TWIN_BIN

    r = subprocess.run(
        [str(TWIN_BIN), "serve", "--listen", "tcpin:127.0.0.1:0", "--count", "2",
         "--control", "tcpin:127.0.0.1:0"],
        capture_output=True, text=True, timeout=20,
    )
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--count" in lines[0], r.stderr


def test_count_past_255_is_refused():
    from conftest import TWIN_BIN

    r = subprocess.run(
        [str(TWIN_BIN), "serve", "--listen", "tcpin:127.0.0.1:0", "--count", "10", "--sysid", "250"],
        capture_output=True, text=True, timeout=20,
    )
    assert r.returncode != 0
    assert r.stderr.strip().splitlines() == ["error: --count 10 from system id 250 passes 255"], r.stderr


def gcs_cli(*args: str, link: str) -> subprocess.CompletedProcess:
    from daemon_support import DAEMON_BIN

    return subprocess.run([str(DAEMON_BIN), *args, "--link", link], capture_output=True, text=True, timeout=60)


def test_three_twins_through_one_daemon(twin_factory, daemon_factory, tmp_path):  # noqa: F811
    """A fleet of three behind one `vtol-gcs run --vehicle tcp:...`: a script on the daemon's
    serve port sees the three vehicles with their own sequence numbers, arms one of them and
    gets its ACK; only that one arms. A parameter pull and a verified push reach one vehicle."""
    twin = twin_factory(listen=["tcpin:127.0.0.1:0"], speed=1, extra=["--count", str(COUNT)])
    host, port = twin.host_port("tcpin")
    daemon = daemon_factory(vehicle=f"tcp:{host}:{port}", serve=["tcpin:127.0.0.1:0"], log=False)
    g = script(daemon.tcp)
    try:
        ids = {1, 2, 3}
        heartbeats_by_sysid(g, ids, timeout=20)
        # Sequence numbers are each vehicle's own, unchanged through the daemon: no gaps.
        last, gaps = count_gaps(g, ids, 2.0)
        assert set(last) == ids and gaps == 0, (last, gaps)

        arm_only(g, ids, 3)

        # A pull and a verified push through the daemon to vehicle 2 only.
        pulled = tmp_path / "sys2.param"
        r = gcs_cli("params", "pull", "-o", str(pulled), "--target", "2", link=daemon.tcp)
        assert r.returncode == 0 and "HOVER_ALT" in pulled.read_text(), r.stdout + r.stderr
        wanted = tmp_path / "hover.parm"
        wanted.write_text("HOVER_ALT 2.75\n")
        r = gcs_cli("params", "push", str(wanted), "--target", "2", link=daemon.tcp)
        assert r.returncode == 0 and "1 changed" in r.stdout, r.stdout + r.stderr
        base = twin.param_file
        assert "2.75" in base.with_name(f"{base.stem}-sys2{base.suffix}").read_text()
        for other in (1, 3):
            assert not base.with_name(f"{base.stem}-sys{other}{base.suffix}").exists()
        assert daemon.alive(), daemon.tail()
    finally:
        g.close()


def free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_vehicles_on_their_own_links_lost_conflict_and_back(twin_factory, daemon_factory):  # noqa: F811
    """Three twins, each its own process and UDP peer of the daemon's `--vehicle udpin:`: one
    is killed and shows LOST within 5 s while the others go on; a fourth claiming system 1 is a
    CONFLICT, never merged; the killed one restarted (a new UDP port) comes back by itself."""
    port = free_udp_port()
    daemon = daemon_factory(vehicle=f"udpin:127.0.0.1:{port}", serve=["tcpin:127.0.0.1:0"], log=False)
    url = f"udpout:127.0.0.1:{port}"
    twins = {n: twin_factory(listen=[url], speed=1, extra=["--sysid", str(n)]) for n in (1, 2, 3)}
    g = script(daemon.tcp)
    try:
        heartbeats_by_sysid(g, {1, 2, 3}, timeout=20)
        # Across links: the command for 2 reaches 2 only.
        arm_only(g, {1, 2, 3}, 2)

        # Vehicle 3 dies: LOST within 5 s of its last heartbeat (status lines every second).
        twin_factory.twins.remove(twins[3])
        twins[3].proc.kill()
        twins[3].proc.wait(timeout=10)
        killed = time.monotonic()
        daemon.wait_line(r"\[3 LOST\]", timeout=10)
        assert time.monotonic() - killed < 6.5
        g.drain()
        heartbeats_by_sysid(g, {1, 2}, timeout=5)

        # Another vehicle left at system 1: a conflict, its frames kept out.
        impostor = twin_factory(listen=[url], speed=1, extra=["--sysid", "1"])
        line = daemon.wait_line(r"CONFLICT sys 1 on link#\d+ and link#\d+", timeout=10)
        assert "kept" in line, line
        twin_factory.stop(impostor)

        # Vehicle 3 again, from a new UDP port: back without restarting anything else.
        twins[3] = twin_factory(listen=[url], speed=1, extra=["--sysid", "3"])
        g.drain()
        heartbeats_by_sysid(g, {1, 2, 3}, timeout=10)
        assert daemon.alive(), daemon.tail()
    finally:
        g.close()
