"""Writes the seed corpora of the fuzz targets (fuzz/corpus/TARGET/): real inputs of each format,
made with pymavlink and by hand, so mutations start deep inside each parser. Run from the
repository root with the test venv: `.venv/bin/python fuzz/make_corpus.py`. The files are kept in
git; running it again rewrites the same bytes."""

from __future__ import annotations

import struct
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

OUT = Path(__file__).parent / "corpus"
TWIN_READS = [0, 11, 20, 21, 23, 39, 40, 41, 43, 44, 45, 47, 51, 66, 69, 70, 73, 75, 76, 84, 86, 109,
              110, 111, 2, 4, 253, 256]


def write(target: str, name: str, data: bytes | str) -> None:
    d = OUT / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data.encode() if isinstance(data, str) else data)


def mav(sysid=255, compid=190, signed=False):
    m = apm.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    m.robust_parsing = True
    if signed:
        m.signing.secret_key = bytes(range(32))
        m.signing.sign_outgoing = True
        m.signing.link_id = 1
        m.signing.timestamp = 4_000_000_000
    return m


def frames(sysid=255, compid=190, signed=False, v1=False) -> list[bytes]:
    m = mav(sysid, compid, signed)
    if v1:
        m.WIRE_PROTOCOL_VERSION = "1.0"
    msgs = [
        apm.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3),
        apm.MAVLink_param_set_message(1, 1, b"HOVER_ALT", 1.5, 9),
        apm.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
        apm.MAVLink_attitude_message(1234, 0.1, -0.2, 0.3, 0.01, 0.02, 0.03),
        apm.MAVLink_statustext_message(6, b"Rebooted", 0, 0),
    ]
    return [bytes(x.pack(m)) for x in msgs]


# frame_decoder and signing_verify: v2, v1, signed, with garbage between
v2, v1, signed = frames(), frames(v1=True), frames(signed=True)
write("frame_decoder", "v2", b"".join(v2))
write("frame_decoder", "v1", b"".join(v1))
write("frame_decoder", "signed", b"".join(signed))
write("frame_decoder", "garbage_between", b"\xfd\x05junk".join(v2 + v1))
write("signing_verify", "signed", b"".join(signed))
vehicle = mav(1, 1)
write("router", "command_and_ack", b"".join(v2 + [
    bytes(apm.MAVLink_heartbeat_message(20, 17, 0, 18, 4, 3).pack(vehicle)),
    bytes(apm.MAVLink_command_ack_message(400, 0, 0, 0, 255, 190).pack(vehicle)),
    bytes(apm.MAVLink_param_value_message(b"HOVER_ALT", 1.0, 9, 50, 3).pack(vehicle)),
] + v2[1:3]))
write("signing_verify", "unsigned", b"".join(v2))

# tlog: records of 8-byte big-endian µs stamps, both directions, and a cut last record
t0 = 1_795_346_880_000_000
recs = b"".join(struct.pack(">Q", (t0 + i * 10_000) & ~3 | (0 if i % 2 else 3)) + f
                for i, f in enumerate(frames(1, 1) + v2))
write("tlog", "records", recs)
write("tlog", "cut_tail", recs + struct.pack(">Q", t0 + 99_000) + v2[0][:7])
write("tlog", "garbage", b"\x00" * 9 + recs[:40] + b"\xfe\xfe" + recs[40:])

# URLs and --vehicle values
for i, u in enumerate(["tcpin:127.0.0.1:5770", "udpin:0.0.0.0:14550", "udpout:127.0.0.1:14550",
                       "tcp:localhost:5760", "serial:/dev/ttyUSB0:57600", "tcpin:[::1]:0",
                       "tcpin:127.0.0.1:5770?trust=read-only&rate=50"]):
    write("link_url", f"url{i}", u)
for i, u in enumerate(["embedded", "replay:logs/flight.tlog?speed=2", "tcp:127.0.0.1:5760",
                       "serial:/dev/ttyACM0"]):
    write("vehicle_source", f"src{i}", u)

write("daemon_config", "default", (Path(__file__).parent.parent / "config" / "vtol-gcs.toml").read_text())
write("daemon_config", "small", 'vehicle = "tcp:127.0.0.1:5760"\nserve = ["tcpin:127.0.0.1:0"]\n'
      'log_dir = ""\nstatus_interval_s = 0.5\nqueue_len = 16\n')

gains = (Path(__file__).parent.parent / "config" / "gains.param").read_text()
write("param_file", "mavproxy", gains)
write("param_file", "missionplanner", "HOVER_ALT,1.5\nALT_KP,5\n")
write("param_file", "qgc", "# Onboard parameters\n1\t1\tHOVER_ALT\t1.5\t9\n1\t1\tSYSID_THISMAV\t1\t2\n")
write("twin_param_file", "gains", gains)
write("twin_param_file", "hex", "SYSID_THISMAV 0x2\nHOVER_ALT 1.25 # comment\n")

