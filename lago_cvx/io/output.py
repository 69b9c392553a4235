"""Where an output goes, and how it gets there without destroying what it should not.

:func:`open_output` is the one way lago_cvx writes a file (``write_graph`` uses it; so can the CLI).
What the target is decides how it is written:

=============================================  ====================================================
target                                         what happens
=============================================  ====================================================
``"-"``                                        standard output (its binary buffer), flushed, never
                                               closed
regular file, or a name that does not exist    a temporary file in the same directory, flushed and
yet                                            fsync'ed, then ``os.replace`` (atomic: a reader sees
                                               the old file or the new one, never half of it); an
                                               existing file keeps its permission bits (and, when
                                               allowed, its owner); a new one gets ``0666 & ~umask``
symbolic link (also dangling, also a chain)    written through to its final target, by the rule
                                               above; the link stays a link; a dangling link
                                               creates its target
FIFO, character device (``/dev/null``,         streamed directly, never replaced: a FIFO's reader
``/dev/full``, a terminal)                     gets the whole output and it stays a FIFO
directory, socket, block device, ``""``        :class:`~lago_cvx.errors.OutputError`, nothing
                                               written
=============================================  ====================================================

Every failure — a missing directory, no permission (an existing file without write permission is not
replaced either), a read-only file system, a directory that accepts no new files (``/proc``), a write
error such as ENOSPC on ``/dev/full`` or a full disk — raises ``OutputError`` (an ``OSError``, CLI exit
status 2) with one line naming the path as the caller gave it and the reason, never the temporary file;
the temporary file is removed (also on ``KeyboardInterrupt``) and an existing target is left as it was.

:func:`same_file` tells whether two names are one file (through symbolic and hard links), so that a
caller can refuse to write an estimate over its own input.
"""

from __future__ import annotations

import contextlib
import errno as _errno
import os
import stat
import sys
import tempfile

from ..errors import LagoError, OutputError

__all__ = ["open_output", "same_file", "STDOUT"]

#: The output name that means standard output.
STDOUT = "-"


def _shown(path) -> str:
    return os.fspath(path) if isinstance(path, os.PathLike) else str(path)


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


def _fail(shown: str, reason: str, code: int | None = None) -> OutputError:
    return OutputError(f"cannot write {shown}: {reason}", path=shown, errno=code)


def _from_oserror(shown: str, exc: OSError) -> OutputError:
    return _fail(shown, _reason(exc), exc.errno)


def same_file(a, b) -> bool:
    """True when ``a`` and ``b`` name the same existing file — the same device and inode after
    following symbolic links, so hard links and symlinks to one file count as the same. False when
    either does not exist (or cannot be examined), and for the standard-output name ``"-"``."""
    if _shown(a) in (STDOUT, "") or _shown(b) in (STDOUT, ""):
        return False
    try:
        sa, sb = os.stat(a), os.stat(b)
    except (OSError, ValueError):
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def _default_mode() -> int:
    """0666 & ~umask, the permissions ``open()`` would give a new file."""
    try:  # Linux: read the umask without changing it
        with open("/proc/self/status") as f:
            mask = next(int(ln.split()[1], 8) for ln in f if ln.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0)  # elsewhere: the classic (briefly process-wide) set-and-restore
        os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def open_output(path):
    """Context manager yielding a binary file object that writes to ``path`` by the rules of the
    module docstring. The output is complete (replaced atomically, or streamed and flushed) when the
    ``with`` block ends without an exception; if the block raises, a temporary file is removed, an
    existing target is left untouched, and the exception propagates (an ``OSError`` from writing is
    turned into :class:`OutputError`)."""
    shown = _shown(path)
    if shown == "":
        raise OutputError("cannot write to an empty file name", path=shown)
    if shown == STDOUT:
        with _stdout(shown) as f:
            yield f
        return
    try:
        st = os.stat(shown)  # follows symbolic links
    except FileNotFoundError:
        st = None  # a new file, a dangling link, or a missing directory (found out below)
    except OSError as exc:  # ELOOP, ENOTDIR, EACCES on a directory on the way, ...
        raise _from_oserror(shown, exc) from None
    if st is not None:
        mode = st.st_mode
        if stat.S_ISDIR(mode):
            raise _fail(shown, "it is a directory", _errno.EISDIR)
        if stat.S_ISSOCK(mode):
            raise _fail(shown, "it is a socket, not a file")
        if stat.S_ISBLK(mode):
            raise _fail(shown, "it is a block device; refusing to write a pose graph onto it")
        if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode):
            with _stream(shown) as f:
                yield f
            return
        if not stat.S_ISREG(mode):
            raise _fail(shown, f"it is not a regular file (mode {stat.filemode(mode)})")
    target = os.path.realpath(shown) if os.path.islink(shown) else shown
    with _replace(shown, target, st) as f:
        yield f


