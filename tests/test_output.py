"""Where write_graph's bytes go (lago_cvx.io.output): regular files replaced atomically, symlinks written
through, FIFOs and character devices streamed, "-" to standard output, and a one-line OutputError naming
the user's path for everything that cannot be written — with nothing left behind."""

from __future__ import annotations

import errno
import os
import socket
import stat
import threading

import numpy as np
import pytest

import lago_cvx.io.output as output
from lago_cvx.errors import LagoError, OptionError, OutputError
from lago_cvx.io import open_output, read_graph, same_file, write_graph
from lago_cvx.synthetic import manhattan_world

GRAPH = manhattan_world(60, seed=4).graph


def _expected(tmp_path, poses=None) -> bytes:
    """The bytes write_graph produces for GRAPH, via an ordinary new file."""
    ref = tmp_path / "reference"
    ref.mkdir(exist_ok=True)
    return write_graph(ref / "ref.g2o", GRAPH, poses).read_bytes()


def _listing(folder) -> list[str]:
    return sorted(os.listdir(folder))


def _check_error(exc: OutputError, shown: str, *fragments: str):
    msg = str(exc)
    assert isinstance(exc, OSError) and isinstance(exc, LagoError) and exc.exit_status == 2
    assert "\n" not in msg
    assert msg.startswith(f"cannot write {shown}") or msg.startswith("cannot write to an empty file name"), msg
    assert ".tmp" not in msg, msg  # never the temporary file's name
    for fragment in fragments:
        assert fragment in msg, msg


# ------------------------------------------------------------------------------------ regular files
def test_new_file_and_no_temporary_left(tmp_path):
    out = tmp_path / "out" / "g.g2o"
    out.parent.mkdir()
    assert write_graph(out, GRAPH, wrap_angles=False) == out
    assert _listing(out.parent) == ["g.g2o"]
    assert read_graph(out).equals(GRAPH)


def test_existing_file_keeps_permission_bits(tmp_path):
    out = tmp_path / "g.g2o"
    out.write_text("old\n")
    os.chmod(out, 0o604)
    write_graph(out, GRAPH)
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o604
    assert out.read_bytes() == _expected(tmp_path)


