"""A failed test keeps its twin's tlog and says where; a passing test leaves none behind."""

from pymavlink import mavutil


def test_a_failed_test_keeps_its_tlog(pytester):
    pytester.makepyfile(
        """
        import pytest

        pytestmark = pytest.mark.vtol_twin(speed="lockstep")

        def test_passes(vtol_twin):
            vtol_twin.advance(1)

        def test_fails(vtol_twin):
            vtol_twin.connect()
            vtol_twin.advance(2)
            assert vtol_twin.state().armed, "the vehicle never armed"
        """
    )
    tlogs = pytester.path / "tlogs"
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", f"--vtol-twin-tlog-dir={tlogs}")
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines([
        "*- vtol_twin -*",
        "tlog kept: *test_fails-*.tlog",
        "*vtol_twin: tlogs of failed tests*",
        "*::test_fails: tlog kept: *test_fails-*.tlog",
    ])
    kept = sorted(tlogs.glob("*.tlog"))
    assert [p.name.split("-")[0] for p in kept] == ["test_fails"], kept

    # The kept log reads as a tlog: the heartbeats the test's connection got over the 2 s it
    # flew, stamped with sim time.
    log = mavutil.mavlink_connection(str(kept[0]))
    beats = []
    while (msg := log.recv_match(type="HEARTBEAT")) is not None:
        beats.append(msg._timestamp)
    assert len(beats) >= 3 and beats[-1] == 2.0, beats
