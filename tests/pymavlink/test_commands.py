"""Command protocol: unknown commands, ACK addressing, SET_MESSAGE_INTERVAL and the resulting rate."""

import time

import pytest

from conftest import (
    GCS_SYSID,
    MAV_CMD_SET_MESSAGE_INTERVAL,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_UNSUPPORTED,
    MSG_ATTITUDE,
)

MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_GET_MESSAGE_INTERVAL = 510
MSG_AUTOPILOT_VERSION = 148
CAP_MAVLINK2 = 0x2000
CAP_PARAM_ENCODE_C_CAST = 0x20000


@pytest.mark.parametrize("transport", ["tcp", "udp"])
@pytest.mark.parametrize("command", [65000, 31999, 16])
def test_unknown_command_is_unsupported(twin, gcs_factory, transport, command):
    """Command ids the twin does not implement, including ones no dialect knows (65000)."""
    g = gcs_factory(getattr(twin, transport))
    g.wait_vehicle_heartbeat()
    g.m.mav.command_long_send(1, 1, command, 0, 1, 2, 3, 4, 5, 6, 7)
    ack = g.recv("COMMAND_ACK", lambda a: a.command == command, timeout=10)
    assert ack.result == MAV_RESULT_UNSUPPORTED, ack


def test_unknown_command_int_is_unsupported(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    g.m.mav.command_int_send(1, 1, 0, 65000, 0, 0, 1, 2, 3, 4, 5, 6, 7.0)
    ack = g.recv("COMMAND_ACK", lambda a: a.command == 65000)
    assert ack.result == MAV_RESULT_UNSUPPORTED, ack


def test_ack_addresses_the_sender(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    ack = g.command(65000)
    assert (ack.target_system, ack.target_component) == (GCS_SYSID, 190), ack


def test_exactly_one_ack_per_command(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    for _ in range(3):
        g.m.mav.command_long_send(1, 1, 65000, 0, 0, 0, 0, 0, 0, 0, 0)
    # a different command as a fence: its ACK comes after the three above
    g.m.mav.command_long_send(1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0)
    acks = g.collect("COMMAND_ACK", until=lambda a: a and a[-1].command == 31999, timeout=10)
    assert [a.command for a in acks] == [65000, 65000, 65000, 31999], acks


def test_request_autopilot_version(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    g.m.mav.command_long_send(1, 1, MAV_CMD_REQUEST_MESSAGE, 0, MSG_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
    ack = g.recv("COMMAND_ACK", lambda a: a.command == MAV_CMD_REQUEST_MESSAGE)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    v = g.recv("AUTOPILOT_VERSION")
    assert v.capabilities & CAP_MAVLINK2 and v.capabilities & CAP_PARAM_ENCODE_C_CAST, hex(v.capabilities)


def test_set_message_interval_disable(twin, gcs_factory):
    """-1 stops a stream on this link; 0 brings back the default. Other links are unaffected."""
    g = gcs_factory(twin.tcp)
    other = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    other.wait_vehicle_heartbeat()
    assert g.command(MAV_CMD_SET_MESSAGE_INTERVAL, MSG_ATTITUDE, -1).result == MAV_RESULT_ACCEPTED
    # two heartbeats later (2 s of vehicle time) no ATTITUDE has come on this link
    n_beats = 0
    while n_beats < 2:
        m = g.recv(["HEARTBEAT", "ATTITUDE"], timeout=10)
        assert m.get_type() != "ATTITUDE", "ATTITUDE still streamed after interval -1"
        n_beats += 1
    other.drain()
    other.recv("ATTITUDE", timeout=5)  # the other client still gets it
    assert g.command(MAV_CMD_SET_MESSAGE_INTERVAL, MSG_ATTITUDE, 0).result == MAV_RESULT_ACCEPTED
    g.recv("ATTITUDE", timeout=5)


@pytest.fixture(scope="module")
def realtime_twin(module_twin_factory):
    """A twin at speed 1: rates are measured here."""
    return module_twin_factory(speed=1)


def measure(g, msg_type, seconds):
    """Messages over `seconds` of vehicle time; returns (rate by vehicle time, rate by wall time)."""
    first = g.recv(msg_type)
    t_wall0 = time.monotonic()
    n = 0
    last = first
    while last.time_boot_ms - first.time_boot_ms < seconds * 1000:
        last = g.recv(msg_type, timeout=5)
        n += 1
    wall = time.monotonic() - t_wall0
    return n / ((last.time_boot_ms - first.time_boot_ms) / 1000), n / wall


@pytest.mark.parametrize("hz", [50, 10])
def test_set_message_interval_attitude(realtime_twin, gcs_factory, hz):
    g = gcs_factory(realtime_twin.tcp)
    g.wait_vehicle_heartbeat()
    ack = g.command(MAV_CMD_SET_MESSAGE_INTERVAL, MSG_ATTITUDE, 1e6 / hz)
    assert ack.result == MAV_RESULT_ACCEPTED, ack
    g.recv("ATTITUDE")  # let the new interval take over
    by_vehicle, by_wall = measure(g, "ATTITUDE", 4.0)
    tol = hz * 0.1
    assert abs(by_vehicle - hz) <= tol, f"{by_vehicle:.1f} Hz in vehicle time, wanted {hz}"
    assert abs(by_wall - hz) <= tol, f"{by_wall:.1f} Hz in wall time at speed 1, wanted {hz}"
    # GET_MESSAGE_INTERVAL reports it back
    g.m.mav.command_long_send(1, 1, MAV_CMD_GET_MESSAGE_INTERVAL, 0, MSG_ATTITUDE, 0, 0, 0, 0, 0, 0)
    mi = g.recv("MESSAGE_INTERVAL", lambda m: m.message_id == MSG_ATTITUDE)
    assert mi.interval_us == int(1e6 / hz), mi


def test_request_data_stream_sets_group_rate(realtime_twin, gcs_factory):
    """The legacy REQUEST_DATA_STREAM (what MAVProxy sends): EXTRA1 (10) carries ATTITUDE."""
    g = gcs_factory(realtime_twin.tcp)
    g.wait_vehicle_heartbeat()
    g.m.mav.request_data_stream_send(1, 1, 10, 5, 1)
    g.recv("ATTITUDE")
    # the old rate may still be in the pipe: measure from the second second on
    first = g.recv("ATTITUDE")
    while g.recv("ATTITUDE").time_boot_ms - first.time_boot_ms < 1000:
        pass
    by_vehicle, _ = measure(g, "ATTITUDE", 4.0)
    assert abs(by_vehicle - 5) <= 0.5, f"{by_vehicle:.2f} Hz after REQUEST_DATA_STREAM(EXTRA1, 5 Hz)"
