"""Two pymavlink scripts at once through the daemon (embedded twin): one over TCP (tcpin), one over
UDP (udpin, pymavlink `udpout:`). Both see the vehicle's raw frames gap-free, each gets the
COMMAND_ACK for its own command and never the other's, and a parameter download through the
daemon is complete."""

from __future__ import annotations

import threading
import time

import pytest

from conftest import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_SET_MODE,
    FLAG_CUSTOM_MODE,
    MAV_RESULT_ACCEPTED,
    MODES,
    VEHICLE_COMPID,
    VEHICLE_SYSID,
)
from daemon_support import module_daemon_factory, script  # noqa: F401 (fixture)
from test_params import EXPECTED_NAMES, fetch_all

WINDOW_S = 5.0


@pytest.fixture(scope="module")
def daemon(module_daemon_factory):  # noqa: F811
    return module_daemon_factory(serve=["tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"])


def run_both(fns, timeout: float):
    """Runs fns[i](i) in threads at once; re-raises the first failure."""
    errors: list[BaseException] = [None] * len(fns)  # type: ignore[list-item]
    results = [None] * len(fns)

    def wrap(i):
        try:
            results[i] = fns[i](i)
        except BaseException as e:  # noqa: BLE001 (re-raised below)
            errors[i] = e

    threads = [threading.Thread(target=wrap, args=(i,), daemon=True) for i in range(len(fns))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout)
        assert not t.is_alive(), f"client thread still running after {timeout} s"
    for e in errors:
        if e is not None:
            raise e
    return results


def test_two_clients_see_every_vehicle_frame(daemon):
    urls = [daemon.tcp, daemon.udp]
    barrier = threading.Barrier(2, timeout=20)

    def client(i):
        g = script(urls[i])
        try:
            g.wait_vehicle_heartbeat(timeout=15)  # the udpin side learnt us from our heartbeat
            barrier.wait()
            counts: dict[str, int] = {}
            gaps = []
            bad = []
            last_seq = None
            frames = 0
            end = time.monotonic() + WINDOW_S
            while (left := end - time.monotonic()) > 0:
                g.beat()
                m = g.m.recv_match(blocking=True, timeout=min(left, 0.25))
                if m is None:
                    continue
                if m.get_type() == "BAD_DATA":
                    bad.append(m)
                    continue
                if (m.get_srcSystem(), m.get_srcComponent()) != (VEHICLE_SYSID, VEHICLE_COMPID):
                    continue
                frames += 1
                counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
                seq = m.get_seq()
                if last_seq is not None and seq != (last_seq + 1) % 256:
                    gaps.append((last_seq, seq, m.get_type()))
                last_seq = seq
            return urls[i], frames, counts, gaps, bad
        finally:
            g.close()

    for url, frames, counts, gaps, bad in run_both([client, client], timeout=WINDOW_S + 40):
        assert not bad, f"{url}: bad data through the daemon: {bad[:3]}"
        assert counts.get("HEARTBEAT", 0) >= WINDOW_S - 1, f"{url}: {counts}"
        assert counts.get("ATTITUDE", 0) >= 10 * WINDOW_S * 0.9, f"{url}: ATTITUDE below 10 Hz: {counts}"
        assert not gaps, f"{url}: {len(gaps)} sequence gaps in {frames} vehicle frames: {gaps[:10]} ({counts})"


