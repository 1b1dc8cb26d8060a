"""A keyed twin (`serve --signing-passphrase`) against pymavlink's own signing.

Each refusal is shown without waiting for silence: the refused frame and then a rightly signed
request go down the same TCP connection, which the twin reads in order, so the answer to the
signed request arriving first (and the value it reads) proves the refused frame did nothing.
"""

import hashlib
import subprocess

from conftest import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_SET_MESSAGE_INTERVAL,
    MAV_RESULT_ACCEPTED,
    TWIN_BIN,
    VEHICLE_COMPID,
    VEHICLE_SYSID,
    Gcs,
    f32,
)

PASSPHRASE = "twin signing test"
KEY = hashlib.sha256(PASSPHRASE.encode()).digest()
WRONG_KEY = hashlib.sha256(b"not the twin's passphrase").digest()
MAV_MODE_FLAG_SAFETY_ARMED = 128
MSG_ID_SYSTEM_TIME = 2


def param_set(g: Gcs, name: str, value: float) -> None:
    g.mav.param_set_send(VEHICLE_SYSID, VEHICLE_COMPID, name.encode(), value, 9)


def read_param(g: Gcs, name: str) -> float:
    """A signed read on the same connection: answered after everything sent before it."""
    return g.param_get(name, timeout=10.0).param_value


def test_keyed_twin_takes_only_rightly_signed_fresh_frames(twin_factory):
    twin = twin_factory(speed=4, extra=["--signing-passphrase", PASSPHRASE])
    with Gcs(twin.tcp) as g:
        g.m.setup_signing(KEY, sign_outgoing=True)
        signing = g.mav.signing
        # The twin signs what it sends, with the same key.
        hb = g.wait_vehicle_heartbeat()
        assert hb.get_signed(), "vehicle heartbeat not signed"
        base = read_param(g, "ALT_KP")

        # Unsigned PARAM_SET: no change.
        signing.sign_outgoing = False
        param_set(g, "ALT_KP", base + 1.0)
        signing.sign_outgoing = True
        assert read_param(g, "ALT_KP") == base

        # Unsigned COMMAND_LONG (arm): no ACK, not armed.
        g.drain()
        signing.sign_outgoing = False
        g.mav.command_long_send(VEHICLE_SYSID, VEHICLE_COMPID, MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        signing.sign_outgoing = True
        g.mav.command_long_send(
            VEHICLE_SYSID, VEHICLE_COMPID, MAV_CMD_SET_MESSAGE_INTERVAL, 0, MSG_ID_SYSTEM_TIME, 1e6, 0, 0, 0, 0, 0
        )
        ack = g.recv("COMMAND_ACK", what="for the signed command")
        assert ack.command == MAV_CMD_SET_MESSAGE_INTERVAL, f"the unsigned arm was answered: {ack}"
        assert ack.result == MAV_RESULT_ACCEPTED
        hb = g.wait_vehicle_heartbeat()
        assert not hb.base_mode & MAV_MODE_FLAG_SAFETY_ARMED, "armed by an unsigned command"

        # Signed with the wrong key: no change.
        signing.secret_key = WRONG_KEY
        param_set(g, "ALT_KP", base + 2.0)
        signing.secret_key = KEY
        assert read_param(g, "ALT_KP") == base

        # Signed with the right key: accepted and echoed.
        g.drain()
        first = g.mav.param_set_encode(VEHICLE_SYSID, VEHICLE_COMPID, b"ALT_KP", base + 3.0, 9)
        first_bytes = first.pack(g.mav)
        g.m.write(first_bytes)
        echo = g.recv("PARAM_VALUE", lambda p: p.param_id == "ALT_KP", what="echo of the signed set")
        assert echo.param_value == f32(base + 3.0)
        param_set(g, "ALT_KP", base + 4.0)
        assert read_param(g, "ALT_KP") == f32(base + 4.0)

        # The first signed PARAM_SET replayed byte for byte: refused (its timestamp is old).
        g.m.write(first_bytes)
        assert read_param(g, "ALT_KP") == f32(base + 4.0)
        assert signing.badsig_count == 0, "pymavlink refused one of the twin's signatures"

    twin.stop()
    twin.assert_clean_exit()
    # Key and timestamp persisted beside --param-file; the key appears in no log.
    state = twin.param_file.with_suffix(".signing").read_text()
    assert f'key = "{KEY.hex()}"' in state
    saved = int(state.split("timestamp = ")[1].split()[0])
    assert saved >= signing.timestamp - 1 > 0
    logs = twin.stderr() + "\n".join(twin.stdout_lines)
    assert KEY.hex() not in logs and PASSPHRASE not in logs

    # Restarted on the same files, the twin signs on from the saved timestamp, even one ahead
    # of the wall clock (here moved 10 minutes on).
    ahead = saved + 10 * 60 * 100_000
    state_file = twin.param_file.with_suffix(".signing")
    state_file.write_text(state.replace(f"timestamp = {saved}", f"timestamp = {ahead}"))
    again = twin_factory(speed=4, param_file=twin.param_file, extra=["--signing-passphrase", PASSPHRASE])
    with Gcs(again.tcp) as g:
        g.m.setup_signing(KEY, sign_outgoing=True)
        assert g.wait_vehicle_heartbeat().get_signed()
        assert g.mav.signing.stream_timestamps[(0, VEHICLE_SYSID, VEHICLE_COMPID)] > ahead


def test_key_file_signs_and_a_bad_one_is_one_clear_error(twin_factory, tmp_path):
    key_file = tmp_path / "twin.key"
    key_file.write_text(KEY.hex() + "\n")
    twin = twin_factory(extra=["--signing-key-file", str(key_file)])
    with Gcs(twin.tcp) as g:
        g.m.setup_signing(KEY, sign_outgoing=True)
        assert g.wait_vehicle_heartbeat().get_signed()
        assert g.mav.signing.badsig_count == 0
    twin.stop()
    twin.assert_clean_exit()

    secret = "0123456789abcdef" * 3 + "not hex!" + "0" * 8
    key_file.write_text(secret)
    run = subprocess.run(
        [str(TWIN_BIN), "serve", "--listen", "tcpin:127.0.0.1:0", "--signing-key-file", str(key_file)],
        capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL,
    )
    assert run.returncode != 0
    err = run.stderr.strip()
    assert "twin.key" in err and "character 49 is not a hex digit" in err, err
    assert "0123456789abcdef" not in err + run.stdout
    assert len(err.splitlines()) == 1, err
