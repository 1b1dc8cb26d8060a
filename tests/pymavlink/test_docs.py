"""The documentation is tested: every fenced block of the documents in DOCS is run, or says why
not (the convention of docs/cli.md, "Testing the documentation"):

- ```console: `$ command` lines, each followed by its expected output (stdout and stderr
  together, as a terminal shows them). `...` on a line of its own matches any lines (none
  included), `[..]` any part of a line, and a first line `? N` is the expected exit status
  (default 0). Each block runs its commands in order, through `bash -c`, in one scratch
  directory per document (so a file one block writes, the next can read).
- ```python: run with this test's Python in the same directory; it must exit 0.
- anything else: ```text, or any fence directly preceded by `<!-- not run: REASON -->`.

The commands find the built binaries first on PATH (`vtol-gcs`, `firmware-sim`: the ones
$VTOL_GCS_BIN and $FIRMWARE_SIM_BIN name). Those that need a vehicle talk to a daemon with the
embedded twin that this test starts on free ports, one per document:

- VTOL_GCS_LINK: its tcp serve port, the default --link of `vtol-gcs params|arm|disarm|mode`,
  so an example can be written exactly as a user types it against a local daemon;
- DAEMON_TCP, DAEMON_UDP: its serve ports as pymavlink URLs (tcp:H:P, udpout:H:P);
- REPO: the repository; the scratch directory also holds links `config` and `docs` to its
  config/ and docs/, and `python` is this test's Python (first on PATH).

A document not written to the convention fails here with the list of its blocks that are
neither run nor marked. The checker itself is tested on tests/docs_fixture.md and on broken
copies of it: a changed flag or output must fail.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from conftest import TWIN_BIN
from daemon_support import DAEMON_BIN, module_daemon_factory, start_daemon  # noqa: F401

ROOT = Path(__file__).resolve().parents[2]
# Documents whose examples are tested.
DOCS = ["tests/docs_fixture.md", "README.md", "docs/cli.md"]

FENCE = re.compile(r"^(?P<fence>```+|~~~+)\s*(?P<lang>[\w+-]*)")
NOT_RUN = re.compile(r"^<!--\s*not run:\s*\S.*-->\s*$")


@dataclass
class Block:
    lang: str
    line: int  # 1-based line of the opening fence
    body: list[str]
    marked: bool  # directly preceded by `<!-- not run: ... -->`


def blocks(text: str) -> list[Block]:
    """The fenced blocks of a markdown text."""
    lines = text.splitlines()
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, start = m["fence"], i
        prev = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
        i += 1
        body = []
        while i < len(lines) and not lines[i].startswith(fence):
            body.append(lines[i])
            i += 1
        out.append(Block(m["lang"].lower(), start + 1, body, bool(NOT_RUN.match(prev))))
        i += 1
    return out


def unmarked(bs: list[Block]) -> list[str]:
    """Blocks that are neither run nor marked."""
    return [f"line {b.line}: ```{b.lang} block neither run (console, python) nor marked "
            f"`<!-- not run: REASON -->`" for b in bs
            if b.lang not in ("console", "python", "text") and not b.marked]


def commands(b: Block) -> list[tuple[str, int, list[str]]]:
    """(command, expected status, expected output lines) of a console block."""
    out = []
    for line in b.body:
        if line.startswith("$ "):
            out.append((line[2:], 0, []))
        elif not out:
            raise AssertionError(f"line {b.line}: console block output before any `$ command`")
        elif not out[-1][2] and re.fullmatch(r"\? \d+", line) and out[-1][1] == 0:
            out[-1] = (out[-1][0], int(line[2:]), [])
        else:
            out[-1][2].append(line)
    return out


def pattern(expected: list[str]) -> re.Pattern:
    """The regex of expected output lines with `...` and `[..]`."""
    parts = []
    for line in expected:
        if line == "...":
            parts.append(r"(?:[^\n]*\n)*?")
        else:
            parts.append(".*?".join(re.escape(p) for p in line.split("[..]")) + r"\n")
    return re.compile("".join(parts), re.DOTALL)


def matches(expected: list[str], actual: str) -> bool:
    if actual and not actual.endswith("\n"):
        actual += "\n"
    return pattern(expected).fullmatch(actual) is not None


def check(doc: Path, workdir: Path, env: dict) -> list[str]:
    """Runs a document's blocks; returns its failures (empty when every example holds)."""
    bs = blocks(doc.read_text())
    failures = unmarked(bs)
    for b in bs:
        if b.marked or b.lang == "text":
            continue
        if b.lang == "python":
            r = subprocess.run([sys.executable, "-c", "\n".join(b.body)], cwd=workdir, env=env,
                               capture_output=True, text=True, timeout=120)
            if r.returncode != 0:
                failures.append(f"{doc.name} line {b.line}: python block exited {r.returncode}\n"
                                f"{r.stdout}{r.stderr}")
        elif b.lang == "console":
            for cmd, status, expected in commands(b):
                r = subprocess.run(["bash", "-c", cmd], cwd=workdir, env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True, timeout=120)
                if r.returncode != status or not matches(expected, r.stdout):
                    failures.append(
                        f"{doc.name} line {b.line}: $ {cmd}\n  expected (status {status}):\n"
                        + "".join(f"    {e}\n" for e in expected)
                        + f"  got (status {r.returncode}):\n"
                        + "".join(f"    {a}\n" for a in r.stdout.splitlines()))
    return failures


