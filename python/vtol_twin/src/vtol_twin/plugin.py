"""The pytest side: the `vtol_twin` and `vtol_fleet` fixtures, their options, and the tlog of a
failed test.

Options of a twin, from weakest to strongest: the defaults of `TwinOptions` (real time, seed 1,
physical model), the `vtol_twin_options` fixture (override it in a conftest.py for a whole
suite), the `@pytest.mark.vtol_twin(...)` marker of a test, and the keywords of a
`vtol_fleet(n, ...)` call.

Every twin writes a tlog of every frame in both directions. When its test passes, the tlog is
deleted; when the test fails (in setup, call or teardown), the tlog is kept and its path is
printed in the failure report and at the end of the run.
"""

from __future__ import annotations

import itertools
import os
import re
from pathlib import Path
from typing import Callable

import pytest

from .twin import TwinError, TwinOptions, VtolTwin, find_binary, start_fleet

_TWINS = pytest.StashKey[list]()
_SECTION = "vtol_twin"
_counter = itertools.count()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("vtol_twin", "the VTOL twin as a test fixture")
    group.addoption("--vtol-twin-bin", metavar="PATH", default=None,
                    help="the firmware-sim binary (default: $FIRMWARE_SIM_BIN, firmware-sim on PATH, "
                         "or target/release|debug/firmware-sim of the rootdir or above)")
    group.addoption("--vtol-twin-tlog-dir", metavar="DIR", default=None,
                    help="where the twins' tlogs go (default: each test's tmp_path); those of failed "
                         "tests are kept")
    parser.addini("vtol_twin_bin", "the firmware-sim binary (as --vtol-twin-bin)", default="")
    parser.addini("vtol_twin_tlog_dir", "where the twins' tlogs go (as --vtol-twin-tlog-dir)", default="")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "vtol_twin(**options): options of the vtol_twin and vtol_fleet fixtures: speed ('lockstep', "
        "'fast' or a factor), seed, model, initial, param_file, params, sysid, ideal_sensors, "
        "boot_calibration",
    )
    _KEPT.clear()


# Kept tlogs, as "nodeid: tlog kept: PATH" lines, for the summary at the end of the run.
_KEPT: list = []


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call):
    rep = yield
    twins = item.stash.get(_TWINS, [])
    if rep.failed and twins:
        for t in twins:
            t.keep_tlog = True
        rep.sections.append((_SECTION, "\n".join(f"tlog kept: {t.tlog}" for t in twins)))
    return rep


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    # Called where reports are shown (the controller under xdist), so the summary sees them all.
    for name, text in report.sections:
        if name == _SECTION:
            _KEPT.extend(f"{report.nodeid}: {line}" for line in text.splitlines())


def pytest_terminal_summary(terminalreporter) -> None:
    if _KEPT:
        terminalreporter.section("vtol_twin: tlogs of failed tests")
        for line in dict.fromkeys(_KEPT):
            terminalreporter.line(line)


def _binary(config: pytest.Config) -> Path:
    explicit = config.getoption("--vtol-twin-bin") or config.getini("vtol_twin_bin") or None
    return find_binary(explicit, search_from=config.rootpath)


def _tlog_dir(config: pytest.Config, tmp_path: Path) -> Path:
    d = config.getoption("--vtol-twin-tlog-dir") or config.getini("vtol_twin_tlog_dir")
    return Path(d).expanduser().resolve() if d else tmp_path


@pytest.fixture
def vtol_twin_options() -> dict:
    """Options every twin of a test starts with; override in a conftest.py for a whole suite."""
    return {}


@pytest.fixture
def vtol_fleet(request: pytest.FixtureRequest, tmp_path: Path, vtol_twin_options: dict) -> Callable[..., list]:
    """A factory: `vtol_fleet(n, **options)` starts n twins at once and returns them (system ids
    1..n unless `sysid` is given). They are stopped after the test."""
    config = request.config
    marker = request.node.get_closest_marker("vtol_twin")
    marked = dict(marker.kwargs) if marker else {}
    binary = _binary(config)
    tlog_dir = _tlog_dir(config, tmp_path)
    tlog_dir.mkdir(parents=True, exist_ok=True)
    started: list[VtolTwin] = request.node.stash.setdefault(_TWINS, [])
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", request.node.name)[:80]

    def make(n: int = 1, **options) -> list[VtolTwin]:
        if n < 1:
            raise ValueError("vtol_fleet needs n >= 1")
        base = TwinOptions.merged(vtol_twin_options, marked, options)
        opts = []
        for k in range(n):
            o = TwinOptions.merged(vars(base))
            if n > 1 and o.sysid is None:
                o.sysid = k + 1
            opts.append(o)
        ids = [next(_counter) for _ in range(n)]
        workdirs = [tmp_path / f"vtol_twin{i}" for i in ids]
        tlogs = [tlog_dir / f"{stem}-{os.getpid()}-{i}.tlog" for i in ids]
        twins = start_fleet(binary, workdirs, tlogs, opts)
        started.extend(twins)
        return twins

    yield make

    errors = []
    for t in started:
        try:
            t.stop()
        except TwinError as e:
            t.keep_tlog = True
            errors.append(f"{e}\ntlog kept: {t.tlog}")
    for t in started:
        if not t.keep_tlog:
            t.tlog.unlink(missing_ok=True)
    if errors:
        raise TwinError("\n\n".join(errors))


@pytest.fixture
def vtol_twin(vtol_fleet) -> VtolTwin:
    """One twin (options from `vtol_twin_options` and the `vtol_twin` marker), stopped after
    the test."""
    return vtol_fleet(1)[0]
