"""SETUP_SIGNING sent by real pymavlink (`mav.setup_signing_send`, what MAVProxy's `signing setup`
sends) to the twin: taken only from a link signed with the twin's current key or from a local
(serial) link, refused from an unsigned network link.

Each outcome is read from what the twin does next on the same link, which it reads in order:
still unkeyed, the answer to an unsigned request comes back unsigned; re-keyed, the answer comes
back signed with the new key (pymavlink drops frames signed with any other key).
"""

import hashlib
import time

from conftest import VEHICLE_COMPID, VEHICLE_SYSID, Gcs, f32
from daemon_support import Socat

PASSPHRASE = "twin setup signing test"
KEY = hashlib.sha256(PASSPHRASE.encode()).digest()
NEW_KEY = hashlib.sha256(b"the key SETUP_SIGNING brings").digest()
SIGNING_EPOCH = 1420070400


def timestamp_now() -> int:
    """The signing timestamp of now: 10 us units since 2015-01-01 (as MAVProxy sends)."""
    return int((time.time() - SIGNING_EPOCH) * 100_000)


def send_setup(g: Gcs, key: bytes) -> None:
    g.mav.setup_signing_send(VEHICLE_SYSID, VEHICLE_COMPID, list(key), timestamp_now())


def saved_key(twin) -> str | None:
    path = twin.param_file.with_suffix(".signing")
    if not path.exists():
        return None
    return path.read_text().split('key = "')[1].split('"')[0]


def assert_no_key_in_logs(twin) -> None:
    logs = twin.stderr() + "\n".join(twin.stdout_lines)
    for k in (KEY, NEW_KEY):
        assert k.hex() not in logs, "key bytes in the twin's log"


def test_unsigned_setup_signing_over_udp_is_refused(twin_factory):
    # An unkeyed twin stays unkeyed.
    twin = twin_factory(speed=4)
    with Gcs(twin.udp) as g:
        assert not g.wait_vehicle_heartbeat().get_signed()
        send_setup(g, NEW_KEY)
        p = g.param_get("ALT_KP")
        assert not p.get_signed(), "the twin took a key from an unsigned UDP link"
    twin.stop()
    twin.assert_clean_exit()
    assert saved_key(twin) is None
    assert "SETUP_SIGNING refused" in twin.stderr()
    assert_no_key_in_logs(twin)

    # A keyed twin keeps its key: a request signed with it is still answered, signed with it.
    keyed = twin_factory(speed=4, extra=["--signing-passphrase", PASSPHRASE])
    with Gcs(keyed.udp) as g:
        g.m.setup_signing(KEY, sign_outgoing=True)
        assert g.wait_vehicle_heartbeat().get_signed()
        g.mav.signing.sign_outgoing = False
        send_setup(g, NEW_KEY)
        g.mav.signing.sign_outgoing = True
        p = g.param_get("ALT_KP")
        assert p.get_signed()
        assert g.mav.signing.badsig_count == 0, "the twin signed with another key"
    keyed.stop()
    keyed.assert_clean_exit()
    assert saved_key(keyed) == KEY.hex()
    assert_no_key_in_logs(keyed)


def test_setup_signing_signed_with_the_current_key_rekeys_the_twin(twin_factory):
    twin = twin_factory(speed=4, extra=["--signing-passphrase", PASSPHRASE])
    with Gcs(twin.tcp) as g:
        g.m.setup_signing(KEY, sign_outgoing=True)
        signing = g.mav.signing
        assert g.wait_vehicle_heartbeat().get_signed()
        base = g.param_get("ALT_KP").param_value

        send_setup(g, NEW_KEY)  # signed with KEY
        signing.secret_key = NEW_KEY
        # Signed with the new key: accepted, and the echo is signed with the new key.
        g.mav.param_set_send(VEHICLE_SYSID, VEHICLE_COMPID, b"ALT_KP", base + 1.0, 9)
        echo = g.recv("PARAM_VALUE", lambda p: p.param_id == "ALT_KP", what="echo under the new key")
        assert echo.get_signed() and echo.param_value == f32(base + 1.0)

        # Signed with the old key: refused (a read under the new key, sent after it, shows it).
        signing.secret_key = KEY
        g.mav.param_set_send(VEHICLE_SYSID, VEHICLE_COMPID, b"ALT_KP", base + 2.0, 9)
        signing.secret_key = NEW_KEY
        assert g.param_get("ALT_KP").param_value == f32(base + 1.0)
    twin.stop()
    twin.assert_clean_exit()
    assert saved_key(twin) == NEW_KEY.hex()
    assert_no_key_in_logs(twin)

    # Restarted on the same files with no key on the command line: the saved key is used.
    again = twin_factory(speed=4, param_file=twin.param_file)
    with Gcs(again.tcp) as g:
        g.m.setup_signing(NEW_KEY, sign_outgoing=True)
        assert g.wait_vehicle_heartbeat().get_signed()
        assert g.param_get("ALT_KP").param_value == f32(base + 1.0)


