"""`vtol-gcs mission` against the real twin, checked independently with pymavlink: a QGC WPL 110
file and a QGroundControl .plan uploaded and downloaded back equal (lossless and at 30 % frame
loss each way), a file with a bad item refused before anything is sent (naming its line),
`mission show`, `clear` and `set-current`, and a fence the twin does not support refused with
the vehicle's MISSION_ACK result in words. Exit status as docs/cli.md: 0 done, 1 refused,
2 bad input (nothing sent), 3 no vehicle or link failure."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from conftest import VEHICLE_COMPID, VEHICLE_SYSID, Gcs
from daemon_support import DAEMON_BIN

HOME = (-35.363261, 149.16523)
# Home, VTOL take-off to 10 m, a waypoint 50 m north with a 2 s hold, a VTOL landing back at
# home (a 50 m last leg: ArduPlane wants at least 30 m).
WPL = (
    "QGC WPL 110\n"
    "0\t1\t0\t16\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36326100\t149.16523000\t584.000000\t1\n"
    "1\t0\t3\t84\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t10.000000\t1\n"
    "2\t0\t3\t16\t2.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36281200\t149.16523000\t10.000000\t1\n"
    "3\t0\t3\t85\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36326100\t149.16523000\t0.000000\t1\n"
)

PLAN = {
    "fileType": "Plan",
    "groundStation": "QGroundControl",
    "version": 1,
    "geoFence": {"circles": [], "polygons": [], "version": 2},
    "rallyPoints": {"points": [], "version": 2},
    "mission": {
        "cruiseSpeed": 15, "firmwareType": 3, "hoverSpeed": 5, "vehicleType": 20, "version": 2,
        "plannedHomePosition": [-35.363261, 149.16523, 584],
        "items": [
            {"type": "SimpleItem", "command": 84, "frame": 3, "autoContinue": True, "doJumpId": 1,
             "AMSLAltAboveTerrain": None, "Altitude": 8, "AltitudeMode": 1,
             "params": [0, 0, 0, None, 0, 0, 8]},
            {"type": "SimpleItem", "command": 19, "frame": 3, "autoContinue": True, "doJumpId": 2,
             "params": [3, 0, 5, 0, -35.3631, 149.1654, 8]},
            {"type": "SimpleItem", "command": 85, "frame": 3, "autoContinue": True, "doJumpId": 3,
             "params": [0, 0, 0, None, -35.3635, 149.1650, 0]},
        ],
    },
}


def gcs(*args: str, link: str, timeout: float = 90.0) -> subprocess.CompletedProcess:
    assert DAEMON_BIN.exists(), f"{DAEMON_BIN} missing: build it with `cargo build --workspace`"
    return subprocess.run([str(DAEMON_BIN), "mission", *args, "--link", link],
                          capture_output=True, text=True, timeout=timeout)


def rows(text: str) -> list[list[float]]:
    """A QGC WPL 110 file's items as numbers (seq and current left out)."""
    lines = text.splitlines()
    assert lines[0] == "QGC WPL 110", lines[:1]
    return [[float(f) for f in line.split("\t")[2:]] for line in lines[1:] if line.strip()]


def close(a: list[list[float]], b: list[list[float]]) -> bool:
    def same(x, y):
        return (x != x and y != y) or abs(x - y) <= 1e-6 * max(1.0, abs(x), abs(y))
    return len(a) == len(b) and all(len(r) == len(s) and all(map(same, r, s)) for r, s in zip(a, b))


def gcs_mode(name: str, link: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(DAEMON_BIN), "mode", name, "--link", link], capture_output=True,
                          text=True, timeout=60)


def pymavlink_items(url: str) -> list:
    """The twin's mission, read by pymavlink (an independent check)."""
    with Gcs(url) as g:
        g.wait_vehicle_heartbeat()
        g.drain()
        g.mav.mission_request_list_send(VEHICLE_SYSID, VEHICLE_COMPID)
        count = g.recv("MISSION_COUNT", timeout=10).count
        out = []
        for seq in range(count):
            g.mav.mission_request_int_send(VEHICLE_SYSID, VEHICLE_COMPID, seq)
            out.append(g.recv("MISSION_ITEM_INT", lambda m, s=seq: m.seq == s, timeout=10))
        return out


