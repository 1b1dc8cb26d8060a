"""Compares a vehicle's trace with the recorded ArduPlane trace of the same scenario.

Protocol observations (`trace["protocol"]`) must be equal: ACK results, mode numbers, message
sets, parameter types, mission replies, STATUSTEXT categories, state sequences. Physics
observations (`trace["physics"]`, phase summaries flattened to `phase.field`) must agree within
the tolerance of the first `TOLERANCES` row whose pattern matches the key. `info` is never
compared.

A difference that the table in expected_differences.py names is reported under that name
instead of failing; a strict entry that no longer matches any difference fails too (the twin now
does what ArduPlane does, and the entry must go).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from expected_differences import EXPECTED_DIFFERENCES

# (key pattern, how, tolerance): "abs" |a - b| <= tol; "rel" |a - b| <= tol * max(|a|, |b|);
# "angle" the circular difference in degrees <= tol.
TOLERANCES = [
    (r"(roll|pitch)_deg$", "abs", 10.0),
    (r"(yaw|heading|course)_deg$", "angle", 20.0),
    (r"(airspeed|groundspeed)_m_s$", "abs", 3.0),
    (r"climb_m_s$", "abs", 1.0),
    (r"rel_alt_m$", "abs", 5.0),
    (r"duration_s$", "rel", 0.5),
    (r"_m$", "abs", 5.0),
    (r"(\.value|WP_RADIUS)$", "rel", 1e-6),
]


# On the wing, the attitude and heading a ground station draws are compared with a tailsitter
# that ArduPilot's autotest flies on the wing (SITL's `quadplane-copter_tailsitter`, traces in
# traces/arduplane-copter-tailsitter/): SITL's `plane-tailsitter`, whose traces the rest is
# compared with, cannot hold its cruise airspeed (6 m/s at 17-21 degrees of pitch). Roll and
# pitch within the physics tolerance; the heading within this many degrees of the course, for
# the reference and the vehicle alike (the figure for ArduPlane's first seconds in
# CRUISE after a transition).
WING_PHASES = ("wing.first_10s",)
HEADING_OFF_COURSE_DEG = 26.0


def heading_off_course(phase: dict) -> float | None:
    """How far VFR_HUD's heading is from the course over the ground, in degrees."""
    if phase.get("heading_deg") is None or phase.get("course_deg") is None:
        return None
    return abs((phase["heading_deg"] - phase["course_deg"] + 180.0) % 360.0 - 180.0)


def wing_frame(ref: dict, got: dict) -> list[str]:
    """What on the wing differs from the flyable tailsitter's trace `ref` (empty: nothing)."""
    problems = []
    for phase in WING_PHASES:
        a, b = ref.get("physics", {}).get(phase), got.get("physics", {}).get(phase)
        if a is None:
            continue
        if b is None:
            problems.append(f"{phase}: not flown")
            continue
        for key in ("roll_deg", "pitch_deg"):
            if not close(key, a[key], b[key]):
                problems.append(f"{phase}.{key}: ArduPlane {a[key]}, this vehicle {b[key]}")
        for who, t in (("ArduPlane", a), ("this vehicle", b)):
            off = heading_off_course(t)
            if off is None or off > HEADING_OFF_COURSE_DEG:
                problems.append(f"{phase}: {who}'s heading {t.get('heading_deg')} is {off} degrees off its "
                                f"course {t.get('course_deg')}")
    return problems


@dataclass
class Difference:
    key: str  # "protocol:arm" or "physics:takeoff.climb.pitch_deg"
    arduplane: object
    vehicle: object
    expected: str | None = None  # the EXPECTED_DIFFERENCES entry's name

    def __str__(self) -> str:
        tag = f" [expected: {self.expected}]" if self.expected else ""
        return f"{self.key}: ArduPlane {self.arduplane!r}, this vehicle {self.vehicle!r}{tag}"


def flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def tolerance(key: str) -> tuple[str, float]:
    for pat, how, tol in TOLERANCES:
        if re.search(pat, key):
            return how, tol
    return "abs", 0.0


def close(key: str, a, b) -> bool:
    if a is None or b is None or isinstance(a, bool) or isinstance(b, bool):
        return a == b
    if not isinstance(a, (int, float)) or not isinstance(b, (int, float)):
        return a == b
    how, tol = tolerance(key)
    if how == "angle":
        return abs((a - b + 180.0) % 360.0 - 180.0) <= tol
    if how == "rel":
        return abs(a - b) <= tol * max(abs(a), abs(b)) or math.isclose(a, b)
    return abs(a - b) <= tol


def differences(ref: dict, got: dict) -> list[Difference]:
    """Every observation where `got` differs from the ArduPlane trace `ref`."""
    out = []
    if ref.get("error") != got.get("error"):
        out.append(Difference("error", ref.get("error"), got.get("error")))
    for part in ("protocol", "physics"):
        a, b = flatten(ref.get(part, {})), flatten(got.get(part, {}))
        for key in sorted(a.keys() | b.keys()):
            x, y = a.get(key, "<absent>"), b.get(key, "<absent>")
            same = x == y if part == "protocol" or "<absent>" in (x, y) else close(key, x, y)
            if not same:
                out.append(Difference(f"{part}:{key}", x, y))
    return out


def classify(scenario: str, diffs: list[Difference]) -> tuple[list[Difference], list[Difference], list[dict]]:
    """(expected differences, unexpected ones, strict table entries that matched nothing)."""
    entries = [e for e in EXPECTED_DIFFERENCES if e["scenario"] in (scenario, "*")]
    used: set[str] = set()
    expected, unexpected = [], []
    for d in diffs:
        for e in entries:
            if re.fullmatch(e["keys"], d.key):
                d.expected = e["name"]
                used.add(e["name"])
                expected.append(d)
                break
        else:
            unexpected.append(d)
    stale = [e for e in entries if e.get("strict", True) and e["name"] not in used and e["scenario"] == scenario]
    return expected, unexpected, stale


def report(scenario: str, ref: dict, got: dict) -> tuple[str, bool]:
    """A readable comparison and whether it passes."""
    expected, unexpected, stale = classify(scenario, differences(ref, got))
    lines = [f"scenario {scenario}: {len(unexpected)} unexpected, {len(expected)} expected differences"]
    lines += [f"  UNEXPECTED {d}" for d in unexpected]
    lines += [f"  expected   {d}" for d in expected]
    lines += [f"  STALE expected difference '{e['name']}' ({e['keys']}): the vehicle now does what ArduPlane "
              f"does; remove the entry" for e in stale]
    return "\n".join(lines), not unexpected and not stale


def main(argv: list[str] | None = None) -> int:
    """`python compare.py REF_DIR OTHER_DIR [NAME...]`: the report of each scenario traced in
    both folders (e.g. traces/arduplane and a folder `record.py --twin` wrote)."""
    import argparse
    import json
    from pathlib import Path

    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("ref", type=Path)
    ap.add_argument("other", type=Path)
    ap.add_argument("names", nargs="*")
    a = ap.parse_args(argv)
    names = a.names or sorted(p.stem for p in a.ref.glob("*.json") if (a.other / p.name).is_file())
    ok_all = True
    for name in names:
        text, ok = report(name, json.loads((a.ref / f"{name}.json").read_text()),
                          json.loads((a.other / f"{name}.json").read_text()))
        ok_all &= ok
        print(text)
    return 0 if ok_all else 1


if __name__ == "__main__":
    raise SystemExit(main())
