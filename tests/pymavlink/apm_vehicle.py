"""An ArduPilot parameter server, from a recording of ArduPlane SITL's table.

`ApmVehicle(data)` listens on a loopback TCP port (0: a free one) and answers as ArduPilot's
GCS_Param.cpp and AP_Filesystem_Param.cpp do, from `data/arduplane_params.json` (recorded from
ArduPlane 4.7 SITL, a QuadPlane tailsitter, by tests/sitl/record_params.py):

- HEARTBEAT 1 Hz as ArduPlane (type FIXED_WING, autopilot ARDUPILOTMEGA); TIMESYNC answered;
  AUTOPILOT_VERSION on request, with MAV_PROTOCOL_CAPABILITY_FTP when `ftp` is on.
- PARAM_REQUEST_LIST restarts the stream at index 0. The stream goes out from the main loop
  (`TICK_S`) paced as the recording shows it arriving: bursts of about 220 values, each
  followed by a pause of about 100 ms (`stream_pacing`); a tick's replies to reads take the
  place of stream values.
- PARAM_REQUEST_READ goes into a queue of 20 requests shared by all links (a request that finds
  it full is dropped); the IO thread (`IO_TICK_S`) moves one at a time into a reply queue of 5,
  and the main loop sends up to 5 replies a tick. A reply carries the index asked for: -1
  (65535) for a read by name.
- PARAM_SET: a read-only or internal parameter is refused with the STATUSTEXT "Param write
  denied (NAME)" and an echo of its unchanged value; otherwise the value is stored as its type
  holds it (integers: +/-0.01 then truncated, clamped to the type's range; floats: float32)
  and echoed with index -1 to every link. An unknown name or a non-finite value is ignored.
  Setting an enable parameter (`variants` in the recording) changes the table and its count.
- MAVLink FTP: `@PARAM/param.pck` (OpenFileRO, ReadFile, BurstReadFile, TerminateSession,
  ResetSessions), packed as AP_Filesystem_Param.cpp packs it; any other path is a NAK
  FileNotFound.

Values are kept as float32, the way the vehicle sends them.
"""

from __future__ import annotations

import json
import math
import os
import socket
import struct
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402

DATA = Path(__file__).resolve().parent / "data" / "arduplane_params.json"

TICK_S = 0.0025  # ArduPlane's 400 Hz main loop
IO_TICK_S = 0.001  # the IO thread, 1 kHz
STREAM_BURST_PER_TICK = 60  # a burst's values go out over a few ticks
REQUEST_QUEUE = 20
REPLY_QUEUE = 5
REPLIES_PER_TICK = 5

INT_TYPES = {
    apm.MAV_PARAM_TYPE_INT8: (-128, 127, 1, "b"),
    apm.MAV_PARAM_TYPE_INT16: (-32768, 32767, 2, "h"),
    apm.MAV_PARAM_TYPE_INT32: (-2147483648, 2147483647, 4, "i"),
}
# AP_Param type ids in param.pck
PCK_TYPE = {apm.MAV_PARAM_TYPE_INT8: 1, apm.MAV_PARAM_TYPE_INT16: 2, apm.MAV_PARAM_TYPE_INT32: 3,
            apm.MAV_PARAM_TYPE_REAL32: 4}

FTP_ACK, FTP_NAK = 128, 129
FTP_TERMINATE, FTP_RESET, FTP_OPEN_RO, FTP_READ, FTP_BURST = 1, 2, 4, 5, 15
FTP_ERR_FAIL, FTP_ERR_EOF, FTP_ERR_UNKNOWN, FTP_ERR_NOT_FOUND = 1, 6, 4, 10
FTP_DATA = 239


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def stored(ty: int, value: float) -> float:
    """What ArduPilot's AP_Param::set_float stores for `value` (as a float32 on the wire)."""
    if ty in INT_TYPES:
        lo, hi, _, _ = INT_TYPES[ty]
        v = value + (0.01 if value >= 0 else -0.01)
        v = min(max(v, lo), hi)
        return float(int(v))
    return f32(value)


