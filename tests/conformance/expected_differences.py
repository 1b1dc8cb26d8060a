"""Where the twin is known to answer otherwise than ArduPlane: each entry names a difference,
the scenario and the observation keys (a regular expression over `protocol:KEY` /
`physics:KEY`, see compare.py) it covers, what ArduPlane does and what the twin does.
docs/compatibility.md's section "Conformance with ArduPlane" mirrors this table.

An entry is strict unless it says otherwise: once the twin answers as ArduPlane does, the
comparison fails until the entry is removed.
"""

EXPECTED_DIFFERENCES: list[dict] = []
