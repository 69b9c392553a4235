"""``lago_cvx.allocator.keep_freed_memory``: glibc takes the thresholds where it is the C library, nothing
changes elsewhere, and only the ``lago-cvx`` console entry point calls it (never ``import lago_cvx``,
``lago()`` or ``main(argv)`` called in process). Each case runs in a child process, so the test process
keeps glibc's defaults."""

from __future__ import annotations

import platform
import subprocess
import sys

import pytest

GLIBC = platform.libc_ver()[0] == "glibc"


def _child(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_keep_freed_memory_is_taken_once_and_reports_itself():
    code = ("from lago_cvx import allocator as a\n"
            "first = a.keep_freed_memory(); again = a.keep_freed_memory()\n"
            "print(first, again, sorted(a._APPLIED.items()))")
    first, again, applied = _child(code).split(" ", 2)
    assert first == again == str(GLIBC)
    assert applied == f"[(({16 << 20}, {64 << 20}), {GLIBC})]"


def test_without_glibc_nothing_changes(monkeypatch):
    from lago_cvx import allocator

    def no_libc(*args, **kwargs):
        raise OSError("no C library here")

    monkeypatch.setattr(allocator, "_APPLIED", {})
    monkeypatch.setattr(allocator.ctypes, "CDLL", no_libc)
    assert allocator.keep_freed_memory() is False


def test_only_the_console_entry_point_tunes_the_allocator():
    code = ("import sys\n"
            "from lago_cvx import allocator as a, lago, manhattan_world\n"
            "from lago_cvx.cli.main import main\n"
            "lago(manhattan_world(30, seed=0).graph)\n"
            "try:\n"
            "    main(['--version'])\n"
            "except SystemExit:\n"
            "    pass\n"
            "print('in process', bool(a._APPLIED))\n"
            "sys.argv = ['lago-cvx', '--version']\n"
            "try:\n"
            "    main()\n"
            "except SystemExit:\n"
            "    pass\n"
            "print('entry point', bool(a._APPLIED))\n")
    lines = [line for line in _child(code).splitlines() if not line.startswith("lago-cvx ")]
    assert lines == ["in process False", f"entry point {GLIBC}"]