def stream_pacing(arrival_s: list[float]) -> tuple[int, float]:
    """(values per burst, pause after each) of a recorded stream: the pauses are the gaps over
    30 ms after the first value."""
    gaps = [(i, arrival_s[i] - arrival_s[i - 1]) for i in range(2, len(arrival_s))
            if arrival_s[i] - arrival_s[i - 1] > 0.03]
    if len(gaps) < 2:
        return 1 << 30, 0.0
    starts = [i for i, _ in gaps]
    bursts = sorted(b - a for a, b in zip(starts, starts[1:]))
    pauses = sorted(g for _, g in gaps)
    return bursts[len(bursts) // 2], pauses[len(pauses) // 2]


def pack_table(table: list[list], read_size: int = FTP_DATA) -> bytes:
    """`@PARAM/param.pck`: header (magic 0x671b, count, count), then per parameter a type byte,
    a byte of (name bytes shared with the previous name, new name bytes - 1), the new name
    bytes and the value; zero pad bytes keep a value from crossing a `read_size` boundary."""
    out = bytearray(struct.pack("<HHH", 0x671B, len(table), len(table)))
    last = b""
    for name, ty, value in table:
        raw = name.encode()
        common = 0
        while common < min(len(raw), len(last), 15) and raw[common] == last[common]:
            common += 1
        if common == len(raw):
            common -= 1
        rest = raw[common:]
        if ty in INT_TYPES:
            size, fmt = INT_TYPES[ty][2], INT_TYPES[ty][3]
            data = struct.pack("<" + fmt, int(value))
        else:
            size, data = 4, struct.pack("<f", value)
        packed = 2 + len(rest) + size
        if size > 1:
            ofs_mod = (len(out) + packed) % read_size
            if 0 < ofs_mod < size:
                out += bytes(size - ofs_mod)
        out += bytes([PCK_TYPE[ty], common | ((len(rest) - 1) << 4)]) + rest + data
        last = raw
    return bytes(out)


class _Writer:
    """A file-like sink for pymavlink that writes to one connection."""

    def __init__(self, conn: socket.socket):
        self.conn = conn
        self.lock = threading.Lock()
        self.closed = False

    def write(self, data: bytes) -> None:
        if self.closed:
            return
        try:
            with self.lock:
                self.conn.sendall(data)
        except OSError:
            self.closed = True


class _Link:
    def __init__(self, vehicle: "ApmVehicle", conn: socket.socket):
        self.vehicle = vehicle
        self.conn = conn
        self.writer = _Writer(conn)
        self.mav = apm.MAVLink(self.writer, srcSystem=vehicle.sysid, srcComponent=1)
        self.mav.robust_parsing = True
        self.parser = apm.MAVLink(None, srcSystem=vehicle.sysid, srcComponent=1)
        self.parser.robust_parsing = True
        self.stream_index: int | None = None
        self.stream_count = 0
        self.burst_left = 0
        self.resume_at = 0.0
        self.ftp_file: bytes | None = None
        self.ftp_session = 0


class ApmVehicle:
    """ArduPilot's parameter server on a loopback TCP port, from a recording."""

    def __init__(self, data: Path | dict = DATA, ftp: bool = True, sysid: int = 1, port: int = 0):
        rec = json.loads(Path(data).read_text()) if not isinstance(data, dict) else data
        self.recording = rec
        self.base = [[n, int(t), f32(v)] for n, t, v in rec["params"]]
        self.variants = rec.get("variants", {})
        self.read_only = set(rec.get("read_only", []))
        self.values = {n: v for n, _, v in self.base}
        self.types = {n: t for n, t, _ in self.base}
        for var in self.variants.values():
            for _, n, t, v in var["inserted"]:
                self.values.setdefault(n, f32(v))
                self.types.setdefault(n, int(t))
        self.burst, self.pause = stream_pacing(rec.get("arrival_s", []))
        self.ftp = ftp
        self.sysid = sysid
        self.lock = threading.Lock()
        self.links: list[_Link] = []
        self.requests: list[tuple[_Link, int, str]] = []
        self.replies: list[tuple[_Link, str, float, int, int, int]] = []
        self.stop_event = threading.Event()
        self.sets: list[tuple[str, float]] = []  # every PARAM_SET applied (name, stored value)
        self.list_requests = 0
        self.read_requests = 0
        self.dropped_reads = 0
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind(("127.0.0.1", port))
        self.srv.listen(4)
        self.port = self.srv.getsockname()[1]
        self.threads = [threading.Thread(target=f, daemon=True)
                        for f in (self._accept, self._main_loop, self._io_loop)]
        for t in self.threads:
            t.start()

    @property
    def url(self) -> str:
        return f"tcp:127.0.0.1:{self.port}"

    # -- the table ---------------------------------------------------------------------------

    def table(self) -> list[list]:
        """The parameters in index order, as the vehicle holds them now (enabled variants in)."""
        rows = [list(r) for r in self.base]
        for name, var in self.variants.items():
            if self.values.get(name, 0.0) != 0.0:
                for index, n, t, _ in sorted(var["inserted"]):
                    rows.insert(index, [n, int(t), None])
        for r in rows:
            r[2] = self.values[r[0]]
        return rows

    def close(self) -> None:
        self.stop_event.set()
        try:
            self.srv.close()
        except OSError:
            pass
        for link in list(self.links):
            try:
                link.conn.close()
            except OSError:
                pass
        for t in self.threads:
            t.join(timeout=5)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- threads ---------------------------------------------------------------------------

    def _accept(self) -> None:
        self.srv.settimeout(0.2)
        while not self.stop_event.is_set():
            try:
                conn, _ = self.srv.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            link = _Link(self, conn)
            with self.lock:
                self.links.append(link)
            threading.Thread(target=self._read, args=(link,), daemon=True).start()

    def _read(self, link: _Link) -> None:
        link.conn.settimeout(0.2)
        while not self.stop_event.is_set():
            try:
                data = link.conn.recv(4096)
            except socket.timeout:
                continue
            except OSError:
                break
            if not data:
                break
            for msg in link.parser.parse_buffer(data) or []:
                with self.lock:
                    self._handle(link, msg)
        with self.lock:
            if link in self.links:
                self.links.remove(link)
        link.writer.closed = True

    def _main_loop(self) -> None:
        next_tick = time.monotonic()
        next_beat = next_tick
        while not self.stop_event.is_set():
            now = time.monotonic()
            if now < next_tick:
                time.sleep(next_tick - now)
                continue
            next_tick += TICK_S
            if next_tick < now - 0.1:
                next_tick = now
            with self.lock:
                if now >= next_beat:
                    next_beat += 1.0
                    for link in self.links:
                        link.mav.heartbeat_send(apm.MAV_TYPE_FIXED_WING, apm.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, apm.MAV_STATE_STANDBY)
                self._send_params()

    def _io_loop(self) -> None:
        while not self.stop_event.is_set():
            time.sleep(IO_TICK_S)
            with self.lock:
                if len(self.replies) >= REPLY_QUEUE or not self.requests:
                    continue
                link, index, name = self.requests.pop(0)
                table = self.table()
                if index != -1:
                    if not 0 <= index < len(table):
                        continue
                    name, ty, value = table[index]
                elif name in self.values and any(r[0] == name for r in table):
                    ty, value = self.types[name], self.values[name]
                else:
                    continue
                self.replies.append((link, name, value, ty, len(table), index))

    # -- sending ---------------------------------------------------------------------------

    def _send_params(self) -> None:
        sent: dict[int, int] = {}
        for _ in range(REPLIES_PER_TICK):
            if not self.replies:
                break
            link, name, value, ty, count, index = self.replies.pop(0)
            link.mav.param_value_send(name.encode(), value, ty, count, index & 0xFFFF)
            sent[id(link)] = sent.get(id(link), 0) + 1
        now = time.monotonic()
        for link in self.links:
            if link.stream_index is None or now < link.resume_at:
                continue
            if link.burst_left <= 0:
                link.burst_left = self.burst
            budget = STREAM_BURST_PER_TICK - sent.get(id(link), 0)
            table = self.table()
            while budget > 0 and link.stream_index is not None:
                if link.stream_index >= len(table):
                    link.stream_index = None
                    break
                name, ty, value = table[link.stream_index]
                link.mav.param_value_send(name.encode(), value, ty, link.stream_count, link.stream_index)
                link.stream_index += 1
                budget -= 1
                link.burst_left -= 1
                if link.burst_left <= 0:
                    link.resume_at = now + self.pause
                    break

    def _echo(self, name: str) -> None:
        count = len(self.table())
        for link in self.links:
            link.mav.param_value_send(name.encode(), self.values[name], self.types[name], count, 0xFFFF)

    # -- handling ----------------------------------------------------------------------------

    def _handle(self, link: _Link, msg) -> None:
        t = msg.get_type()
        if t == "PARAM_REQUEST_LIST":
            self.list_requests += 1
            link.stream_index = 0
            link.stream_count = len(self.table())
            link.burst_left = self.burst
            link.resume_at = time.monotonic() + TICK_S
        elif t == "PARAM_REQUEST_READ":
            self.read_requests += 1
            if len(self.requests) >= REQUEST_QUEUE:
                self.dropped_reads += 1
                return
            name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
            self.requests.append((link, msg.param_index, name.rstrip("\0")))
        elif t == "PARAM_SET":
            self._param_set(link, msg)
        elif t == "TIMESYNC" and msg.tc1 == 0:
            link.mav.timesync_send(time.monotonic_ns(), msg.ts1)
        elif t == "COMMAND_LONG":
            self._command(link, msg)
        elif t == "FILE_TRANSFER_PROTOCOL":
            self._ftp(link, msg)

    def _param_set(self, link: _Link, msg) -> None:
        name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
        name = name.rstrip("\0")
        if name not in self.values or not any(r[0] == name for r in self.table()):
            return
        if not math.isfinite(msg.param_value):
            return
        if name in self.read_only:
            link.mav.statustext_send(apm.MAV_SEVERITY_WARNING, f"Param write denied ({name})".encode())
            count = len(self.table())
            link.mav.param_value_send(name.encode(), self.values[name], self.types[name], count, 0xFFFF)
            return
        value = stored(self.types[name], msg.param_value)
        self.values[name] = value
        self.sets.append((name, value))
        self._echo(name)

    def _command(self, link: _Link, msg) -> None:
        if msg.command == apm.MAV_CMD_REQUEST_MESSAGE and int(msg.param1) == apm.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            caps = (apm.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | apm.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                    | apm.MAV_PROTOCOL_CAPABILITY_MISSION_INT | apm.MAV_PROTOCOL_CAPABILITY_COMMAND_INT)
            if self.ftp:
                caps |= apm.MAV_PROTOCOL_CAPABILITY_FTP
            link.mav.command_ack_send(msg.command, apm.MAV_RESULT_ACCEPTED)
            link.mav.autopilot_version_send(caps, 0x04070000, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0)
        else:
            link.mav.command_ack_send(msg.command, apm.MAV_RESULT_UNSUPPORTED)

    # -- FTP -----------------------------------------------------------------------------------

    def _ftp(self, link: _Link, msg) -> None:
        p = bytes(msg.payload)
        seq, session, opcode, size, _req, _burst, _pad, offset = struct.unpack("<HBBBBBBI", p[:12])
        data = p[12:12 + size]

        def reply(op: int, body: bytes = b"", ofs: int = 0, burst_complete: int = 0, seq_add: int = 1):
            hdr = struct.pack("<HBBBBBBI", (seq + seq_add) & 0xFFFF, session, op, len(body), opcode,
                              burst_complete, 0, ofs)
            payload = (hdr + body).ljust(251, b"\0")
            link.mav.file_transfer_protocol_send(0, 0, 0, list(payload))

        def nak(code: int):
            reply(FTP_NAK, bytes([code]))

        if opcode in (FTP_ACK, FTP_NAK):
            return
        if not self.ftp:
            nak(FTP_ERR_NOT_FOUND)
            return
        if opcode == FTP_RESET:
            link.ftp_file = None
            reply(FTP_ACK)
        elif opcode == FTP_TERMINATE:
            link.ftp_file = None
            reply(FTP_ACK)
        elif opcode == FTP_OPEN_RO:
            path = data.split(b"\0")[0].decode(errors="replace")
            if not path.startswith("@PARAM/param.pck"):
                nak(FTP_ERR_NOT_FOUND)
                return
            link.ftp_file = pack_table(self.table())
            link.ftp_session = session
            reply(FTP_ACK, struct.pack("<I", len(link.ftp_file)))
        elif opcode in (FTP_READ, FTP_BURST):
            f = link.ftp_file
            if f is None or session != link.ftp_session:
                nak(FTP_ERR_FAIL)
                return
            if offset >= len(f):
                nak(FTP_ERR_EOF)
                return
            if opcode == FTP_READ:
                reply(FTP_ACK, f[offset:offset + min(size or FTP_DATA, FTP_DATA)], offset)
                return
            ofs, n = offset, 0
            while ofs < len(f):
                chunk = f[ofs:ofs + FTP_DATA]
                last = ofs + len(chunk) >= len(f)
                reply(FTP_ACK, chunk, ofs, burst_complete=1 if last else 0, seq_add=1 + n)
                ofs += len(chunk)
                n += 1
            # The read after the last byte fails: a NAK EndOfFile ends every burst.
            reply(FTP_NAK, bytes([FTP_ERR_EOF]), ofs, seq_add=1 + n)
        else:
            nak(FTP_ERR_UNKNOWN)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--port", type=int, default=5760)
    ap.add_argument("--no-ftp", action="store_true")
    a = ap.parse_args()
    v = ApmVehicle(ftp=not a.no_ftp, port=a.port)
    print(f"listening tcp:127.0.0.1:{v.port}", flush=True)
    try:
        v.stop_event.wait()
    except KeyboardInterrupt:
        v.close()
