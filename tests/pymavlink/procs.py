"""Process mechanics shared by the suite: the twin (conftest.py), the daemon (daemon_support.py)
and MAVProxy (test_mavproxy.py, test_daemon_mavproxy.py).

A `ManagedProcess` is spawned with its arguments in a work directory, with stderr to a file and
stdout piped. Its start is "announced": it prints one line per port-0 endpoint (matched by
`ENDPOINT_RE`, giving the real address) and maybe other start lines (`on_line`); `spawn` reads
them until `started()` holds, with a deadline as the upper bound (never a sleep), with the
vtol_twin plugin's start-line reader (`vtol_twin.startup`, which tests/run.sh installs into the
venv). Then a thread
drains stdout, keeping a bounded tail. `stop` signals it (SIGINT, like Ctrl-C) and
`assert_clean_exit` checks exit code 0 and no panic in stderr.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Generic, Iterator, TypeVar

import pexpect
import pytest
from vtol_twin.startup import ExitedAtStart, StartTimeout, read_start_lines

STDOUT_TAIL = 200  # stdout lines kept after the start (status lines, about 1 a second)


class ManagedProcess:
    """A binary of ours as a subprocess. Subclasses set `KIND` (for messages), `ENDPOINT_RE`
    (named groups `scheme` and `addr`) and may override `on_line` and `started`."""

    KIND = "process"
    ENDPOINT_RE: re.Pattern = re.compile(r"(?!)")  # matches nothing
    ENDPOINT_WORD = "endpoint"

    def __init__(self, proc: subprocess.Popen, args: list[str], workdir: Path, stderr_path: Path,
                 expected_endpoints: int = 0):
        self.proc = proc
        self.args = args
        self.workdir = workdir
        self.stderr_path = stderr_path
        self.expected_endpoints = expected_endpoints
        self.endpoints: list[tuple[str, str]] = []  # (scheme, address) as printed
        self.stdout_lines: list[str] = []
        self._drain: threading.Thread | None = None
        self._new_lines = threading.Condition()

    # -- start ------------------------------------------------------------------------------

    @classmethod
    def spawn(cls, args: list[str], workdir: Path, expected_endpoints: int, startup_timeout: float = 30.0,
              **attrs):
        """Starts `args` in `workdir` and reads its start lines (the instance gets `attrs` set
        before the first line is parsed)."""
        workdir.mkdir(parents=True, exist_ok=True)
        stderr_path = workdir / f"{cls.KIND}-{time.monotonic_ns()}.stderr"
        env = dict(os.environ)
        env.setdefault("RUST_LOG", "info")
        env.setdefault("RUST_BACKTRACE", "1")
        with open(stderr_path, "wb") as err:
            proc = subprocess.Popen(args, cwd=workdir, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                    stderr=err, env=env)
        p = cls(proc, args, workdir, stderr_path, expected_endpoints)
        for k, v in attrs.items():
            setattr(p, k, v)
        try:
            rest = p._read_start(startup_timeout)
            # Port-0 endpoints must come back with a real port.
            for scheme, addr in p.endpoints:
                if scheme in ("tcpin", "udpin"):
                    assert int(addr.rsplit(":", 1)[1]) > 0, p.endpoints
        except BaseException:
            proc.kill()
            proc.wait()
            raise
        p._drain = threading.Thread(target=p._drain_stdout, args=(rest,), daemon=True)
        p._drain.start()
        return p

    def on_line(self, text: str) -> None:
        """A start line that is not an endpoint line."""

    def started(self) -> bool:
        return len(self.endpoints) >= self.expected_endpoints

    def _read_start(self, timeout: float) -> bytes:
        """Reads stdout lines until started() (the plugin's start-line reader); returns the bytes
        read past the last full line."""
        try:
            return read_start_lines(self.proc, self._start_line, self.started, time.monotonic() + timeout)
        except StartTimeout:
            raise AssertionError(f"{self.KIND} did not print its start lines in {timeout} s "
                                 f"({len(self.endpoints)}/{self.expected_endpoints} {self.ENDPOINT_WORD}s); "
                                 f"args {self.args}\nstdout so far: {self.stdout_lines}\n{self.tail()}") from None
        except ExitedAtStart as e:
            raise AssertionError(f"{self.KIND} exited ({e.returncode}) at start; args {self.args}\n"
                                 f"stdout: {self.stdout_lines}\n{self.tail()}") from None

    def _start_line(self, text: str) -> None:
        self.stdout_lines.append(text)
        if m := self.ENDPOINT_RE.match(text):
            self.endpoints.append((m["scheme"], m["addr"]))
        else:
            self.on_line(text)

    def _drain_stdout(self, rest: bytes) -> None:
        fd = self.proc.stdout.fileno()
        while True:
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            rest += chunk
            *lines, rest = rest.split(b"\n")
            with self._new_lines:
                self.stdout_lines.extend(x.decode(errors="replace") for x in lines)
                del self.stdout_lines[:-STDOUT_TAIL]  # only the tail matters
                self._new_lines.notify_all()
        with self._new_lines:
            if rest:
                self.stdout_lines.append(rest.decode(errors="replace"))
            self._new_lines.notify_all()

    def wait_line(self, pattern: str, timeout: float = 10.0) -> str:
        """The first stdout line (start lines and the drained tail) matching the regex `pattern`,
        waiting for new lines with `timeout` as the upper bound."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout
        with self._new_lines:
            while True:
                for line in self.stdout_lines:
                    if rx.search(line):
                        return line
                left = deadline - time.monotonic()
                if left <= 0 or not self.alive():
                    raise AssertionError(f"no {self.KIND} line matching {pattern!r} in {timeout} s\n{self.tail()}")
                self._new_lines.wait(left)

    # -- addresses --------------------------------------------------------------------------

    def addr(self, scheme: str, nth: int = 0) -> str:
        found = [a for (s, a) in self.endpoints if s == scheme]
        assert len(found) > nth, f"no {scheme} {self.ENDPOINT_WORD} #{nth} in {self.endpoints}"
        return found[nth]

    def host_port(self, scheme: str, nth: int = 0) -> tuple[str, int]:
        host, port = self.addr(scheme, nth).rsplit(":", 1)
        return host, int(port)

    @property
    def tcp(self) -> str:
        """pymavlink URL of the first tcpin endpoint."""
        return "tcp:" + self.addr("tcpin")

    @property
    def udp(self) -> str:
        """pymavlink URL of the first udpin endpoint."""
        return "udpout:" + self.addr("udpin")

    # -- state and end ----------------------------------------------------------------------

    def stderr(self) -> str:
        try:
            return self.stderr_path.read_text(errors="replace")
        except OSError:
            return ""

    def tail(self) -> str:
        return f"stdout tail: {self.stdout_lines[-5:]}\nstderr tail:\n{self.stderr()[-3000:]}"

    def alive(self) -> bool:
        return self.proc.poll() is None

    def _join_drain(self) -> None:
        if self._drain is not None:
            self._drain.join(timeout=5)

    def kill9(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        self._join_drain()

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        """Signals the process (Ctrl-C by default) and returns its exit code (killed → negative)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
                raise AssertionError(f"{self.KIND} did not exit within {timeout:g} s of "
                                     f"{signal.Signals(sig).name}\n{self.tail()}")
        self._join_drain()
        return self.proc.returncode

    def assert_clean_exit(self, sig: int = signal.SIGINT) -> None:
        rc = self.stop(sig)
        err = self.stderr()
        assert rc == 0, f"{self.KIND} exited with {rc}\n{self.tail()}"
        assert "panicked" not in err, f"{self.KIND} panicked:\n{err[-3000:]}"


P = TypeVar("P", bound=ManagedProcess)


class ProcessFactory(Generic[P]):
    """Starts processes on demand with `start(workdir, **kw)`, each in its own `base/<prefix>N`
    unless given a `workdir`; stops every one of them (checking a clean exit) at teardown.
    The running ones are `procs`, also named `<prefix>s` (`twins`, `daemons`)."""

    def __init__(self, base: Path, start: Callable[..., P], prefix: str):
        self.base = base
        self.start = start
        self.prefix = prefix
        self.procs: list[P] = []
        setattr(self, f"{prefix}s", self.procs)  # the same list (only ever changed in place)
        self.n = 0

    def __call__(self, **kw) -> P:
        self.n += 1
        workdir = kw.pop("workdir", None) or self.base / f"{self.prefix}{self.n}"
        p = self.start(workdir, **kw)
        self.procs.append(p)
        return p

    def stop(self, p: P) -> None:
        self.procs.remove(p)
        p.assert_clean_exit()

    def forget(self, p: P) -> None:
        """For a process the test ended itself."""
        self.procs.remove(p)

    def close(self) -> None:
        errors = []
        for p in self.procs:
            try:
                p.assert_clean_exit()
            except AssertionError as e:  # keep stopping the others
                errors.append(str(e))
        self.procs.clear()
        assert not errors, "\n".join(errors)


def factory_fixtures(start: Callable[..., ManagedProcess], prefix: str):
    """The fixtures `<prefix>_factory` (a ProcessFactory(tmp_path, start, prefix) per test) and
    `module_<prefix>_factory` (one per module): each closes its factory at teardown, checking
    that every process it still holds exits cleanly."""

    def serve(f: ProcessFactory):
        yield f
        f.close()

    @pytest.fixture(name=f"{prefix}_factory")
    def per_test(tmp_path):
        yield from serve(ProcessFactory(tmp_path, start, prefix))

    @pytest.fixture(scope="module", name=f"module_{prefix}_factory")
    def per_module(tmp_path_factory):
        yield from serve(ProcessFactory(tmp_path_factory.mktemp(prefix), start, prefix))

    return per_test, per_module


# --------------------------------------------------------------------------------------------
# MAVProxy (through its console, with pexpect)
# --------------------------------------------------------------------------------------------

MAVPROXY = Path(sys.executable).parent / "mavproxy.py"
MAVPROXY_MODULES = "log,signing,ftp,param,arm,mode,cmdlong,misc"


@contextmanager
def mavproxy(master: str, workdir: Path, *, interactive: bool = True, cmd: str | None = None,
             timeout: float = 60, modules: str | None = MAVPROXY_MODULES) -> Iterator[pexpect.spawn]:
    """MAVProxy on `master`, with HOME `workdir/home`, state under `workdir/state` (aircraft
    "twin") and its output in `workdir/mavproxy.out`; no stream-rate requests; the modules
    `modules` (None: MAVProxy's own default list, wp, fence, rally, battery… included). Yields
    the pexpect child; stops it with SIGTERM at the end (its quit handler)."""
    home = workdir / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MAVLINK20")}
    env.update(HOME=str(home), TERM="dumb", PYTHONUNBUFFERED="1")
    exe = str(MAVPROXY) if MAVPROXY.exists() else shutil.which("mavproxy.py")
    assert exe, "mavproxy.py not installed in the venv"
    args = [exe, "--master", master]
    if not interactive:
        args.append("--non-interactive")
    args += [
        "--streamrate=-1",
        "--state-basedir", str(workdir / "state"),
        "--aircraft", "twin",
    ]
    if modules is not None:
        args += ["--default-modules", modules]
    if cmd is not None:
        args += ["--cmd", cmd]
    with open(workdir / "mavproxy.out", "w") as log:
        child = pexpect.spawn(sys.executable, args, cwd=str(workdir), env=env, encoding="utf-8",
                              timeout=timeout, codec_errors="replace")
        child.logfile_read = log
        try:
            yield child
        finally:
            if child.isalive():
                child.kill(signal.SIGTERM)  # MAVProxy's quit handler sets its stop event…
                if interactive:
                    child.sendline("")  # …which its console loop checks after the next line
                try:
                    child.expect(pexpect.EOF, timeout=15)
                except (pexpect.TIMEOUT, pexpect.EOF):
                    pass
            child.close(force=True)