def test_failed_write_leaves_old_file_and_no_temporary(tmp_path, monkeypatch):
    out = tmp_path / "g.g2o"
    out.write_text("old\n")

    def no_space(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(output.os, "fsync", no_space)
    with pytest.raises(OutputError) as ei:
        write_graph(out, GRAPH)
    _check_error(ei.value, str(out), "No space left on device")
    assert ei.value.errno == errno.ENOSPC
    assert out.read_text() == "old\n"
    assert _listing(tmp_path) == ["g.g2o"]


def test_interrupted_write_leaves_nothing(tmp_path, monkeypatch):
    import lago_cvx.io.writer as writer

    calls = []

    def interrupted(tag, ids, values):
        calls.append(tag)
        if len(calls) > 1:
            raise KeyboardInterrupt
        return b"VERTEX_SE2 0 0.0 0.0 0.0\n"

    monkeypatch.setattr(writer, "format_records", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_graph(tmp_path / "g.g2o", GRAPH)
    assert _listing(tmp_path) == []


# ------------------------------------------------------------------------------------ links
def test_symlink_is_written_through(tmp_path):
    target = tmp_path / "data" / "target.g2o"
    target.parent.mkdir()
    target.write_text("old\n")
    os.chmod(target, 0o640)
    link = tmp_path / "link.g2o"
    link.symlink_to(os.path.relpath(target, tmp_path))  # a relative link
    chain = tmp_path / "chain.g2o"
    chain.symlink_to(link)
    write_graph(chain, GRAPH)
    assert chain.is_symlink() and link.is_symlink() and not target.is_symlink()
    assert target.read_bytes() == _expected(tmp_path)
    assert stat.S_IMODE(os.stat(target).st_mode) == 0o640
    assert _listing(target.parent) == ["target.g2o"] and _listing(tmp_path) == ["chain.g2o", "data", "link.g2o",
                                                                                "reference"]


def test_dangling_symlink_creates_its_target(tmp_path):
    link = tmp_path / "link.g2o"
    link.symlink_to(tmp_path / "new.g2o")
    write_graph(link, GRAPH)
    assert link.is_symlink()
    assert (tmp_path / "new.g2o").read_bytes() == _expected(tmp_path)


def test_dangling_symlink_into_missing_directory(tmp_path):
    link = tmp_path / "link.g2o"
    link.symlink_to(tmp_path / "nowhere" / "new.g2o")
    with pytest.raises(OutputError) as ei:
        write_graph(link, GRAPH)
    _check_error(ei.value, str(link), "does not exist")
    assert link.is_symlink() and _listing(tmp_path) == ["link.g2o"]


def test_symlink_loop(tmp_path):
    a, b = tmp_path / "a.g2o", tmp_path / "b.g2o"
    a.symlink_to(b)
    b.symlink_to(a)
    with pytest.raises(OutputError) as ei:
        write_graph(a, GRAPH)
    _check_error(ei.value, str(a), "symbolic links")
    assert a.is_symlink() and b.is_symlink()


def test_same_file(tmp_path):
    a = tmp_path / "a.g2o"
    a.write_text("x\n")
    hard = tmp_path / "hard.g2o"
    os.link(a, hard)
    soft = tmp_path / "soft.g2o"
    soft.symlink_to(a)
    other = tmp_path / "other.g2o"
    other.write_text("x\n")
    assert same_file(a, hard) and same_file(soft, a) and same_file(str(a), a)
    assert not same_file(a, other)
    assert not same_file(a, tmp_path / "missing.g2o") and not same_file("-", a)


# ------------------------------------------------------------------------------------ special files
def test_fifo_is_streamed_and_stays_a_fifo(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []

    def reader():
        with open(fifo, "rb") as f:
            received.append(f.read())

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    write_graph(fifo, GRAPH)
    thread.join(timeout=30)
    assert not thread.is_alive()
    assert received == [_expected(tmp_path)]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert _listing(tmp_path) == ["pipe", "reference"]


def test_dev_null_stays_a_device():
    if not os.path.exists("/dev/null"):
        pytest.skip("no /dev/null")
    write_graph("/dev/null", GRAPH)
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_dev_full_reports_no_space():
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    with pytest.raises(OutputError) as ei:
        write_graph("/dev/full", GRAPH)
    _check_error(ei.value, "/dev/full", "No space left on device")
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_stdout(tmp_path, capsysbinary):
    assert str(write_graph("-", GRAPH)) == "-"
    assert capsysbinary.readouterr().out == _expected(tmp_path)
    with open_output("-") as f:  # not closed: usable again
        f.write(b"more\n")
    assert capsysbinary.readouterr().out == b"more\n"


# ------------------------------------------------------------------------------------ refusals
def test_empty_name():
    with pytest.raises(OutputError) as ei:
        write_graph("", GRAPH)
    _check_error(ei.value, "", "empty file name")


def test_missing_directory(tmp_path):
    out = tmp_path / "nowhere" / "g.g2o"
    with pytest.raises(OutputError) as ei:
        write_graph(out, GRAPH)
    _check_error(ei.value, str(out), f"directory {tmp_path / 'nowhere'} does not exist")
    assert _listing(tmp_path) == []


def test_directory(tmp_path):
    with pytest.raises(OutputError) as ei:
        write_graph(tmp_path, GRAPH)
    _check_error(ei.value, str(tmp_path), "it is a directory")
    assert _listing(tmp_path) == []


def test_socket(tmp_path):
    path = tmp_path / "sock"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        try:
            s.bind(str(path))
        except OSError as exc:
            pytest.skip(f"cannot create a UNIX socket here: {exc}")
        with pytest.raises(OutputError) as ei:
            write_graph(path, GRAPH)
        _check_error(ei.value, str(path), "socket")
        assert stat.S_ISSOCK(os.stat(path).st_mode)
    finally:
        s.close()


def test_file_in_proc_cannot_be_replaced():
    """/proc accepts no new files, even for root (where permission bits do not bite)."""
    if not os.path.isfile("/proc/version"):
        pytest.skip("no /proc/version (not Linux)")
    before = open("/proc/version", "rb").read()
    with pytest.raises(OutputError) as ei:
        write_graph("/proc/version", GRAPH)
    _check_error(ei.value, "/proc/version", "/proc")
    assert open("/proc/version", "rb").read() == before
    with pytest.raises(OutputError) as ei:
        write_graph("/proc/lago_cvx_new.g2o", GRAPH)
    _check_error(ei.value, "/proc/lago_cvx_new.g2o", "/proc")


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="permission bits do not bite as root")
def test_permission_denied(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    os.chmod(locked, 0o500)
    try:
        with pytest.raises(OutputError) as ei:
            write_graph(locked / "g.g2o", GRAPH)
        _check_error(ei.value, str(locked / "g.g2o"), "permission denied")
    finally:
        os.chmod(locked, 0o700)
    ro = tmp_path / "ro.g2o"
    ro.write_text("old\n")
    os.chmod(ro, 0o444)
    with pytest.raises(OutputError) as ei:
        write_graph(ro, GRAPH)
    _check_error(ei.value, str(ro), "not writable")
    assert ro.read_text() == "old\n"


def test_non_finite_poses_write_nothing(tmp_path):
    out = tmp_path / "g.g2o"
    out.write_text("old\n")
    poses = GRAPH.initial.copy()
    poses[7, 1] = np.nan
    poses[9, 2] = np.inf
    for target in (out, tmp_path / "new.g2o"):
        with pytest.raises(OptionError) as ei:
            write_graph(target, GRAPH, poses)
        msg = str(ei.value)
        assert f"refusing to write {target}: 2 of 60 poses are not finite (first: id 7 = (" in msg
        assert "nan" in msg and "nothing was written" in msg
    assert out.read_text() == "old\n" and _listing(tmp_path) == ["g.g2o"]
    fifo = tmp_path / "pipe"  # not even opened (opening a FIFO would wait for a reader)
    os.mkfifo(fifo)
    with pytest.raises(OptionError):
        write_graph(fifo, GRAPH, poses)