@contextlib.contextmanager
def _stdout(shown: str):
    stream = sys.stdout
    if stream is None:  # pythonw, or closed on purpose
        raise OutputError("cannot write to standard output: there is none", path=shown)
    buffer = getattr(stream, "buffer", None)
    try:
        if buffer is not None:
            stream.flush()  # text already written to sys.stdout comes first
            yield buffer
            buffer.flush()
        else:  # a text-only stand-in (io.StringIO): decode what we write
            sink = _TextSink(stream)
            yield sink
            stream.flush()
    except OSError as exc:
        raise _fail("standard output", _reason(exc), exc.errno) from None


class _TextSink:
    """A binary ``write`` onto a text stream (ASCII output only)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, data) -> int:
        self._stream.write(bytes(data).decode("ascii"))
        return len(data)

    def flush(self) -> None:
        self._stream.flush()


@contextlib.contextmanager
def _stream(shown: str):
    """FIFO or character device: open it for writing (a FIFO blocks until a reader opens it) and
    write straight into it; it is never replaced."""
    try:
        f = open(shown, "wb")  # noqa: SIM115 - closed below, errors mapped
    except OSError as exc:
        raise _from_oserror(shown, exc) from None
    try:
        yield f
        f.flush()
    except OSError as exc:
        _close_quietly(f)
        raise _from_oserror(shown, exc) from None
    except BaseException:
        _close_quietly(f)
        raise
    try:
        f.close()
    except OSError as exc:
        raise _from_oserror(shown, exc) from None


def _close_quietly(f) -> None:
    try:
        f.close()
    except OSError:
        pass


@contextlib.contextmanager
def _replace(shown: str, target: str, st):
    """Write a temporary file beside ``target`` and move it over ``target`` when done."""
    directory = os.path.dirname(target) or "."
    if st is not None and not os.access(target, os.W_OK):
        if _read_only_fs(directory):
            raise _fail(shown, f"read-only file system ({directory})", _errno.EROFS)
        raise _fail(shown, "permission denied (the file is not writable)", _errno.EACCES)
    mode = st.st_mode & 0o7777 if st is not None else _default_mode()
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(target)}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise _fail(shown, _create_reason(directory, exc), exc.errno) from None
    f = os.fdopen(fd, "wb")
    try:
        yield f
        f.flush()
        os.fsync(f.fileno())
        f.close()
        if st is not None and (st.st_uid, st.st_gid) != _owner(tmp):
            try:  # keep the owner when allowed (root replacing a user's file)
                os.chown(tmp, st.st_uid, st.st_gid)
            except OSError:
                pass
        os.chmod(tmp, mode)
        os.replace(tmp, target)
    except BaseException as exc:
        _close_quietly(f)
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError) and not isinstance(exc, LagoError):
            raise _from_oserror(shown, exc) from None
        raise


def _read_only_fs(directory: str) -> bool:
    try:
        return bool(os.statvfs(directory).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        return False


def _owner(path: str) -> tuple[int, int]:
    s = os.stat(path)
    return s.st_uid, s.st_gid


def _create_reason(directory: str, exc: OSError) -> str:
    """Why no file could be created in ``directory`` (the temporary file is not named)."""
    if exc.errno == _errno.ENOENT:
        if not os.path.isdir(directory):
            return f"directory {directory} does not exist"
        return f"{directory} does not accept new files ({_reason(exc)})"
    if exc.errno == _errno.ENOTDIR:
        return f"{directory} is not a directory"
    if exc.errno in (_errno.EACCES, _errno.EPERM):
        return f"permission denied (cannot create a file in {directory})"
    if exc.errno == _errno.EROFS:
        return f"read-only file system ({directory})"
    return _reason(exc)
