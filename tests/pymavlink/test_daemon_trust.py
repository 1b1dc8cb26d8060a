"""Signing, trust and rate limits through the daemon (`vtol-gcs run`), against a keyed twin,
against a vehicle socket the test holds itself, and against the embedded twin.

Absence is never waited for: a frame that must not arrive is followed down the same path by one
that must, and the second arriving first proves the first went nowhere (the daemon routes each
link's frames in order, and a vehicle link or a client connection delivers them in order). A
read-only client's frames come from another connection, so the test first waits for the
daemon's own status line to count the refusal, then sends the barrier.
"""

from __future__ import annotations

import hashlib
import select
import socket
import subprocess
import time
from pathlib import Path

from pymavlink import mavutil

from conftest import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_SET_MESSAGE_INTERVAL,
    MAV_RESULT_ACCEPTED,
    TWIN_BIN,  # noqa: F401 (the twin's binary is checked by the fixture)
    VEHICLE_COMPID,
    VEHICLE_SYSID,
    Gcs,
    f32,
    twin_factory,  # noqa: F401 (fixture)
)
from daemon_support import DAEMON_BIN, daemon_factory, frame_ids, raw_records  # noqa: F401

PASSPHRASE = "trust test passphrase"
KEY = hashlib.sha256(PASSPHRASE.encode()).digest()
WRONG_KEY = hashlib.sha256(b"another key").digest()
FLAG_ARMED = 128
MSG_SYSTEM_TIME = 2
MSG_COMMAND_LONG = 76
MSG_SETUP_SIGNING = 256
SIGNING_EPOCH = 1420070400


def signed(msg) -> bool:
    """Whether a received message came signed (pymavlink's get_signed() says so only when the
    connection has a key itself)."""
    buf = bytes(msg.get_msgbuf())
    return buf[0] == 0xFD and bool(buf[2] & 1)


def signing_args(workdir: Path) -> list[str]:
    return ["--signing-passphrase", PASSPHRASE, "--signing-state", str(workdir / "signing.toml")]


def wait_status(daemon, pattern: str, timeout: float = 10.0) -> str:
    """The first status line (printed every 0.1 s here) matching `pattern`."""
    return daemon.wait_line(pattern, timeout)


def fast_status_config(workdir: Path, extra: str = "") -> list[str]:
    cfg = workdir / "vtol-gcs.toml"
    workdir.mkdir(parents=True, exist_ok=True)
    cfg.write_text(f"status_interval_s = 0.1\n{extra}")
    return ["--config", str(cfg)]