def test_each_script_gets_only_its_own_ack(daemon):
    """(255, 0) sits behind both links: the ACK must follow the command's link. Round 1: the TCP
    script arms while the UDP script changes mode; round 2 the other way round."""
    urls = [daemon.tcp, daemon.udp]
    gs = [script(u) for u in urls]
    try:
        for g in gs:
            g.wait_vehicle_heartbeat(timeout=15)
        gs[0].wait_ready(timeout=30)
        rounds = [
            [(MAV_CMD_COMPONENT_ARM_DISARM, (1,)), (MAV_CMD_DO_SET_MODE, (FLAG_CUSTOM_MODE, MODES["QHOVER"]))],
            [(MAV_CMD_DO_SET_MODE, (FLAG_CUSTOM_MODE, MODES["QLAND"])), (MAV_CMD_COMPONENT_ARM_DISARM, (1,))],
        ]
        for rnd, cmds in enumerate(rounds):
            barrier = threading.Barrier(2, timeout=20)
            sent_at = [0.0, 0.0]

            def client(i, cmds=cmds, barrier=barrier, sent_at=sent_at):
                g = gs[i]
                g.drain()
                barrier.wait()
                cmd, params = cmds[i]
                p = list(params) + [0.0] * (7 - len(params))
                g.m.mav.command_long_send(VEHICLE_SYSID, VEHICLE_COMPID, cmd, 0, *p)
                sent_at[i] = time.monotonic()
                acks = []
                # Long enough for both ACKs (they come back in milliseconds) plus a margin in
                # which a misrouted copy of the other's ACK would show up.
                end = time.monotonic() + 3.0
                while (left := end - time.monotonic()) > 0:
                    g.beat()
                    m = g.m.recv_match(type="COMMAND_ACK", blocking=True, timeout=min(left, 0.25))
                    if m is not None:
                        acks.append((time.monotonic(), m))
                return acks

            results = run_both([client, client], timeout=40)
            for i in range(2):
                own_cmd = cmds[i][0]
                other_cmd = cmds[1 - i][0]
                acks = results[i]
                own = [m for _, m in acks if m.command == own_cmd]
                other = [m for _, m in acks if m.command == other_cmd]
                assert len(own) == 1, f"round {rnd}, {urls[i]}: expected one ACK for {own_cmd}, got {acks}"
                assert own[0].target_system == 255 and own[0].target_component == 0, own[0]
                if rnd == 0:
                    assert own[0].result == MAV_RESULT_ACCEPTED, own[0]
                assert not other, (
                    f"round {rnd}, {urls[i]} received the ACK of the other script's command "
                    f"{other_cmd}: {other}")
            # each script's own ACK arrived early in the window, so the other's window really
            # covered the time a misrouted copy would have arrived in
            for i in range(2):
                t_ack = next(t for t, m in results[i] if m.command == cmds[i][0])
                assert t_ack - sent_at[i] < 2.0, f"ACK took {t_ack - sent_at[i]:.2f} s"
            if rnd == 0:
                gs[1].wait_vehicle_heartbeat(
                    timeout=10, pred=lambda h: h.base_mode & 128 and h.custom_mode == MODES["QHOVER"])
    finally:
        for g in gs:
            g.close()


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_param_fetch_all_complete(daemon, transport):
    g = script(getattr(daemon, transport))
    try:
        g.wait_vehicle_heartbeat(timeout=15)
        seen, counts = fetch_all(g)
        assert len(counts) == 1, f"param_count changed during the download: {counts}"
        count = counts.pop()
        # nothing trails: no index comes a second time shortly after the download
        end = time.monotonic() + 1.0
        while (left := end - time.monotonic()) > 0:
            p = g.m.recv_match(type="PARAM_VALUE", blocking=True, timeout=left)
            if p is not None and p.get_srcSystem() == VEHICLE_SYSID:
                seen.setdefault(p.param_index, []).append(p)
        assert sorted(seen) == list(range(count)), f"indices {sorted(seen)} for count {count}"
        dup = {i: [p.param_id for p in ps] for i, ps in seen.items() if len(ps) > 1}
        assert not dup, f"indices received more than once through the daemon: {dup}"
        names = [ps[0].param_id for ps in seen.values()]
        for n in EXPECTED_NAMES:
            assert n in names, f"{n} missing from {sorted(names)}"
        # pymavlink's own table is complete too
        assert len(g.m.param_state[(VEHICLE_SYSID, VEHICLE_COMPID)].params) == count
    finally:
        g.close()