write("mission_file", "square", "QGC WPL 110\n"
      "0\t1\t0\t16\t0\t0\t0\t0\t-35.363261\t149.165230\t584.000000\t1\n"
      "1\t0\t3\t84\t0\t0\t0\t0\t0\t0\t2.000000\t1\n"
      "2\t0\t3\t16\t2\t0\t0\t0\t-35.363200\t149.165230\t2.000000\t1\n"
      "3\t0\t3\t85\t0\t0\t0\t0\t-35.363261\t149.165230\t0\t1\n")

write("signing_state", "state", 'key = "' + "00112233445566778899aabbccddeeff" * 2 + '"\ntimestamp = 37537847269913\n')

write("sim_cli_values", "initial", b"\x00phi=0.1,theta=0.1,psi=1,x=0.1,y=0.1,z=0.1")
write("sim_cli_values", "setpoint", b"\x01x=1,y=-2,z=1.5")
write("sim_cli_values", "param", b"\x02LAT_SAT_A=1.3")
write("sim_cli_values", "push", b"\x03roll=0.1@2:200")

# statustext: (severity, id, chunk_seq, 50 text bytes) per message, a chunked text of three
def st(sev, id_, seq, text):
    return bytes([sev]) + struct.pack("<H", id_) + bytes([seq]) + text.encode().ljust(50, b"\0")[:50]
long = "Arm: refused because the vehicle is not level enough; " * 2
write("statustext", "chunks", st(4, 7, 0, long[:50]) + st(4, 7, 1, long[50:100]) + st(4, 7, 2, long[100:]))
write("statustext", "single", st(6, 0, 0, "Rebooted"))


# twin_endpoint and tracker: [selector, length, payload] per frame (payload as the dialect packs it)
def payload_of(msg) -> tuple[int, bytes]:
    m = mav()
    buf = bytes(msg.pack(m))
    n = buf[1]
    return msg.get_msgId(), buf[10:10 + n]


def endpoint_input(msgs) -> bytes:
    out = b""
    for msg in msgs:
        mid, p = payload_of(msg)
        out += bytes([TWIN_READS.index(mid), len(p)]) + p
    return out


write("twin_endpoint", "params", endpoint_input([
    apm.MAVLink_param_request_list_message(1, 1),
    apm.MAVLink_param_set_message(1, 1, b"HOVER_ALT", 1.5, 9),
    apm.MAVLink_param_request_read_message(1, 1, b"", 3),
]))
write("twin_endpoint", "arm_fly", endpoint_input([
    apm.MAVLink_command_long_message(1, 1, 176, 0, 1, 18, 0, 0, 0, 0, 0),
    apm.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
    apm.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0xff8, 1, 2, -1, 0, 0, 0, 0, 0, 0, 0, 0),
    apm.MAVLink_rc_channels_override_message(1, 1, 1500, 1500, 1700, 1500, 0, 0, 0, 0),
    apm.MAVLink_command_long_message(1, 1, 246, 0, 1, 0, 0, 0, 0, 0, 0),
]))
write("twin_endpoint", "mission", endpoint_input([
    apm.MAVLink_mission_count_message(1, 1, 2, 0),
    apm.MAVLink_mission_item_int_message(1, 1, 0, 0, 16, 0, 1, 0, 0, 0, 0, -353632610, 1491652300, 584, 0),
    apm.MAVLink_mission_item_int_message(1, 1, 1, 3, 84, 0, 1, 0, 0, 0, 0, 0, 0, 2, 0),
    apm.MAVLink_mission_request_list_message(1, 1, 0),
    apm.MAVLink_mission_request_int_message(1, 1, 1, 0),
]))
write("twin_endpoint", "ftp_timesync", endpoint_input([
    apm.MAVLink_file_transfer_protocol_message(0, 1, 1, bytes([1, 0, 0, 3] + [0] * 247)),
    apm.MAVLink_timesync_message(0, 12345),
]))
TRACKED = [0, 30, 32, 36, 253]


def tracker_input(msgs) -> bytes:
    out = b""
    for msg in msgs:
        mid, p = payload_of(msg)
        out += bytes([TRACKED.index(mid), len(p)]) + p
    return out


write("tracker", "telemetry", tracker_input([
    apm.MAVLink_heartbeat_message(20, 17, 128 | 1, 18, 4, 3),
    apm.MAVLink_attitude_message(1000, 0.1, -0.2, 0.3, 0.01, 0.02, 0.03),
    apm.MAVLink_local_position_ned_message(1000, 1, 2, -1, 0, 0, 0),
    apm.MAVLink_servo_output_raw_message(1000, 0, 1680, 1681, 1500, 1500, 1503, 0, 0, 0),
    apm.MAVLink_statustext_message(4, b"Arm: refused because the vehicle is not level enough;", 7, 0),
    apm.MAVLink_attitude_message(10, 0.1, -0.2, 0.3, 0.01, 0.02, 0.03),
]))
