"""The conformance scenarios against a fresh twin each, compared with the ArduPlane traces in
traces/arduplane/ (compare.py says how; expected_differences.py names the known differences).

The twin's own trace of each scenario is written to the test's tmp_path (and to
$CONFORMANCE_TWIN_OUT/NAME.json when that is set), beside the comparison report.
"""

import json
import os
from pathlib import Path

import pytest

from compare import report, wing_frame
from expected_differences import EXPECTED_DIFFERENCES
from record import TWIN_SPEED
from scenarios import SCENARIOS, run

TRACES = Path(__file__).resolve().parent / "traces" / "arduplane"
FLYABLE = TRACES.parent / "arduplane-copter-tailsitter"


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_scenario_matches_arduplane(name, twin_factory, tmp_path):
    ref_path = TRACES / f"{name}.json"
    assert ref_path.is_file(), f"no ArduPlane trace {ref_path}: record it with record.py (see README.md)"
    ref = json.loads(ref_path.read_text())
    twin = twin_factory(listen=("tcpin:127.0.0.1:0",), speed=TWIN_SPEED[SCENARIOS[name][1]])
    got = run(name, twin.tcp)
    text = json.dumps(got, indent=1) + "\n"
    (tmp_path / f"{name}.json").write_text(text)
    if os.environ.get("CONFORMANCE_TWIN_OUT"):
        out = Path(os.environ["CONFORMANCE_TWIN_OUT"])
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{name}.json").write_text(text)
    summary, ok = report(name, ref, got)
    print(summary)
    assert ok, summary
    flyable = FLYABLE / f"{name}.json"
    if flyable.is_file():
        problems = wing_frame(json.loads(flyable.read_text()), got)
        assert not problems, "on the wing, against a flyable ArduPlane tailsitter:\n" + "\n".join(problems)


def test_expected_differences_are_well_formed():
    """Every entry names a known scenario, says what ArduPlane and the twin do, and has a
    unique name."""
    names = [e["name"] for e in EXPECTED_DIFFERENCES]
    assert len(names) == len(set(names)), names
    for e in EXPECTED_DIFFERENCES:
        assert e["scenario"] in SCENARIOS or e["scenario"] == "*", e
        assert e["arduplane"].strip() and e["twin"].strip(), e
        assert e["keys"].startswith(("protocol:", "physics:", "error", "(")), e


def test_the_wing_check_catches_the_hover_frame():
    """The check on the wing fails for what the twin reported before it spoke the fixed-wing
    frame (pitch +84.5 degrees, heading 179 on a course of 360), and passes the reference."""
    ref = json.loads((FLYABLE / "rtl_wing.json").read_text())
    assert wing_frame(ref, ref) == []
    phase = dict(ref["physics"]["wing.first_10s"], pitch_deg=84.5, heading_deg=179.0, course_deg=0.0)
    problems = wing_frame(ref, {"physics": {"wing.first_10s": phase}})
    assert any("pitch_deg" in p for p in problems), problems
    assert any("off its course" in p for p in problems), problems
    assert wing_frame(ref, {"physics": {}}) == ["wing.first_10s: not flown"]