def environment(daemon) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("VTOL_GCS_SIGNING_PASSPHRASE", "RUST_LOG", "VTOL_GCS_LINK")}
    bins = {str(DAEMON_BIN.resolve().parent), str(TWIN_BIN.resolve().parent)}
    env["PATH"] = os.pathsep.join([*sorted(bins), str(Path(sys.executable).parent),
                                   env.get("PATH", "")])
    if daemon is not None:
        env["VTOL_GCS_LINK"] = daemon.tcp
        env["DAEMON_TCP"] = daemon.tcp
        env["DAEMON_UDP"] = daemon.udp
    env["REPO"] = str(ROOT)
    return env


def scratch(tmp_path: Path) -> Path:
    work = tmp_path / "work"
    work.mkdir()
    (work / "config").symlink_to(ROOT / "config")
    (work / "docs").symlink_to(ROOT / "docs")
    return work


@pytest.mark.parametrize("doc", DOCS)
def test_every_example_runs_as_written(doc, tmp_path):
    daemon = start_daemon(tmp_path / "daemon", serve=["tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"],
                          log=False)
    try:
        failures = check(ROOT / doc, scratch(tmp_path), environment(daemon))
    finally:
        daemon.assert_clean_exit()
    assert not failures, "\n".join(failures)


# --- the checker itself ---------------------------------------------------------------------

FIXTURE = ROOT / "tests" / "docs_fixture.md"


@pytest.fixture(scope="module")
def daemon(module_daemon_factory):  # noqa: F811
    return module_daemon_factory(serve=["tcpin:127.0.0.1:0", "udpin:127.0.0.1:0"], log=False)


def test_the_fixture_holds(daemon, tmp_path):
    assert check(FIXTURE, scratch(tmp_path), environment(daemon)) == []


@pytest.mark.parametrize("change, failure", [
    # A flag the binary no longer has.
    ("$ vtol-gcs log stats --json", "$ vtol-gcs log stats --jsonn"),
    # An output that changed.
    ("not a tlog, or empty", "not a tlog or empty"),
    # An exit status that changed.
    ("? 2\n", "? 1\n"),
    # A python block that fails.
    ("assert sum([1, 2]) == 3", "assert sum([1, 2]) == 4"),
    # A block neither run nor marked.
    ("<!-- not run: needs a serial device -->\n", ""),
])
def test_a_drifted_document_fails(daemon, change, failure, tmp_path):
    text = FIXTURE.read_text()
    assert change in text, change
    broken = tmp_path / "broken.md"
    broken.write_text(text.replace(change, failure, 1))
    assert check(broken, scratch(tmp_path), environment(daemon)), f"{failure!r} went unnoticed"


def test_wildcards():
    assert matches(["a [..] c", "...", "z"], "a b c\nx\ny\nz\n")
    assert matches(["...", "z"], "z\n")
    assert not matches(["a [..] c", "z"], "a b c\nx\nz\n")
    assert not matches(["exact"], "exact but longer\n")