def test_read_only_and_sign_clients_against_a_keyed_twin(twin_factory, daemon_factory, tmp_path, monkeypatch):  # noqa: F811
    """A read-only client's arm never reaches the keyed twin, even signed with the right key; a
    `sign` client's unsigned arm and PARAM_SET are signed by the daemon and answered; a trusted
    client that signs for itself is heard; no key bytes in any log."""
    monkeypatch.setenv("RUST_LOG", "debug")
    twin = twin_factory(speed=4, extra=["--signing-passphrase", PASSPHRASE])
    work = tmp_path / "d"
    # The key and the endpoints come from the config file this time.
    cfg = fast_status_config(
        work,
        f'signing_passphrase = "{PASSPHRASE}"\nsigning_state = "{work / "signing.toml"}"\n',
    )
    daemon = daemon_factory(
        vehicle="tcp:" + twin.addr("tcpin"),
        serve=["tcpin:127.0.0.1:0?trust=sign", "tcpin:127.0.0.1:0?trust=read-only", "tcpin:127.0.0.1:0"],
        extra=cfg,
        workdir=work,
    )
    signer_url = "tcp:" + daemon.addr("tcpin", 0)
    reader_url = "tcp:" + daemon.addr("tcpin", 1)
    trusted_url = "tcp:" + daemon.addr("tcpin", 2)
    assert "serving tcpin:127.0.0.1:" in "\n".join(daemon.stdout_lines)
    assert any(line.endswith("?trust=read-only") for line in daemon.stdout_lines), daemon.stdout_lines

    # The read-only client is a bare pymavlink connection: it sends nothing unless told, so the
    # daemon's count of its refused frames is exactly its arm command. It even holds the key:
    # the keyed twin would take its arm if the daemon let it through.
    reader = mavutil.mavlink_connection(reader_url, source_system=250, source_component=0)
    reader.setup_signing(KEY, sign_outgoing=True)
    with Gcs(signer_url, source_system=255, source_component=0) as signer:
        # Both see the vehicle (its frames are signed by the twin and verified by the daemon).
        assert signed(signer.wait_ready())
        hb = reader.recv_match(type="HEARTBEAT", condition="HEARTBEAT.type!=6", blocking=True, timeout=10)
        assert hb is not None and signed(hb)

        # The read-only client arms: refused by the daemon, counted on its link.
        reader.mav.command_long_send(VEHICLE_SYSID, VEHICLE_COMPID, MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        wait_status(daemon, r"read-only refused 1\b")
        # Barrier: a signed command the twin answers after anything sent before it.
        ack = signer.command(MAV_CMD_SET_MESSAGE_INTERVAL, MSG_SYSTEM_TIME, 1e6)
        assert ack.result == MAV_RESULT_ACCEPTED
        hb = signer.wait_vehicle_heartbeat()
        assert not hb.base_mode & FLAG_ARMED, "armed by a read-only client"
        while (m := reader.recv_match(blocking=False)) is not None:
            assert m.get_type() != "COMMAND_ACK", f"the read-only client got an answer: {m}"
        # It still gets the telemetry.
        assert reader.recv_match(type="ATTITUDE", blocking=True, timeout=5) is not None

        # The sign client: unsigned arm and PARAM_SET, signed by the daemon, answered.
        ack = signer.arm()
        assert signed(ack)
        echo = signer.param_set("HOVER_ALT", 1.25)
        assert echo.param_value == f32(1.25)
        assert signer.wait_vehicle_heartbeat(pred=lambda h: h.base_mode & FLAG_ARMED) is not None
        signer.command(MAV_CMD_COMPONENT_ARM_DISARM, 0)

        # A trusted client that signs for itself goes through unchanged and is heard.
        with Gcs(trusted_url, source_system=253, source_component=0) as own:
            own.m.setup_signing(KEY, sign_outgoing=True)
            assert own.wait_vehicle_heartbeat().get_signed()
            assert own.param_set("HOVER_ALT", 1.5).param_value == f32(1.5)
            assert own.mav.signing.badsig_count == 0

        # SETUP_SIGNING carrying the key, from a client: never forwarded, never logged.
        signer.mav.setup_signing_send(VEHICLE_SYSID, VEHICLE_COMPID, list(KEY), 0)
        wait_status(daemon, r"signing \d+ signed, [1-9]\d* verified, refused 0 unsigned 0 bad 0 replayed")

    reader.close()
    tlog = daemon.tlog
    daemon_factory.stop(daemon)
    records, cut = raw_records(tlog.read_bytes())
    assert cut == 0
    assert not [f for _, f in records if frame_ids(f)[3] == MSG_SETUP_SIGNING], "SETUP_SIGNING logged"
    # Everything the daemon forwarded from the sign client (255) went signed; the trusted
    # client's first heartbeat, sent before it set its key up, went unsigned, as it came; the
    # read-only client's arm is nowhere.
    to_vehicle = [f for stamp, f in records if stamp & 3 == 3]
    from_signer = [f for f in to_vehicle if frame_ids(f)[1] == 255]
    assert from_signer and all(f[0] == 0xFD and f[2] & 1 for f in from_signer)
    assert any(not f[2] & 1 for f in to_vehicle if frame_ids(f)[1] == 253)
    assert not [f for f in to_vehicle if frame_ids(f)[1] == 250], "a read-only client's frame was logged"

    # No key bytes anywhere: stderr at debug level, stdout, the tlog.
    logs = daemon.stderr() + "\n".join(daemon.stdout_lines)
    assert "DEBUG" in daemon.stderr(), "RUST_LOG=debug did not reach the daemon"
    for secret in (KEY.hex(), KEY.hex().upper(), PASSPHRASE):
        assert secret not in logs, "key material in the daemon's output"
    assert KEY not in tlog.read_bytes(), "key bytes in the tlog"
    # The state file holds the key, owner-only.
    state = work / "signing.toml"
    assert oct(state.stat().st_mode & 0o777) == "0o600"


def signed_packer(key: bytes, link_id: int = 0):
    """A pymavlink MAVLink object that packs frames as the vehicle (1, 1), signed with key."""
    mav = mavutil.mavlink.MAVLink(None, srcSystem=VEHICLE_SYSID, srcComponent=VEHICLE_COMPID)
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = True
    mav.signing.link_id = link_id
    mav.signing.timestamp = int((time.time() - SIGNING_EPOCH) * 1e5)
    return mav


def test_trusted_frames_pass_unchanged_and_the_vehicle_is_verified(daemon_factory, tmp_path):  # noqa: F811
    """The daemon's vehicle link goes to a UDP socket this test holds: a trusted client's
    unsigned frame arrives byte for byte (no signature added), a sign client's arrives signed
    with the key; the vehicle's unsigned, wrongly signed and replayed frames are dropped and
    counted, and SETUP_SIGNING never reaches the vehicle."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(5.0)
    port = vehicle.getsockname()[1]
    work = tmp_path / "d"
    daemon = daemon_factory(
        vehicle=f"udpout:127.0.0.1:{port}",
        serve=["tcpin:127.0.0.1:0", "tcpin:127.0.0.1:0?trust=sign"],
        extra=signing_args(work) + fast_status_config(work),
        workdir=work,
    )
    rx = mavutil.mavlink.MAVLink(None)

    # Frames the vehicle got that no wait has taken yet: the two clients' first frames may
    # reach it in either order.
    backlog: list = []

    def next_to_vehicle(pred, what: str):
        """The first frame the daemon sent to the vehicle, not yet taken, for which
        pred(msgid, frame)."""
        deadline = time.monotonic() + 5
        while True:
            for k, (frame, addr) in enumerate(backlog):
                if pred(frame_ids(frame)[3], frame):
                    del backlog[k]
                    return frame, addr
            if time.monotonic() >= deadline:
                raise AssertionError(f"the vehicle never got {what}")
            data, addr = vehicle.recvfrom(4096)
            i = 0
            while i < len(data):
                n = 10 + data[i + 1] + 2 + (13 if data[i + 2] & 1 else 0) if data[i] == 0xFD else 8 + data[i + 1]
                backlog.append((data[i:i + n], addr))
                i += n

    packer = signed_packer(KEY)
    with Gcs("tcp:" + daemon.addr("tcpin", 0), source_system=255, source_component=0) as trusted, \
            Gcs("tcp:" + daemon.addr("tcpin", 1), source_system=254, source_component=0) as signer:
        # Both clients' heartbeats reaching the vehicle say their links are up, and where the
        # daemon's vehicle link is.
        _, daemon_addr = next_to_vehicle(lambda mid, f: mid == 0 and f[5] == 255, "a heartbeat (trusted)")
        next_to_vehicle(lambda mid, f: mid == 0 and f[5] == 254, "a heartbeat (sign)")
        vehicle.sendto(packer.heartbeat_encode(2, 0, 0, 0, 3).pack(packer), daemon_addr)
        trusted.wait_vehicle_heartbeat()
        signer.wait_vehicle_heartbeat()

        # A trusted client's unsigned command arrives unchanged, unsigned.
        msg = trusted.mav.command_long_encode(VEHICLE_SYSID, VEHICLE_COMPID, 65001, 0, 1, 2, 3, 4, 5, 6, 7)
        sent = msg.pack(trusted.mav)
        trusted.m.write(sent)
        got, _ = next_to_vehicle(lambda mid, f: mid == MSG_COMMAND_LONG and f[5] == 255, "the trusted command")
        assert got == sent, "the trusted client's frame was changed"
        assert not got[2] & 1, "the daemon signed a trusted client's frame"

        # SETUP_SIGNING from the trusted client, then a barrier: only the barrier arrives.
        trusted.mav.setup_signing_send(VEHICLE_SYSID, VEHICLE_COMPID, list(KEY), 0)
        trusted.mav.command_long_send(VEHICLE_SYSID, VEHICLE_COMPID, 65002, 0, 0, 0, 0, 0, 0, 0, 0)
        got, _ = next_to_vehicle(lambda mid, f: mid in (MSG_SETUP_SIGNING, MSG_COMMAND_LONG), "the barrier")
        assert frame_ids(got)[3] == MSG_COMMAND_LONG, "SETUP_SIGNING was forwarded to the vehicle"

        # A sign client's unsigned command arrives signed with the daemon's key, as a stream of
        # its own (link id not 0, which clients signing themselves use).
        signer.mav.command_long_send(VEHICLE_SYSID, VEHICLE_COMPID, 65003, 0, 0, 0, 0, 0, 0, 0, 0)
        got, _ = next_to_vehicle(lambda mid, f: mid == MSG_COMMAND_LONG and f[5] == 254, "the sign client's command")
        assert got[2] & 1, "not signed"
        check = mavutil.mavlink.MAVLink(None)
        check.signing.secret_key = KEY
        parsed = check.parse_buffer(got)
        assert parsed and parsed[0].command == 65003 and check.signing.goodsig_count == 1
        assert got[-13] != 0, "signed as link 0"

        # The vehicle's bad frames: unsigned, wrong key, replayed. Each is followed by a good one;
        # the clients see only the good ones.
        def text(t: str):
            return packer.statustext_encode(6, t.encode())

        unsigned = mavutil.mavlink.MAVLink(None, srcSystem=VEHICLE_SYSID, srcComponent=VEHICLE_COMPID)
        wrong = signed_packer(WRONG_KEY)
        first = text("good 1").pack(packer)
        for bad, good in (
            (text("unsigned").pack(unsigned), first),
            (text("wrong key").pack(wrong), text("good 2").pack(packer)),
            (first, text("good 3").pack(packer)),  # `first` again: a replay
        ):
            vehicle.sendto(bad, daemon_addr)
            vehicle.sendto(good, daemon_addr)
        texts = [trusted.recv("STATUSTEXT", timeout=5).text for _ in range(3)]
        assert texts == ["good 1", "good 2", "good 3"], texts
        wait_status(daemon, r"refused 1 unsigned 1 bad 1 replayed")
        del rx
    vehicle.close()


def test_a_rate_limited_client_gets_its_rate_and_the_others_everything(daemon_factory, tmp_path):  # noqa: F811
    """Embedded twin; one client at ?rate=5&burst=5, one without limit. Over 2 s the limited
    one receives at most burst + rate × time; the other and the tlog get every vehicle frame."""
    work = tmp_path / "d"
    daemon = daemon_factory(
        vehicle="embedded",
        serve=["tcpin:127.0.0.1:0?rate=5&burst=5", "tcpin:127.0.0.1:0"],
        extra=fast_status_config(work),
        workdir=work,
    )

    def connect(i):
        host, port = daemon.host_port("tcpin", i)
        s = socket.create_connection((host, port), timeout=5)
        s.setblocking(False)
        return s

    t_connect = time.monotonic()
    limited, free = connect(0), connect(1)
    parsers = {limited: mavutil.mavlink.MAVLink(None), free: mavutil.mavlink.MAVLink(None)}
    got = {limited: [], free: []}
    window_end = time.monotonic() + 2.0
    while (left := window_end - time.monotonic()) > 0:
        ready, _, _ = select.select([limited, free], [], [], left)
        for s in ready:
            data = s.recv(65536)
            assert data, "the daemon closed a client"
            msgs = parsers[s].parse_buffer(data) or []
            got[s] += [bytes(m.get_msgbuf()) for m in msgs if m.get_srcSystem() == VEHICLE_SYSID]
    t_end = time.monotonic()
    limit = 5 + 5 * (t_end - t_connect)
    n_limited, n_free = len(got[limited]), len(got[free])
    assert 0 < n_limited <= limit, f"limited client got {n_limited}, allowed {limit:.1f}"
    assert n_free > 2 * limit, f"the other client got only {n_free}"
    wait_status(daemon, r"link#\d+ trusted rate-dropped [1-9]")
    limited.close()
    free.close()

    tlog = daemon.tlog
    daemon_factory.stop(daemon)
    records, _ = raw_records(tlog.read_bytes())
    from_vehicle = set(f for stamp, f in records if stamp & 3 == 0)
    missing = [f for f in got[free] + got[limited] if f not in from_vehicle]
    assert not missing, f"{len(missing)} frames the clients got are not in the tlog"
    assert len(from_vehicle) >= n_free


def test_bad_serve_options_and_keys_are_one_clear_error(tmp_path):
    key_file = tmp_path / "bad.key"
    key_file.write_text("0123456789abcdef" * 3 + "zz" + "0" * 14)
    cases = [
        (["--serve", "tcpin:127.0.0.1:0?trust=admin"], "unknown trust 'admin'"),
        (["--serve", "tcpin:127.0.0.1:0?rate=-1"], "rate '-1'"),
        (["--serve", "tcpin:127.0.0.1:0?colour=red"], "unknown option 'colour'"),
        (["--serve", "tcpin:127.0.0.1:0?trust=sign"], "no signing key"),
        (["--serve", "tcpin:127.0.0.1:0", "--signing-key-file", str(key_file)], "bad.key"),
    ]
    for args, want in cases:
        run = subprocess.run(
            [str(DAEMON_BIN), "run", "--no-log", "--vehicle", "udpout:127.0.0.1:9", *args],
            capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL, cwd=tmp_path,
        )
        assert run.returncode != 0, args
        err = run.stderr.strip()
        assert want in err, f"{args}: {err}"
        assert len(err.splitlines()) <= 3, err  # clap adds a usage hint under its own errors
        assert "0123456789abcdef" not in err + run.stdout


def test_the_client_commands_sign_against_a_keyed_twin(twin_factory, tmp_path):  # noqa: F811
    """`vtol-gcs params set` and `arm` with --signing-passphrase, straight to a keyed twin."""
    twin = twin_factory(speed=4, extra=["--signing-passphrase", PASSPHRASE])
    state = tmp_path / "cli-signing.toml"
    base = [str(DAEMON_BIN)]
    link = ["--link", "tcp:" + twin.addr("tcpin"), "--signing-passphrase", PASSPHRASE,
            "--signing-state", str(state)]
    for cmd in (["params", "set", "HOVER_ALT", "1.5"], ["arm"], ["disarm"]):
        run = subprocess.run(base + cmd + link, capture_output=True, text=True, timeout=60,
                             stdin=subprocess.DEVNULL, cwd=tmp_path)
        assert run.returncode == 0, f"{cmd}: {run.stdout}{run.stderr}"
        assert KEY.hex() not in run.stdout + run.stderr and PASSPHRASE not in run.stdout + run.stderr
    saved = int(state.read_text().split("timestamp = ")[1].split()[0])
    assert saved > int((time.time() - SIGNING_EPOCH - 60) * 1e5)


def test_a_command_through_a_read_only_endpoint_names_its_trust(daemon_factory, tmp_path):  # noqa: F811
    """`vtol-gcs arm` on a read-only serve port sees the vehicle but no answer: its error names
    the endpoint's trust as the likely cause instead of ending at "no answer"."""
    daemon = daemon_factory(serve=["tcpin:127.0.0.1:0?trust=read-only"], log=False)
    run = subprocess.run(
        [str(DAEMON_BIN), "arm", "--link", "tcp:" + daemon.addr("tcpin")],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL, cwd=tmp_path,
    )
    assert run.returncode == 3, run.stdout + run.stderr
    assert "no answer" in run.stderr and "trust=read-only" in run.stderr, run.stderr