@pytest.fixture(scope="module")
def lossless(module_twin_factory):
    return module_twin_factory(speed=4)


@pytest.fixture(scope="module")
def lossy(module_twin_factory):
    """30 % of frames dropped in each direction."""
    return module_twin_factory(speed=4, extra=["--loss", "0.3"], seed=5)


@pytest.mark.parametrize("which", ["lossless", "lossy"])
def test_a_wpl_file_uploads_and_downloads_back_equal(request, tmp_path, which):
    twin = request.getfixturevalue(which)
    f = tmp_path / "hop.waypoints"
    f.write_text(WPL)
    r = gcs("upload", str(f), link=twin.tcp)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("uploaded 4 mission items from"), r.stdout
    r = gcs("download", link=twin.tcp)
    assert r.returncode == 0, r.stderr
    assert close(rows(r.stdout), rows(WPL)), r.stdout
    back = tmp_path / "back.waypoints"
    assert gcs("download", str(back), link=twin.tcp).returncode == 0
    assert close(rows(back.read_text()), rows(WPL))
    if which == "lossless":
        items = pymavlink_items(twin.tcp)
        assert [m.command for m in items] == [16, 84, 16, 85]
        assert (items[2].x, items[2].y, items[2].z, items[2].param1) == (-353628120, 1491652300, 10.0, 2.0)


@pytest.mark.parametrize("which", ["lossless", "lossy"])
def test_a_plan_file_uploads_and_downloads_back_equal(request, tmp_path, which):
    twin = request.getfixturevalue(which)
    f = tmp_path / "survey.plan"
    f.write_text(json.dumps(PLAN, indent=4))
    r = gcs("upload", str(f), link=twin.tcp)
    assert r.returncode == 0, r.stdout + r.stderr
    back = tmp_path / "back.plan"
    r = gcs("download", str(back), link=twin.tcp)
    assert r.returncode == 0, r.stderr
    got = json.loads(back.read_text())["mission"]
    want = PLAN["mission"]
    assert got["plannedHomePosition"] == pytest.approx(want["plannedHomePosition"], abs=1e-6)
    assert [i["command"] for i in got["items"]] == [84, 19, 85]
    for g, w in zip(got["items"], want["items"]):
        assert g["frame"] == w["frame"] and g["doJumpId"] == w["doJumpId"]
        assert [None if p is None else pytest.approx(p, abs=1e-6) for p in g["params"]] == w["params"]


BAD = [
    # (text, line named, words)
    (WPL.replace("\t16\t2.00000000", "\t9999\t2.00000000"), 4, "unknown command 9999"),
    (WPL.replace("-35.36281200", "nan"), 4, "position or altitude is NaN"),
    (WPL.replace("-35.36281200", "-95.0"), 4, "latitude -95 is out of -90..90"),
    (WPL.replace("3\t0\t3\t85\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36326100",
                 "3\t0\t3\t85\t0.00000000\t0.00000000\t0.00000000\t0.00000000\t-35.36290000"),
     5, "VTOL land too short, min 30m"),
    (WPL.replace("\t3\t84\t", "\t77\t84\t"), 3, "unknown frame 77"),
]


@pytest.mark.parametrize("text,line,words", BAD)
def test_a_bad_item_is_refused_before_anything_is_sent(lossless, tmp_path, text, line, words):
    good = tmp_path / "good.waypoints"
    good.write_text(WPL)
    assert gcs("upload", str(good), link=lossless.tcp).returncode == 0
    before = [m.to_dict() for m in pymavlink_items(lossless.tcp)]
    f = tmp_path / "bad.waypoints"
    f.write_text(text)
    # A link where nothing listens: a refusal here proves nothing was sent.
    r = gcs("upload", str(f), link="tcp:127.0.0.1:9")
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"line {line} " in r.stderr and words in r.stderr, r.stderr
    assert r.stderr.strip().endswith("nothing was sent"), r.stderr
    r = gcs("upload", str(f), link=lossless.tcp)
    assert r.returncode == 2 and words in r.stderr, r.stderr
    assert [m.to_dict() for m in pymavlink_items(lossless.tcp)] == before


