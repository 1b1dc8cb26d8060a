"""Files are written without harm: `params pull -o`, `params save` and `log export` write a
regular file atomically, `-` to standard output, and a device, a FIFO or a symbolic link's target
in place, each left as it was (never replaced by a regular file) and written into."""

from __future__ import annotations

import os
import stat
import subprocess
import threading
from pathlib import Path

import pytest

from test_first_hour import gcs
from test_log_conventions import write_log


def pulled(twin, out: str) -> subprocess.CompletedProcess:
    r = gcs("params", "pull", "-o", out, "--link", twin.tcp)
    assert r.returncode == 0, r.stderr
    return r


def test_pull_to_standard_output(twin):
    r = pulled(twin, "-")
    plain = gcs("params", "pull", "--link", twin.tcp)
    assert r.stdout and r.stdout.splitlines()[0] == plain.stdout.splitlines()[0]
    assert "HOVER_ALT" in r.stdout and "written to -" in r.stderr
    assert not Path("-").exists()


def test_pull_through_a_symlink_writes_its_target(twin, tmp_path):
    target = tmp_path / "real.parm"
    target.write_text("old\n")
    link = tmp_path / "link.parm"
    link.symlink_to(target)
    pulled(twin, str(link))
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert "HOVER_ALT" in target.read_text()


def test_pull_into_a_fifo_with_a_reader(twin, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got: list[str] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    pulled(twin, str(fifo))
    reader.join(timeout=30)
    assert not reader.is_alive()
    assert "HOVER_ALT" in got[0]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_pull_into_a_device_node(twin, tmp_path):
    dev = tmp_path / "null"
    try:
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("making a device node needs root")
    pulled(twin, str(dev))
    assert stat.S_ISCHR(os.lstat(dev).st_mode)
    pulled(twin, str(dev))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null"]


def test_save_to_standard_output(twin):
    r = gcs("params", "save", "-", "--link", twin.tcp)
    assert r.returncode == 0, r.stderr
    assert "HOVER_ALT" in r.stdout and "written to -" in r.stderr


def test_export_to_standard_output_and_a_fifo(tmp_path):
    log = write_log(tmp_path / "f.tlog", seed=5, link_bits=False)
    r = gcs("log", "export", str(log), "--csv", "-", "--messages", "ATTITUDE", "--rate", "10")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("t,") and "wrote -" in r.stderr
    r = subprocess.run([*gcs_cmd(), "log", "export", str(log), "--mcap", "-"], capture_output=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout[:8] == b"\x89MCAP0\r\n" and r.stdout[-8:] == b"\x89MCAP0\r\n"
    fifo = tmp_path / "mcap"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    r = gcs("log", "export", str(log), "--mcap", str(fifo))
    reader.join(timeout=30)
    assert r.returncode == 0, r.stderr
    assert got and got[0][:8] == b"\x89MCAP0\r\n"
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def gcs_cmd() -> list[str]:
    from daemon_support import DAEMON_BIN
    return [str(DAEMON_BIN)]
