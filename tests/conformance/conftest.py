"""Fixtures of the conformance suite: the twin as the pymavlink suite starts it (procs.py's
process mechanics, tests/pymavlink/conftest.py's `start_twin`), one fresh twin per scenario."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from vehicle import suite  # noqa: E402

twin_factory = suite.twin_factory
