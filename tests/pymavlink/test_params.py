"""Parameter protocol: full download, exact set/get, refusals, persistence across restarts."""

import math
import time

import pytest

from conftest import GCS_SYSID, f32

EXPECTED_NAMES = [
    "LAT_SAT_A", "LAT_SAT_B", "LAT_SAT_C", "LAT_SAT_D",
    "LON_SAT_A", "LON_SAT_B", "LON_SAT_C", "LON_SAT_D",
    "ALT_KD", "ALT_KP", "YAW_KD", "YAW_KP", "HOVER_ALT", "SERVO1_FUNCTION", "SERVO2_FUNCTION",
]
DEFAULTS = {
    "LAT_SAT_A": 1.2, "LAT_SAT_B": 0.6, "LAT_SAT_C": 0.22, "LAT_SAT_D": 0.18,
    "LON_SAT_A": 1.2, "LON_SAT_B": 0.6, "LON_SAT_C": 0.22, "LON_SAT_D": 0.18,
    "ALT_KD": 2.0, "ALT_KP": 5.0, "YAW_KD": 5.0, "YAW_KP": 5.0, "HOVER_ALT": 1.0,
}
MAV_PARAM_ERROR_DOES_NOT_EXIST = 1
MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE = 2
MAV_PARAM_ERROR_READ_ONLY = 5
MAV_SEVERITY_WARNING = 4


def fetch_all(g, timeout=30.0):
    """PARAM_REQUEST_LIST, then every PARAM_VALUE until all indices are in (no re-requests)."""
    g.m.param_fetch_all()
    seen: dict[int, list] = {}
    counts = set()
    deadline = time.monotonic() + timeout
    while not counts or len(seen) < max(counts):
        left = deadline - time.monotonic()
        assert left > 0, f"only {len(seen)} of {counts} params in {timeout} s"
        p = g.recv("PARAM_VALUE", timeout=left)
        counts.add(p.param_count)
        seen.setdefault(p.param_index, []).append(p)
    return seen, counts


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_fetch_all_every_index_exactly_once(twin, gcs_factory, transport):
    g = gcs_factory(getattr(twin, transport))
    g.wait_vehicle_heartbeat()
    seen, counts = fetch_all(g)
    assert len(counts) == 1, f"param_count changed during the download: {counts}"
    count = counts.pop()
    assert sorted(seen) == list(range(count)), f"indices {sorted(seen)} for count {count}"
    dup = {i: [p.param_id for p in ps] for i, ps in seen.items() if len(ps) > 1}
    assert not dup, f"indices sent more than once: {dup}"
    names = [ps[0].param_id for ps in seen.values()]
    assert len(set(names)) == len(names), "duplicate names"
    for n in EXPECTED_NAMES:
        assert n in names, f"{n} missing from {sorted(names)}"
    # by index: a read by index answers the same name
    g.m.mav.param_request_read_send(1, 1, b"", count - 1)
    p = g.recv("PARAM_VALUE", lambda p: p.param_index == count - 1)
    assert p.param_id == seen[count - 1][0].param_id
    # pymavlink's own table (m.params reads (sysid, 1): needs compid 1)
    for n in EXPECTED_NAMES:
        assert n in g.m.params


