"""`vtol-gcs params|arm|disarm|mode` against the real twin, straight and through the daemon,
lossless and at 30 % frame loss each way (`firmware-sim serve --loss`), checked independently
with pymavlink. Exit status (docs/cli.md): 0 done, 1 refused (nothing changed), 2 usage or input
error, 3 no vehicle or link failure."""

from __future__ import annotations

import subprocess
import threading
import time
from pathlib import Path

import pytest

from conftest import MODES, MSG_LOCAL_POSITION_NED, Gcs, f32, start_twin
from daemon_support import DAEMON_BIN, daemon_factory, script  # noqa: F401

LOW_LATERAL = {"LAT_SAT_A": 0.4, "LAT_SAT_B": 0.2, "LAT_SAT_C": 0.1, "LAT_SAT_D": 0.05}
DEFAULT_LATERAL = {"LAT_SAT_A": 1.2, "LAT_SAT_B": 0.6, "LAT_SAT_C": 0.22, "LAT_SAT_D": 0.18}


def gcs(*args: str, link: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """Runs `vtol-gcs ARGS --link LINK`; a hang fails the test at `timeout`."""
    assert DAEMON_BIN.exists(), f"{DAEMON_BIN} missing: build it with `cargo build --workspace`"
    return subprocess.run(
        [str(DAEMON_BIN), *args, "--link", link],
        capture_output=True, text=True, timeout=timeout,
    )


def mavproxy_file(path: Path, values: dict[str, float]) -> Path:
    path.write_text("".join(f"{k} {v}\n" for k, v in values.items()))
    return path


def values_on(url: str, names) -> dict[str, float]:
    """What the vehicle holds, read by pymavlink (an independent check)."""
    with Gcs(url) as g:
        g.wait_vehicle_heartbeat()
        return {n: g.param_get(n).param_value for n in names}


def table(path: Path) -> dict[str, str]:
    """A QGroundControl file as name -> value text."""
    rows = [line.split("\t") for line in path.read_text().splitlines() if line and not line.startswith("#")]
    assert all(len(r) == 5 for r in rows), rows
    return {r[2]: r[3] for r in rows}


@pytest.fixture(scope="module")
def lossless(module_twin_factory):
    return module_twin_factory(speed=4)


@pytest.fixture(scope="module")
def lossy(module_twin_factory):
    """30 % of frames dropped in each direction."""
    return module_twin_factory(speed=4, extra=["--loss", "0.3"], seed=3)


@pytest.mark.parametrize("which", ["lossless", "lossy"])
def test_pull_then_push_same_file_writes_nothing(request, tmp_path, which):
    twin = request.getfixturevalue(which)
    f = tmp_path / "all.param"
    r = gcs("params", "pull", "-o", str(f), link=twin.tcp)
    assert r.returncode == 0, r.stderr
    t = table(f)
    # Every parameter: as many as the twin says it has (asked of the lossless twin by pymavlink;
    # both twins have the same table).
    with Gcs(request.getfixturevalue("lossless").tcp) as g:
        g.wait_vehicle_heartbeat()
        count = g.param_get("HOVER_ALT").param_count
    assert len(t) == count and t["LAT_SAT_C"] == "0.22", t
    r = gcs("params", "push", str(f), link=twin.tcp)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "0 changed", r.stdout


@pytest.mark.parametrize("which", ["lossless", "lossy"])
def test_one_order_file_is_applied_and_verified(request, tmp_path, which):
    twin = request.getfixturevalue(which)
    f = mavproxy_file(tmp_path / "low.param", LOW_LATERAL)
    r = gcs("params", "push", str(f), link=twin.tcp)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "4 changed" in r.stdout, r.stdout
    # Written from d up: the only order in which every intermediate set is acceptable.
    order = [line.split()[0] for line in r.stdout.splitlines() if "->" in line]
    assert order == ["LAT_SAT_D", "LAT_SAT_C", "LAT_SAT_B", "LAT_SAT_A"], r.stdout
    if which == "lossless":
        assert values_on(twin.tcp, LOW_LATERAL) == {k: f32(v) for k, v in LOW_LATERAL.items()}
    back = mavproxy_file(tmp_path / "back.param", DEFAULT_LATERAL)
    r = gcs("params", "push", str(back), link=twin.tcp)
    assert r.returncode == 0 and "4 changed" in r.stdout, r.stdout + r.stderr


@pytest.mark.parametrize("which", ["lossless", "lossy"])
def test_file_breaking_the_conditions_changes_nothing(request, tmp_path, which):
    twin = request.getfixturevalue(which)
    before = tmp_path / "before.param"
    assert gcs("params", "pull", "-o", str(before), link=twin.tcp).returncode == 0
    f = tmp_path / "bad.param"
    f.write_text("ALT_KP,6\nLAT_SAT_B,2\n")  # Mission Planner format
    if which == "lossless":
        r = gcs("params", "push", str(f), "--dry-run", link=twin.tcp)
        # A plan expected to be refused: exit 1, as the push itself would.
        assert r.returncode == 1 and "LAT_SAT_B: likely refused" in r.stdout, r.stdout + r.stderr
    r = gcs("params", "push", str(f), link=twin.tcp)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "LAT_SAT_B" in r.stderr and "refused" in r.stderr, r.stderr
    if which == "lossless":
        assert "a > b + c + d" in r.stderr, r.stderr
    after = tmp_path / "after.param"
    assert gcs("params", "pull", "-o", str(after), link=twin.tcp).returncode == 0
    assert table(after) == table(before)


BAD_FILES = [
    ("ALT_KP 7\nLAT_SAT_B 0.5 0.6\n", 2, "column"),
    ("ALT_KP 7\nLAT_SAT_B nan\n", 2, "not finite"),
    ("ALT_KP 7\n# x\nLAT_SAT_B inf\n", 3, "not finite"),
    ("ALT_KP 7\nALT_KP 8\n", 2, "twice"),
    ("ALT_KP 7\nLAT_SAT_B zero\n", 2, "not a number"),
    ("ALT_KP,7\nNO_SUCH_PARAM,1\n", 2, "no parameter NO_SUCH_PARAM"),
    ("1\t1\tALT_KP\t7\t9\n1\t1\tHOVER_ALT\t1\n", 2, "column"),
]


@pytest.mark.parametrize("text,line,what", BAD_FILES)
def test_bad_file_gets_a_line_numbered_error_and_nothing_is_sent(lossless, tmp_path, text, line, what):
    f = tmp_path / "bad.param"
    f.write_text(text)
    r = gcs("params", "push", str(f), link=lossless.tcp)
    assert r.returncode == 2, r.stdout + r.stderr
    assert what in r.stderr and (f":{line}:" in r.stderr or f"line {line}:" in r.stderr), r.stderr
    assert values_on(lossless.tcp, ["ALT_KP"]) == {"ALT_KP": 5.0}


def test_get_set_and_usage_errors(lossless):
    r = gcs("params", "set", "HOVER_ALT", "1.25", link=lossless.tcp)
    assert r.returncode == 0 and "1 changed" in r.stdout, r.stdout + r.stderr
    r = gcs("params", "get", "HOVER_ALT", "LAT_SAT_C", link=lossless.tcp)
    assert r.returncode == 0 and r.stdout.split() == ["HOVER_ALT", "1.25", "LAT_SAT_C", "0.22"], r.stdout
    r = gcs("params", "set", "HOVER_ALT", "1", link=lossless.tcp)
    assert r.returncode == 0, r.stderr
    assert gcs("params", "get", "NO_SUCH_PARAM", link=lossless.tcp).returncode == 2
    assert gcs("params", "set", "HOVER_ALT", "nan", link=lossless.tcp).returncode == 2
    assert gcs("mode", "NOT_A_MODE", link=lossless.tcp).returncode == 2
    # Nothing listening there: a link failure at once, not a hang.
    r = gcs("params", "pull", link="tcp:127.0.0.1:9", timeout=30)
    assert r.returncode == 3 and "cannot connect to tcp:127.0.0.1:9" in r.stderr, r.stderr


def test_arm_refused_by_a_prearm_check_gives_the_reason(twin_factory):
    # At 1 % of real time the hardware's 1 s gyro calibration after power-up lasts 100 s.
    slow = twin_factory(speed=0.01, extra=["--boot-calibration"])
    r = gcs("arm", link=slow.tcp)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "PreArm" in r.stderr and "calibration" in r.stderr, r.stderr


def test_mode_qhover_then_arm_takes_off(twin_factory):
    t = twin_factory(speed=2)
    with Gcs(t.tcp) as g:
        g.wait_ready()
        g.set_interval(MSG_LOCAL_POSITION_NED, 10)
        r = gcs("mode", "QHOVER", link=t.tcp)
        assert r.returncode == 0, r.stderr
        r = gcs("arm", link=t.tcp)
        assert r.returncode == 0, r.stderr
        assert r.stdout.strip() == "armed in QHOVER", r.stdout  # the mode it armed in
        p = g.recv("LOCAL_POSITION_NED", lambda p: -p.z > 0.5, timeout=30, what="altitude above 0.5 m")
        assert -p.z > 0.5
        r = gcs("mode", "QLAND", link=t.tcp)
        assert r.returncode == 0, r.stderr


def test_pull_and_push_through_the_daemon_beside_a_busy_script(daemon_factory, tmp_path):  # noqa: F811
    d = daemon_factory(serve=["tcpin:127.0.0.1:0"], log=False)
    s = script(d.tcp)
    s.wait_vehicle_heartbeat()
    errors: list[str] = []
    reads = 0
    stop = threading.Event()

    def busy():
        # The script's own reads, one after another, each answered with the right value.
        nonlocal reads
        while not stop.is_set():
            s.m.mav.param_request_read_send(1, 1, b"ALT_KD", -1)
            try:
                p = s.recv("PARAM_VALUE", lambda p: p.param_id == "ALT_KD", timeout=5)
            except AssertionError as e:
                errors.append(str(e))
                return
            if p.param_value != 2.0:
                errors.append(f"ALT_KD read {p.param_value}")
            reads += 1

    th = threading.Thread(target=busy)
    th.start()
    try:
        f = tmp_path / "all.param"
        assert gcs("params", "pull", "-o", str(f), link=d.tcp).returncode == 0
        r = gcs("params", "push", str(f), link=d.tcp)
        assert r.returncode == 0 and "0 changed" in r.stdout, r.stdout + r.stderr
        low = mavproxy_file(tmp_path / "low.param", LOW_LATERAL)
        r = gcs("params", "push", str(low), link=d.tcp)
        assert r.returncode == 0 and "4 changed" in r.stdout, r.stdout + r.stderr
        back = mavproxy_file(tmp_path / "back.param", DEFAULT_LATERAL)
        assert gcs("params", "push", str(back), link=d.tcp).returncode == 0
    finally:
        stop.set()
        th.join(timeout=20)
        s.close()
    assert not errors, errors
    assert reads > 5, f"the script completed only {reads} reads"


@pytest.mark.parametrize("path", ["daemon", "direct"])
def test_gcs_failsafe_runs_when_every_operator_has_gone(twin_factory, daemon_factory, path):  # noqa: F811
    """FS_GCS_ENABL=1: while a client with its own heartbeat is connected the twin keeps
    hovering; once every client has gone it switches to QLAND within FS_GCS_TIMEOUT + 1 s, through
    the daemon exactly as straight to the twin (the daemon's own client sends no heartbeat
    without an operator)."""
    timeout_s = 2.0
    if path == "daemon":
        url = daemon_factory(serve=["tcpin:127.0.0.1:0"], log=False).tcp
    else:
        url = twin_factory(speed=1).tcp
    pilot = script(url) if path == "daemon" else Gcs(url)
    pilot.wait_ready()
    pilot.param_set("FS_GCS_ENABL", 1)
    pilot.param_set("FS_GCS_TIMEOUT", timeout_s)
    pilot.set_interval(MSG_LOCAL_POSITION_NED, 10)
    assert pilot.command(400, 1).result == 0
    assert pilot.command(176, 1, MODES["QHOVER"]).result == 0
    pilot.recv("LOCAL_POSITION_NED", lambda p: -p.z > 0.3, timeout=30, what="take-off")
    # An observer that never sends a heartbeat: it watches the mode, it is no operator.
    from pymavlink import mavutil

    watcher = mavutil.mavlink_connection(url, source_system=254)
    try:
        # Pilot present (heartbeats while waiting): no failsafe for longer than the timeout.
        end = time.monotonic() + timeout_s + 2
        while time.monotonic() < end:
            m = pilot.recv(["HEARTBEAT", "STATUSTEXT"], timeout=5)
            assert m.get_type() == "HEARTBEAT" or "Failsafe" not in m.text, m
            if m.get_type() == "HEARTBEAT":
                assert m.custom_mode == MODES["QHOVER"], f"mode {m.custom_mode} while the pilot is connected"
        pilot.close()
        t_gone = time.monotonic()
        # The switch is the moment of the twin's failsafe STATUSTEXT (or, if that frame is
        # missed, the first QLAND heartbeat, which follows within a second at 1 Hz).
        deadline = t_gone + timeout_s + 1
        switched = None
        while switched is None:
            left = deadline - time.monotonic()
            assert left > 0, "no QLAND within FS_GCS_TIMEOUT + 1 s of the last client leaving"
            m = watcher.recv_match(type=["HEARTBEAT", "STATUSTEXT"], blocking=True, timeout=left)
            if m is None or m.get_srcSystem() != 1:
                continue
            if m.get_type() == "STATUSTEXT" and "Failsafe" in m.text:
                switched = m
            elif m.get_type() == "HEARTBEAT" and m.custom_mode == MODES["QLAND"]:
                switched = m
        h = watcher.recv_match(type="HEARTBEAT", blocking=True, timeout=5,
                               condition=f"HEARTBEAT.custom_mode=={MODES['QLAND']}")
        assert h is not None, "the vehicle does not report QLAND after the failsafe"
    finally:
        watcher.close()


def test_shipped_gains_file_matches_the_twin_defaults(lossless):
    gains = Path(__file__).resolve().parents[2] / "config" / "gains.param"
    r = gcs("params", "diff", str(gains), link=lossless.tcp)
    assert r.returncode == 0 and r.stdout.strip() == "0 differ", r.stdout + r.stderr