def test_setup_signing_on_a_serial_link_is_taken_unsigned(twin_factory, tmp_path):
    vehicle_end, gcs_end = tmp_path / "vehicle", tmp_path / "gcs"
    socat = Socat(vehicle_end, gcs_end)
    socat.start()
    try:
        twin = twin_factory(listen=[f"serial:{vehicle_end}:115200", "tcpin:127.0.0.1:0"], speed=4)
        g = Gcs(str(gcs_end), baud=115200)
        try:
            assert not g.wait_vehicle_heartbeat(timeout=20).get_signed()
            send_setup(g, NEW_KEY)  # unsigned, on the cable
            g.m.setup_signing(NEW_KEY, sign_outgoing=True)
            assert g.wait_vehicle_heartbeat().get_signed()
            assert g.param_get("ALT_KP").get_signed()
        finally:
            g.close()
        # The network link is keyed too: the twin signs there with the new key.
        with Gcs(twin.tcp) as t:
            t.m.setup_signing(NEW_KEY, sign_outgoing=True)
            assert t.wait_vehicle_heartbeat().get_signed()
            assert t.param_get("ALT_KP").get_signed()
        twin.stop()
        twin.assert_clean_exit()
        assert saved_key(twin) == NEW_KEY.hex()
        assert_no_key_in_logs(twin)
    finally:
        socat.stop()


def test_a_fleet_member_takes_setup_signing_on_the_shared_serial_link(twin_factory, tmp_path):
    """`serve --count 2`: the serial endpoint is shared by the fleet and still counts as local."""
    vehicle_end, gcs_end = tmp_path / "vehicle", tmp_path / "gcs"
    socat = Socat(vehicle_end, gcs_end)
    socat.start()
    try:
        twin = twin_factory(listen=[f"serial:{vehicle_end}:115200"], speed=4, extra=["--count", "2"])
        g = Gcs(str(gcs_end), baud=115200)
        try:

            def heartbeat_of(sysid: int, signed: bool):
                deadline = time.monotonic() + 20
                while time.monotonic() < deadline:
                    g.beat()
                    m = g.m.recv_match(type="HEARTBEAT", blocking=True, timeout=0.25)
                    if m is not None and m.get_srcSystem() == sysid and m.get_signed() == signed:
                        return m
                raise AssertionError(f"no {'signed' if signed else 'unsigned'} heartbeat of system {sysid}")

            heartbeat_of(2, signed=False)
            g.mav.setup_signing_send(2, VEHICLE_COMPID, list(NEW_KEY), timestamp_now())  # unsigned, on the cable
            g.m.setup_signing(NEW_KEY, sign_outgoing=True)
            heartbeat_of(2, signed=True)
        finally:
            g.close()
        twin.stop()
        twin.assert_clean_exit()
        member = twin.param_file.with_name(f"{twin.param_file.stem}-sys2.signing")
        assert member.read_text().split('key = "')[1].split('"')[0] == NEW_KEY.hex()
        # It was addressed to system 2 only: system 1 stays unkeyed.
        assert not twin.param_file.with_name(f"{twin.param_file.stem}-sys1.signing").exists()
    finally:
        socat.stop()