def test_defaults(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    for name, value in DEFAULTS.items():
        p = g.param_get(name)
        assert p.param_value == f32(value), (name, p.param_value)
        assert p.param_type == 9, f"{name} should be REAL32, got type {p.param_type}"
    # SERVOn_FUNCTION are integers, C-cast encoded (a whole float, integer type)
    functions = {}
    for n in range(1, 6):
        p = g.param_get(f"SERVO{n}_FUNCTION")
        assert p.param_type in (1, 2, 3, 4, 5, 6), f"SERVO{n}_FUNCTION should have an integer type: {p}"
        functions[n] = p.param_value
    # SERVO1/2 = the two ESCs (ThrottleLeft 73 / ThrottleRight 74, in either order),
    # SERVO3/4 = ailerons (4), SERVO5 = elevator (19): ArduPilot SRV_Channel numbers
    assert {functions[1], functions[2]} == {73.0, 74.0}, functions
    assert (functions[3], functions[4], functions[5]) == (4.0, 4.0, 19.0), functions


@pytest.fixture
def restore(twin, gcs_factory):
    """Restores every parameter the test touched."""
    g = gcs_factory(twin.tcp)
    saved = {}

    def remember(*names):
        for n in names:
            saved.setdefault(n, g.param_get(n).param_value)

    yield remember
    for n, v in saved.items():
        assert g.param_set(n, v).param_value == v


@pytest.mark.parametrize(
    "name,value",
    [("HOVER_ALT", 1.1), ("LAT_SAT_A", 1.2345678), ("ALT_KP", 4.7), ("YAW_KD", 5.000001)],
)
def test_set_get_roundtrip_exact(twin, gcs_factory, restore, name, value):
    restore(name)
    g = gcs_factory(twin.tcp)
    echo = g.param_set(name, value)
    assert echo.param_value == f32(value), echo
    assert echo.param_type == 9
    assert g.param_get(name).param_value == f32(value)
    # another client sees the same value
    assert gcs_factory(twin.udp).param_get(name).param_value == f32(value)


def expect_refusal(g, name, value, error=None):
    before = g.param_get(name).param_value
    g.drain()
    g.m.param_set_send(name, value)
    got = {}
    deadline = time.monotonic() + 10
    while len(got) < 3:
        left = deadline - time.monotonic()
        assert left > 0, f"refusal of {name}={value}: got only {sorted(got)}"
        try:
            m = g.recv(["PARAM_VALUE", "PARAM_ERROR", "STATUSTEXT"], timeout=left)
        except AssertionError:
            raise AssertionError(f"refusal of {name}={value} (was {before}): got only { {k: str(v) for k, v in got.items()} }") from None
        t = m.get_type()
        if t in ("PARAM_VALUE", "PARAM_ERROR") and m.param_id != name:
            continue
        if t == "STATUSTEXT" and m.severity > MAV_SEVERITY_WARNING:
            continue
        assert t not in got or t == "STATUSTEXT", f"second {t}: {m} (first {got[t]})"
        got.setdefault(t, m)
    echo, err = got["PARAM_VALUE"], got["PARAM_ERROR"]
    assert echo.param_value == before, f"echo {echo.param_value}, expected the unchanged {before}"
    assert err.target_system == GCS_SYSID, err
    if error is not None:
        assert err.error == error, err
    else:
        assert err.error not in (0, MAV_PARAM_ERROR_DOES_NOT_EXIST), err
    assert got["STATUSTEXT"].text.strip(), got["STATUSTEXT"]
    assert g.param_get(name).param_value == before
    return got


def test_nan_refused(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    expect_refusal(g, "HOVER_ALT", math.nan, MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE)
    expect_refusal(g, "ALT_KP", math.inf, MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE)


def test_out_of_range_refused(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    expect_refusal(g, "HOVER_ALT", -3.0, MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE)
    expect_refusal(g, "HOVER_ALT", 1e6, MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE)


def test_read_only_refused(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    expect_refusal(g, "SERVO1_FUNCTION", 33.0, MAV_PARAM_ERROR_READ_ONLY)


def test_saturation_constraint_refused(twin, gcs_factory, restore):
    g = gcs_factory(twin.tcp)
    restore("LAT_SAT_A", "LAT_SAT_B")
    b, c, d = (g.param_get(n).param_value for n in ("LAT_SAT_B", "LAT_SAT_C", "LAT_SAT_D"))
    # a > b + c + d is broken by a = b + c + d - 0.05 (in range on its own)
    expect_refusal(g, "LAT_SAT_A", b + c + d - 0.05)
    # b > c + d is broken by b = c + d - 0.01
    expect_refusal(g, "LAT_SAT_B", c + d - 0.01)
    # c > d, d > 0 on the other chain
    expect_refusal(g, "LON_SAT_C", g.param_get("LON_SAT_D").param_value - 0.01)
    expect_refusal(g, "LON_SAT_D", 0.0)
    # a value that keeps the constraint is accepted
    assert g.param_set("LAT_SAT_A", b + c + d + 0.1).param_value == f32(b + c + d + 0.1)


def test_saturation_constraint_boundary(twin, gcs_factory, restore):
    """b == c + d as the GCS sees the values (float32, what PARAM_VALUE reports) breaks b > c + d:
    the twin must check the values it reports, not unrounded defaults."""
    g = gcs_factory(twin.tcp)
    restore("LAT_SAT_B", "LON_SAT_C")
    c, d = (g.param_get(n).param_value for n in ("LAT_SAT_C", "LAT_SAT_D"))
    expect_refusal(g, "LAT_SAT_B", f32(c + d))  # b == c + d
    expect_refusal(g, "LON_SAT_C", g.param_get("LON_SAT_D").param_value)  # c == d


def test_unknown_name_gets_param_error_only(twin, gcs_factory):
    g = gcs_factory(twin.tcp)
    g.wait_vehicle_heartbeat()
    for send in (
        lambda: g.m.param_set_send("NO_SUCH_PARAM", 1.0),
        lambda: g.m.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM", -1),
    ):
        send()
        err = g.recv("PARAM_ERROR", lambda e: e.param_id == "NO_SUCH_PARAM")
        assert err.error == MAV_PARAM_ERROR_DOES_NOT_EXIST, err
        assert err.target_system == GCS_SYSID, err
        # Nothing else about NO_SUCH_PARAM (no PARAM_VALUE, no warning) comes before the reply to
        # a later request on the same link.
        g.m.mav.param_request_read_send(1, 1, b"HOVER_ALT", -1)
        stray = g.recv(
            ["PARAM_VALUE", "PARAM_ERROR", "STATUSTEXT"],
            lambda m: m.get_type() == "STATUSTEXT" and m.severity <= MAV_SEVERITY_WARNING
            or m.get_type() != "STATUSTEXT" and m.param_id in ("HOVER_ALT", "NO_SUCH_PARAM"),
        )
        assert getattr(stray, "param_id", None) == "HOVER_ALT", f"unexpected {stray}"


def test_values_survive_restart(twin_factory, gcs_factory, tmp_path):
    pf = tmp_path / "persist.parm"
    t1 = twin_factory(param_file=pf, speed=4)
    g = gcs_factory(t1.tcp)
    assert g.param_set("HOVER_ALT", 1.3).param_value == f32(1.3)
    assert g.param_set("YAW_KP", 4.25).param_value == 4.25
    g.close()
    twin_factory.stop(t1)
    assert pf.exists() and pf.stat().st_size > 0
    t2 = twin_factory(param_file=pf, speed=4)
    g2 = gcs_factory(t2.udp)
    assert g2.param_get("HOVER_ALT").param_value == f32(1.3)
    assert g2.param_get("YAW_KP").param_value == 4.25
    assert g2.param_get("ALT_KP").param_value == f32(5.0)


def test_wp_radius_is_an_int16_as_on_arduplane(twin, gcs_factory, restore):
    """ArduPlane's WP_RADIUS is an AP_Int16: PARAM_VALUE says INT16, and a write of 0.4 stores
    (and reads back) 0, the C cast. Q_TAILSIT_ENABLE says the twin is a tailsitter."""
    g = gcs_factory(twin.tcp)
    restore("WP_RADIUS")
    p = g.param_get("WP_RADIUS")
    assert (p.param_type, p.param_value) == (4, 90.0), p
    g.drain()
    g.m.param_set_send("WP_RADIUS", 0.4)
    echo = g.recv("PARAM_VALUE", lambda v: v.param_id == "WP_RADIUS", what="WP_RADIUS echo")
    assert (echo.param_type, echo.param_value) == (4, 0.0), echo
    p = g.param_get("Q_TAILSIT_ENABLE")
    assert (p.param_type, p.param_value) == (2, 1.0), p
