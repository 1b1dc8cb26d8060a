#!/usr/bin/env bash
# User-space instructions per forwarded frame of the daemon, by function (valgrind callgrind).
#
#   benches/tools/forwarding_instructions.sh [BINARY]      (default target/release/vtol-gcs)
#
# Runs `vtol-gcs run --vehicle udpin --serve udpout --log-dir TMP --headless` under callgrind
# twice, forwarding 2 000 and then 12 000 MAVLink 2 ATTITUDE frames at 1 000/s (a lone datagram
# per wake-up, the 10k/s path), and prints the difference over the 10 000 extra frames: start-up
# and shutdown cancel out. Deterministic, unlike CPU time on a shared VM, but it counts
# instructions, not cache misses. Needs valgrind and the test venv (tests/run.sh makes it).
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=${1:-$root/target/release/vtol-gcs}
py=$root/.venv/bin/python
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

free_port() { "$py" -c 'import socket; s=socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

run() { # frames tag
    local n=$1 tag=$2 port sink
    port=$(free_port); sink=$(free_port)
    mkdir -p "$tmp/log_$tag"
    valgrind --tool=callgrind --callgrind-out-file="$tmp/cg_$tag.out" "$bin" run \
        --vehicle "udpin:127.0.0.1:$port" --serve "udpout:127.0.0.1:$sink" \
        --log-dir "$tmp/log_$tag" --headless > "$tmp/daemon_$tag.log" 2>&1 &
    local daemon=$!
    "$py" - "$port" "$sink" "$n" <<'PY'
import socket, sys, threading, time
from pymavlink.dialects.v20 import common as m
port, sink_port, n = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
mav = m.MAVLink(None, srcSystem=1, srcComponent=1)
frames = [mav.attitude_encode(i, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6).pack(mav) for i in range(256)]
sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sink.bind(("127.0.0.1", sink_port))
out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
# Until the daemon (slow under valgrind) forwards a first frame.
sink.settimeout(0.5)
while True:
    out.sendto(frames[0], ("127.0.0.1", port))
    try:
        sink.recv(2048)
        break
    except socket.timeout:
        pass
got = [0]
def rx():
    sink.settimeout(5)
    try:
        while True:
            sink.recv(2048)
            got[0] += 1
    except socket.timeout:
        pass
t = threading.Thread(target=rx)
t.start()
t0 = time.monotonic()
for i in range(n):
    delay = t0 + i / 1000 - time.monotonic()
    if delay > 0:
        time.sleep(delay)
    out.sendto(frames[i % 256], ("127.0.0.1", port))
t.join()
if got[0] < n:
    sys.exit(f"only {got[0]} of {n} frames came through")
PY
    kill -TERM "$daemon"
    wait "$daemon" || true
}

run 2000 small
run 12000 big
"$py" - "$tmp/cg_small.out" "$tmp/cg_big.out" 10000 <<'PY'
import re, subprocess, sys
def load(path, inclusive):
    out = subprocess.run(["callgrind_annotate", "--threshold=100", "--auto=no", "--tree=none",
                          f"--inclusive={'yes' if inclusive else 'no'}", path],
                         capture_output=True, text=True, check=True).stdout
    total, by_fn = 0, {}
    for line in out.splitlines():
        m = re.match(r"\s*([\d,]+) \(\s*[\d.]+%\)\s+(.*)", line)
        if not m:
            continue
        v, name = int(m.group(1).replace(",", "")), m.group(2)
        if "PROGRAM TOTALS" in name:
            total = v
            continue
        name = re.sub(r" \[.*\]$", "", re.sub(r"^.*?:", "", name, count=1))
        by_fn[name] = max(by_fn.get(name, 0), v) if inclusive else by_fn.get(name, 0) + v
    return total, by_fn
small, big, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
(t0, ex0), (t1, ex1) = load(small, False), load(big, False)
_, in0 = load(small, True)
_, in1 = load(big, True)
print(f"user-space instructions per forwarded frame: {(t1 - t0) / n:.0f}")
for label, pat in [("UDP reader thread (receive, decode, route, log, send)", "udpin_blocking"),
                   ("tracker task", "vehicle::run::{{closure}}"),
                   ("tlog writer thread", "tlog::writer_loop")]:
    k = next((k for k in in1 if pat in k and k.endswith(pat.split("::")[-1])), None)
    if k:
        print(f"  {label}: {(in1[k] - in0.get(k, 0)) / n:.0f}")
print("largest functions (self, per frame):")
rows = sorted(((ex1.get(k, 0) - ex0.get(k, 0)) / n, k) for k in set(ex0) | set(ex1))
for v, k in reversed(rows[-20:]):
    print(f"  {v:7.0f}  {k[:110]}")
PY