def test_show_set_current_and_clear(lossless, tmp_path):
    f = tmp_path / "hop.waypoints"
    f.write_text(WPL)
    assert gcs("upload", str(f), link=lossless.tcp).returncode == 0
    r = gcs("show", link=lossless.tcp)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].split() == ["seq", "command", "frame", "position", "altitude", "parameters"]
    assert "NAV_WAYPOINT (home)" in lines[1] and "-35.3632610, 149.1652300" in lines[1], r.stdout
    assert "NAV_VTOL_TAKEOFF" in lines[2] and "GLOBAL_RELATIVE_ALT" in lines[2] and "here" in lines[2]
    assert lines[3].rstrip().endswith("hold s 2") and "10 m" in lines[3], r.stdout
    assert "NAV_VTOL_LAND" in lines[4]
    # The same table from the file, without a link.
    r2 = subprocess.run([str(DAEMON_BIN), "mission", "show", str(f)], capture_output=True, text=True,
                        timeout=30)
    assert r2.returncode == 0 and r2.stdout.splitlines()[1:] == lines[1:], r2.stdout + r2.stderr
    r = gcs("set-current", "2", link=lossless.tcp)
    assert r.returncode == 0 and r.stdout.strip() == "current item 2", r.stdout + r.stderr
    with Gcs(lossless.tcp) as g:
        g.wait_vehicle_heartbeat()
        assert g.recv("MISSION_CURRENT", lambda m: m.seq == 2, timeout=10).seq == 2
    r = gcs("start", "3", link=lossless.tcp)
    assert r.returncode == 0 and r.stdout.strip() == "mission started at item 3", r.stdout + r.stderr
    with Gcs(lossless.tcp) as g:
        g.wait_vehicle_heartbeat(pred=lambda h: h.custom_mode == 10)  # AUTO, still disarmed
        assert g.recv("MISSION_CURRENT", lambda m: m.seq == 3, timeout=10).seq == 3
    assert gcs_mode("QHOVER", lossless.tcp).returncode == 0
    r = gcs("set-current", "9", link=lossless.tcp)
    assert r.returncode == 1 and "refused" in r.stderr, r.stdout + r.stderr
    r = gcs("clear", link=lossless.tcp)
    assert r.returncode == 0 and r.stdout.strip() == "mission cleared", r.stdout + r.stderr
    assert len(pymavlink_items(lossless.tcp)) <= 1
    r = gcs("start", link=lossless.tcp)
    assert r.returncode == 1 and "no mission" in r.stderr, r.stdout + r.stderr


def test_fence_and_rally_lists(lossless, tmp_path):
    r = gcs("download", "--type", "fence", "--format", "plan", link=lossless.tcp)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["geoFence"]["polygons"] == []
    assert gcs("show", "--type", "rally", link=lossless.tcp).stdout == "no rally items\n"
    plan = dict(PLAN, rallyPoints={"points": [[-35.3630, 149.1650, 30]], "version": 2})
    f = tmp_path / "rally.plan"
    f.write_text(json.dumps(plan))
    r = gcs("upload", "--type", "rally", str(f), link=lossless.tcp)
    # The twin keeps no rally points: its MISSION_ACK in words.
    assert r.returncode == 1, r.stdout + r.stderr
    assert "MAV_MISSION_UNSUPPORTED (command not supported)" in r.stderr, r.stderr


def test_no_vehicle_is_exit_3(tmp_path):
    r = gcs("download", link="tcp:127.0.0.1:9")
    assert r.returncode == 3, r.stderr
