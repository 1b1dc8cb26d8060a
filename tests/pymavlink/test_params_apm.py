"""`vtol-gcs params` against ArduPilot's parameter conventions, without SITL: apm_vehicle.py
answers as ArduPlane 4.7 does, from the table recorded from its SITL (1 566 parameters; a read
queue of 20 that drops what does not fit; a stream of 5 values a tick; echoes with index 65535;
"Param write denied" refusals; integers clamped to their type; float32 values; the table
growing when Q_TILT_ENABLE is set; `@PARAM/param.pck` over MAVLink FTP), through the daemon as
a user runs it (`vtol-gcs run --vehicle tcp:...`)."""

from __future__ import annotations

import struct
import subprocess
import threading
from pathlib import Path

import pytest

from apm_vehicle import ApmVehicle, f32
from daemon_support import DAEMON_BIN, daemon_factory  # noqa: F401

GAINS = ["Q_A_RAT_RLL_P", "Q_A_RAT_RLL_I", "Q_A_RAT_RLL_D", "Q_A_RAT_PIT_P", "Q_A_RAT_PIT_I",
         "Q_A_RAT_PIT_D", "Q_A_RAT_YAW_P", "Q_A_RAT_YAW_I"]


def gcs(*args: str, link: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """`vtol-gcs ARGS --link LINK`; a hang fails the test at `timeout`."""
    assert DAEMON_BIN.exists(), f"{DAEMON_BIN} missing: build it with `cargo build --workspace`"
    return subprocess.run([str(DAEMON_BIN), *args, "--link", link], capture_output=True, text=True,
                          timeout=timeout)


def qgc_table(path: Path) -> dict[str, tuple[float, int]]:
    """A QGroundControl file: name -> (value, MAV_PARAM_TYPE)."""
    out = {}
    for line in path.read_text().splitlines():
        if line and not line.startswith("#"):
            _, _, name, value, ty = line.split("\t")
            out[name] = (float(value), int(ty))
    return out


def same_f32(a: float, b: float) -> bool:
    return struct.pack("<f", a) == struct.pack("<f", b)


@pytest.fixture(params=["param-protocol", "ftp"])
def apm(request):
    with ApmVehicle(ftp=request.param == "ftp") as v:
        yield v


@pytest.fixture
def link(apm, daemon_factory):  # noqa: F811
    d = daemon_factory(vehicle=apm.url, serve=["tcpin:127.0.0.1:0"], log=False)
    return f"tcp:{d.serving[0][1]}"


def test_pull_reads_every_parameter_as_the_vehicle_holds_it(apm, link, tmp_path):
    out = tmp_path / "all.params"
    r = gcs("params", "pull", "-o", str(out), link=link)
    assert r.returncode == 0, r.stderr
    got = qgc_table(out)
    want = apm.table()
    assert len(got) == len(want) == apm.recording["param_count"]
    for name, ty, value in want:
        v, t = got[name]
        assert t == ty, name
        assert same_f32(v, value), (name, v, value)
    if apm.ftp:
        assert apm.list_requests == 0, "the table came as a file"
    # Never more reads than ArduPilot's queue holds: none were dropped.
    assert apm.dropped_reads == 0, f"{apm.dropped_reads} of {apm.read_requests} reads dropped"


def test_get_answers_while_another_pull_runs(apm, link):
    pulls = []
    t = threading.Thread(target=lambda: pulls.append(gcs("params", "pull", link=link)))
    t.start()
    r = gcs("params", "get", "Q_A_RAT_RLL_P", "Q_TAILSIT_ENABLE", link=link, timeout=30)
    t.join(timeout=60)
    assert r.returncode == 0, r.stderr
    words = r.stdout.split()
    assert words[0::2] == ["Q_A_RAT_RLL_P", "Q_TAILSIT_ENABLE"], r.stdout
    for name, text in zip(words[0::2], words[1::2]):
        assert same_f32(float(text), apm.values[name]), (name, text)
    assert pulls and pulls[0].returncode == 0, pulls[0].stderr if pulls else "no pull"


def test_set_is_verified_as_float32_and_not_rolled_back(apm, link):
    before = apm.values["Q_A_RAT_RLL_P"]
    r = gcs("params", "set", "Q_A_RAT_RLL_P", "0.26", link=link)
    assert r.returncode == 0, r.stderr + r.stdout
    assert "1 changed" in r.stdout
    assert apm.values["Q_A_RAT_RLL_P"] == f32(0.26)
    # One value written and never restored; the same write may go again when its echo is slow
    # (a loaded machine), as a retry of an idempotent PARAM_SET.
    assert apm.sets and set(apm.sets) == {("Q_A_RAT_RLL_P", f32(0.26))}, f"no restore (was {before}): {apm.sets}"


def test_a_denied_write_is_a_refusal_with_the_vehicle_text(apm, link):
    name = sorted(apm.read_only)[0]
    before = dict(apm.values)
    r = gcs("params", "set", name, str(apm.values[name] + 1), link=link)
    assert r.returncode == 1, r.stderr
    assert f"Param write denied ({name})" in r.stderr, r.stderr
    assert apm.values == before and apm.sets == []


def test_an_integer_beyond_its_type_is_refused_before_sending(apm, link):
    int8 = next(n for n, t, _ in apm.table() if t == 2 and n.endswith("_ENABLE"))
    r = gcs("params", "set", int8, "300", link=link)
    assert r.returncode == 2, r.stderr
    assert "would be stored as 127" in r.stderr, r.stderr
    assert apm.sets == []


def test_push_with_a_refused_value_is_rolled_back_exactly(apm, link, tmp_path):
    denied = sorted(apm.read_only)[0]
    before = {n: apm.values[n] for n in [*GAINS, denied]}
    f = tmp_path / "gains.parm"
    lines = [f"{n} {before[n] * 1.5 + 0.01:.6g}" for n in GAINS] + [f"{denied} {before[denied] + 1:g}"]
    f.write_text("\n".join(lines) + "\n")
    r = gcs("params", "push", str(f), link=link)
    assert r.returncode == 1, r.stderr + r.stdout
    assert f"{denied} refused" in r.stderr, r.stderr
    after = {n: apm.values[n] for n in before}
    assert all(same_f32(after[n], before[n]) for n in before), (before, after)
    written = [n for n, _ in apm.sets]
    assert set(written) == set(GAINS), written
    # Each gain written (a retry may write it twice), then restored last.
    for n in GAINS:
        values = [v for name, v in apm.sets if name == n]
        assert values[-1] == before[n] and len(set(values)) == 2, (n, values)


def test_save_then_diff_after_a_change(apm, link, tmp_path):
    saved = tmp_path / "saved.params"
    r = gcs("params", "save", str(saved), link=link)
    assert r.returncode == 0, r.stderr
    r = gcs("params", "diff", str(saved), link=link)
    assert r.returncode == 0 and r.stdout.strip().endswith("0 differ"), r.stdout + r.stderr
    assert gcs("params", "set", "Q_A_RAT_PIT_P", "0.31", link=link).returncode == 0
    r = gcs("params", "diff", str(saved), link=link)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Q_A_RAT_PIT_P 0.31 ->" in r.stdout and r.stdout.strip().endswith("1 differ"), r.stdout


def test_an_enable_grows_the_table_and_the_next_pull_has_it(apm, link, tmp_path):
    name, variant = next(iter(apm.recording["variants"].items()))
    r = gcs("params", "set", name, "1", link=link)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "bigger.params"
    r = gcs("params", "pull", "-o", str(out), link=link)
    assert r.returncode == 0, r.stderr
    got = qgc_table(out)
    assert len(got) == variant["count"]
    assert all(n in got for _, n, _, _ in variant["inserted"])


def test_a_push_that_needs_an_enable_writes_it_first(apm, link, tmp_path):
    name, variant = next(iter(apm.recording["variants"].items()))
    _, new_name, new_type, new_value = variant["inserted"][-1]
    wanted = stored_value = new_value + 1
    f = tmp_path / "tilt.parm"
    f.write_text(f"{name} 1\n{new_name} {wanted:.9g}\nQ_A_RAT_YAW_P 0.21\n")
    r = gcs("params", "push", str(f), link=link)
    assert r.returncode == 0, r.stderr + r.stdout
    assert f"{name} 0 -> 1 (written first" in r.stdout, r.stdout
    assert apm.values[name] == 1 and apm.values["Q_A_RAT_YAW_P"] == f32(0.21)
    assert same_f32(apm.values[new_name], stored_value), (new_name, apm.values[new_name])
    assert len(apm.table()) == variant["count"]
