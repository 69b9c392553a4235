"""The vectorized fast path of ``read_graph``: ordinary files at the speed of the machine.

The file is processed in chunks of about :data:`CHUNK` bytes cut at line ends (they stay in the CPU's
cache), each by a fixed number of NumPy passes — never a Python step per line or per token:

1. line starts (the ``\\n`` positions); the record tag of every line, compared as 8-byte words; the tag
   bytes blanked. Lines without a tag — blank lines, comments, ``FIX``/``EQUIV`` — are few; they are
   checked one by one (exactly as ``careful.py`` does) and blanked. A ``#`` that starts a token on a
   data line blanks the rest of the line (an inline comment). Tabs and CRs become spaces.
2. the token grammar, on the sparse set of token starts and non-digit characters: only ``[0-9.eE+-]``
   and ASCII whitespace may remain; a ``-`` starts a token or follows an exponent mark, a ``+`` only
   follows one; a ``.`` sits between digits; an ``e``/``E`` follows a digit and precedes a digit or a
   sign; within a token at most one ``.``, at most one exponent, no ``.`` after it — i.e. every token
   is ``-?D+(.D+)?([eE][+-]?D+)?``; ids have no ``.`` and no exponent.
3. the token count of every data line (planar: 4 numbers after a vertex tag, 11 after an edge tag; 3-D
   records, passed in by ``space.py``: 8 and 30).
4. each token put on a line of its own, for the bulk conversion.

All numbers are then converted at once: by SciPy's Matrix Market reader (``scipy.io.mmread``, the
C++ *fast_matrix_market*: correctly rounded like ``float()``, multi-threaded; the body is presented as
a one-column real array) when it is there and the file is large enough to repay importing it, else by
``np.fromstring``. That reader turns ``-0`` into +0.0, so the sign of every token that starts with
``-`` is set afterwards (``float("-0.0")`` is −0.0). A few tokens per chunk are compared with
``float()`` bit for bit, so a misbehaving converter (say, a locale with a decimal comma) sends the
file to the careful parser instead of giving wrong numbers.

Anything else — a leading ``+``, ``.5`` or ``5.``, indented lines, non-ASCII bytes outside comments,
control characters, an unknown or misplaced tag, a wrong token count, an id beyond 2⁵³, a value that
overflows — returns None, and ``careful.py`` reads the file and names the problem. Hence the fast path
never decides an error message: it either returns exactly what the careful parser would, or nothing.
"""

from __future__ import annotations

import logging
import mmap
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..sparse import cores
from .careful import BOM, Notes, Parsed, floats_or_none, ignored_line, without_comment
from .formats import EQUIV, FIX, FORMAT_SPECS, SPECS

__all__ = ["parse_fast", "CHUNK"]

logger = logging.getLogger("lago_cvx.io")

#: Bytes per chunk (a chunk ends at a line end, so it may be longer).
CHUNK = 1 << 20
#: Below this many numbers, ``np.fromstring`` converts them: importing ``scipy.io`` would cost more than its faster
#: conversion saves (``benchmarks/io.md``).
MMREAD_MIN_TOKENS = 1_500_000
#: Threads for the chunk pass: at most this many, and no more than the cores this process may use now
#: (``sparse.cores()``).
WORKERS = 4
_PAD = 16              # newline padding after a chunk: 8-byte tag words and next-character looks stay inside
_HEADER = 128          # room for the Matrix Market header before the body
_EXACT_INT = 2.0 ** 53
_DIGIT = np.uint8(48)
_MAX_SCAN = 10_000     # lines looked at to find the first data tag


class _GiveUp(Exception):
    """Something unusual: the careful parser takes over."""


def _first_format(data: bytes, start: int) -> str | None:
    """The format of the first data tag (comments, blank, FIX and EQUIV lines skipped), or None."""
    pos, n = start, len(data)
    for _ in range(_MAX_SCAN):
        if pos >= n:
            return None
        end = data.find(b"\n", pos)
        end = n if end < 0 else end
        toks = data[pos:end].split(None, 1)
        pos = end + 1
        if not toks or toks[0][:1] == b"#" or toks[0] in (b"FIX", b"EQUIV"):
            continue
        spec = SPECS.get(toks[0].decode("ascii", "replace"))
        return None if spec is None else spec.fmt
    return None


class _Tag:
    """A record tag, matched on the first 16 bytes of every line (two little-endian 8-byte words) and
    followed by a space or a tab."""

    def __init__(self, tag: str, kind: int, n_numbers: int):
        raw = tag.encode("ascii")
        self.kind, self.n_numbers, self.length = kind, n_numbers, len(raw)
        padded = raw.ljust(16, b"\0")
        mask = (b"\xff" * len(raw)).ljust(16, b"\0")
        self.value = np.frombuffer(padded, "<u8")
        self.mask = np.frombuffer(mask, "<u8")

    def match(self, heads: np.ndarray) -> np.ndarray:
        """``heads``: (k, 16) uint8, the first bytes of k lines."""
        words = heads.view("<u8")
        sep = heads[:, self.length]
        hit = (words[:, 0] & self.mask[0]) == self.value[0]
        hit &= (words[:, 1] & self.mask[1]) == self.value[1]
        return hit & ((sep == 32) | (sep == 9))


class _Scratch:
    """Buffers reused from chunk to chunk (fresh 1 MB arrays would cost page faults every time)."""

    def __init__(self, n: int):
        size = n + _PAD
        self.buf = np.empty(size, np.uint8)
        self.heads = np.lib.stride_tricks.as_strided(self.buf, (size - 15, 16), (1, 1))
        self.u8 = np.empty(size, np.uint8)
        self.b1 = np.empty(size, bool)
        self.b2 = np.empty(size, bool)
        self.b3 = np.empty(size, bool)


@dataclass
class _Piece:
    """What one chunk contributes, in chunk-local numbers (merged in file order by ``_Chunks.run``)."""
    kinds: np.ndarray       # kind of each data line
    lines: np.ndarray       # 0-based index, within the chunk, of each data line
    n_lines: int
    n_tokens: int
    negative: np.ndarray    # per token: starts with '-'
    samples: list           # (token index within the chunk, token bytes)
    ignored: list           # (line index within the chunk, tokens) of FIX / EQUIV lines


class _Chunks:
    """The per-chunk pass (module docstring): fills the conversion buffer and collects, per data line,
    its kind (0 vertex, 1 edge) and line number. Chunks are independent until merged in file order, so
    up to :data:`WORKERS` threads run them (NumPy releases the GIL in its loops)."""

    def __init__(self, data: bytes, specs: tuple, start: int, out: np.ndarray):
        self.data, self.start, self.out = data, start, out
        vspec, espec = specs
        self.tags = (_Tag(vspec.tag, 0, vspec.n_tokens - 1), _Tag(espec.tag, 1, espec.n_tokens - 1))
        self.arity = np.array([t.n_numbers for t in self.tags], np.int64)
        self.fix, self.equiv = Notes(), Notes()
        self.kinds, self.lines, self.samples, self.negative = [], [], [], []
        self.n_tokens = 0
        self._local = threading.local()
        self._stop = False

    def _buffers(self, n: int) -> _Scratch:
        sc = getattr(self._local, "scratch", None)
        if sc is None or sc.buf.size < n + _PAD:
            sc = self._local.scratch = _Scratch(max(n, CHUNK + 4096))
        return sc

    def _bounds(self) -> list:
        data, n_total, a, bounds = self.data, len(self.data), self.start, []
        while a < n_total:
            b = data.find(b"\n", min(a + CHUNK, n_total) - 1)
            b = n_total if b < 0 else b + 1
            bounds.append((a, b))
            a = b
        return bounds

    def _guarded(self, bounds) -> _Piece:
        if self._stop:  # another chunk gave up: no need to go on
            raise _GiveUp
        try:
            return self._chunk(*bounds)
        except _GiveUp:
            self._stop = True
            raise

    def run(self) -> None:
        """Process every chunk, then merge the pieces in file order (``_GiveUp`` if any gave up)."""
        bounds = self._bounds()
        workers = min(WORKERS, cores(), len(bounds))
        if workers > 1:
            with ThreadPoolExecutor(workers) as pool:
                pieces = list(pool.map(self._guarded, bounds))
        else:
            pieces = [self._chunk(a, b) for a, b in bounds]
        line_base = 0
        for piece in pieces:
            for i, toks in piece.ignored:
                (self.fix if toks[0] == FIX else self.equiv).add(line_base + i + 1, toks)
            self.kinds.append(piece.kinds)
            self.lines.append(line_base + 1 + piece.lines)
            self.negative.append(piece.negative)
            self.samples.extend((self.n_tokens + t, token) for t, token in piece.samples)
            self.n_tokens += piece.n_tokens
            line_base += piece.n_lines

    @staticmethod
    def _rare(line: bytes, index: int, ignored: list) -> None:
        """A line without a data tag at its start: blank, comment, FIX, EQUIV — anything else gives up."""
        toks = without_comment(line.decode("utf-8", "surrogateescape")).split()  # no BOM stripping here
        if not toks:
            return
        if toks[0] not in (FIX, EQUIV) or ignored_line(toks, index + 1, Notes(), Notes()) is not None:
            raise _GiveUp
        ignored.append((index, toks))

    def _chunk(self, a: int, b: int) -> _Piece:
        data, n = self.data, b - a
        sc = self._buffers(n)
        buf = sc.buf
        body = buf[:n]
        body[:] = np.frombuffer(data, np.uint8, n, a)
        buf[n:n + _PAD] = 10
        ends = np.flatnonzero(np.equal(body, 10, out=sc.b1[:n]))
        starts = np.empty(ends.size + 1, np.int64)
        starts[0] = 0
        starts[1:] = ends + 1
        if starts[-1] >= n:
            starts = starts[:-1]

        # 1. tags, rare lines, comments, tabs
        kind = np.full(starts.size, -1, np.int8)
        heads = sc.heads[starts]
        for tag in self.tags:
            hit = tag.match(heads)
            kind[hit] = tag.kind
            sc.heads[starts[hit], :tag.length] = 32  # rows do not overlap where written
        rare = np.flatnonzero((kind < 0) & (heads[:, 0] != 10))
        ignored = []
        if rare.size:
            line_end = np.append(ends, n)[:starts.size]
            for i in rare.tolist():
                s, e = int(starts[i]), int(line_end[i])
                self._rare(data[a + s:a + e], i, ignored)
                body[s:e] = 32
        if data.find(b"#", a, b) >= 0:
            self._inline_comments(body, buf, starts, np.append(ends, n)[:starts.size])
        if data.find(b"\t", a, b) >= 0 or data.find(b"\r", a, b) >= 0:
            body[(body == 9) | (body == 13)] = 32
        if np.count_nonzero(np.less(body, 32, out=sc.b1[:n])) != ends.size:
            raise _GiveUp  # control characters (str.split would take some of them for whitespace)

        # 2. token grammar on the "entries": token starts and non-digit characters (entry k is at
        #    position e0[k] + 1)
        ext = buf[:n + 1]
        ws = np.less_equal(ext, 32, out=sc.b2[:n + 1])
        nondigit = np.greater(np.subtract(ext, _DIGIT, out=sc.u8[:n + 1]), 9, out=sc.b3[:n + 1])
        marks = np.bitwise_or(ws[:-1], nondigit[1:], out=sc.b1[:n])
        np.greater(marks, ws[1:], out=marks)  # (prev ws or not a digit) and not ws
        e0 = np.flatnonzero(marks)
        before, c, after = buf.take(e0), buf[1:].take(e0), buf[2:].take(e0)
        is_start = before <= 32
        digit_before = before - _DIGIT <= 9
        digit_after = after - _DIGIT <= 9
        exp_before = (before | 32) == 101
        minus, plus, dot, exp = c == 45, c == 43, c == 46, (c | 32) == 101
        ok = c - _DIGIT <= 9  # a token starting with a digit
        ok |= minus & (is_start | exp_before) & digit_after
        ok |= plus & exp_before & digit_after
        ok |= dot & digit_before & digit_after
        ok |= exp & digit_before & (digit_after | (after == 43) | (after == 45))
        if not ok.all():
            raise _GiveUp  # a character outside [0-9.eE+-], or one in the wrong place
        sign = (minus | plus) & ~is_start
        if ((dot[1:] & ~is_start[:-1]) | (exp[1:] & (exp[:-1] | sign[:-1]))).any():
            raise _GiveUp  # two '.', two exponents, or a '.' in an exponent

        # 3. token counts per line; ids without '.' or exponent
        entry_of_token = np.flatnonzero(is_start)
        t0 = e0.take(entry_of_token)  # the byte before each token
        first = np.searchsorted(t0, starts - 1)
        count = np.diff(np.append(first, t0.size))
        data_line = kind >= 0
        if not np.array_equal(count, np.where(data_line, self.arity[np.maximum(kind, 0)], 0)):
            raise _GiveUp
        ids = np.concatenate([first[data_line], first[kind == 1] + 1])
        if not np.append(is_start, True).take(entry_of_token.take(ids) + 1).all():
            raise _GiveUp  # an id with '.' or an exponent (a sign is part of its first entry)

        # 4. one token per line for the conversion: every blank becomes a newline (32 ^ 42 == 10)
        np.multiply(np.equal(body, 32, out=sc.b1[:n]).view(np.uint8), np.uint8(42), out=sc.u8[:n])
        np.bitwise_xor(body, sc.u8[:n], out=self.out[a:b])
        samples = []
        for t in sorted({0, t0.size - 1}) if t0.size else ():
            p = a + int(t0[t]) + 1
            samples.append((t, data[p:p + 64].split(None, 1)[0]))
        return _Piece(kind[data_line], np.flatnonzero(data_line), int(starts.size), int(t0.size),
                      c.take(entry_of_token) == 45, samples, ignored)

    @staticmethod
    def _inline_comments(body, buf, starts, line_end) -> None:
        """Blank from a token-starting ``#`` to the end of its line; a ``#`` inside a token gives up."""
        hashes = np.flatnonzero(body == 35)
        if hashes.size == 0:
            return
        if (buf[hashes - 1] > 32).any():
            raise _GiveUp
        line = np.searchsorted(starts, hashes, "right") - 1
        first = np.r_[True, line[1:] != line[:-1]]
        delta = np.zeros(body.size + 1, np.int8)
        delta[hashes[first]] = 1
        delta[line_end[line[first]]] -= 1
        body[np.cumsum(delta[:-1], dtype=np.int8).view(bool)] = 32


def _convert(out: mmap.mmap, n_tokens: int, body_size: int) -> np.ndarray | None:
    """All numbers of the prepared body (one token per line, after a Matrix Market header): SciPy's
    C++ reader when SciPy ≥ 1.12 is there and worth its import (already imported, or at least
    :data:`MMREAD_MIN_TOKENS` numbers), else ``np.fromstring``."""
    if "scipy.io" in sys.modules or n_tokens >= MMREAD_MIN_TOKENS:
        try:
            import scipy.io
            from scipy.io import _fast_matrix_market  # noqa: F401 - the C++ reader (SciPy ≥ 1.12)
        except ImportError:
            pass
        else:
            out.seek(0)
            try:
                values = scipy.io.mmread(out)
            except Exception:  # any complaint: let the careful parser look
                return None
            values = np.asarray(values, dtype=float).reshape(-1)
            return values if values.size == n_tokens else None
    values = floats_or_none(out[_HEADER:_HEADER + body_size])
    return values if values is not None and values.size == n_tokens else None


def _header(n_tokens: int) -> bytes:
    banner = b"%%MatrixMarket matrix array real general\n"
    size = b"%d 1\n" % n_tokens
    pad = _HEADER - len(banner) - len(size) - 2
    return banner + b"%" + b" " * pad + b"\n" + size


def _rows(values: np.ndarray, kinds: np.ndarray, arity: np.ndarray, kind: int) -> np.ndarray:
    """The (k, arity) rows of one kind from the flat values, in file order."""
    width = int(arity[kind])
    per_line = arity[kinds]
    offset = np.cumsum(per_line) - per_line
    change = np.flatnonzero(kinds[1:] != kinds[:-1]) + 1
    bounds = np.r_[0, change, kinds.size]
    if bounds.size <= 1025:  # blocks of one kind: slices, no gather
        parts = [values[offset[lo]:offset[lo] + width * (hi - lo)].reshape(-1, width)
                 for lo, hi in zip(bounds[:-1], bounds[1:]) if kinds[lo] == kind]
        if len(parts) == 1:
            return parts[0]
        return np.concatenate(parts) if parts else np.empty((0, width))
    sel = offset[kinds == kind]
    return values[sel[:, None] + np.arange(width)]


def parse_fast(data: bytes, fmt_forced: str | None, *, specs: tuple | None = None) -> Parsed | None:
    """The parsed data lines of an ordinary file, or None when anything looks unusual (then the careful
    parser must read it). ``specs``: the (vertex, edge) record types to read instead of the planar
    format's (``space.py`` passes the 3-D ones; a tag has at most 16 bytes)."""
    start = 3 if data.startswith(BOM) else 0
    fmt = fmt_forced or _first_format(data, start)
    if fmt is None:
        return None
    specs = specs or FORMAT_SPECS[fmt]
    flags = getattr(mmap, "MAP_PRIVATE", 0) | getattr(mmap, "MAP_ANONYMOUS", 0) | getattr(mmap, "MAP_POPULATE", 0)
    size = _HEADER + len(data) + 1
    out_map = mmap.mmap(-1, size, flags=flags) if flags else mmap.mmap(-1, size)
    try:
        out = np.frombuffer(out_map, np.uint8)
        body = out[_HEADER:_HEADER + len(data)]
        body[:start] = 32
        out[-1] = 10
        chunks = _Chunks(data, specs, start, body)
        try:
            chunks.run()
        except _GiveUp:
            return None
        except MemoryError:
            raise
        except Exception as exc:  # a fault here must not cost the file: the careful parser reads it
            logger.debug("fast path failed (%r); using the careful parser", exc)
            return None
        if chunks.n_tokens == 0:
            return None
        out[:_HEADER] = np.frombuffer(_header(chunks.n_tokens), np.uint8)
        del out, body, chunks.out
        values = _convert(out_map, chunks.n_tokens, len(data) + 1)
    finally:
        try:
            out_map.close()
        except BufferError:  # a view is still alive somewhere: the mapping goes with it
            pass
    if values is None:
        return None
    negative = np.concatenate(chunks.negative)
    np.negative(np.abs(values, where=negative, out=values), where=negative, out=values)  # '-0' is −0.0
    for index, token in chunks.samples:  # the converter must agree with float() bit for bit
        if np.float64(float(token)).view(np.int64) != values[index:index + 1].view(np.int64)[0]:
            logger.debug("fast path: bulk conversion gave %r for %r; using the careful parser",
                         values[index], token)
            return None
    if not np.isfinite(values).all():
        return None
    kinds = np.concatenate(chunks.kinds)
    lines = np.concatenate(chunks.lines)
    v = _rows(values, kinds, chunks.arity, 0)
    e = _rows(values, kinds, chunks.arity, 1)
    if (v.size and np.abs(v[:, 0]).max() >= _EXACT_INT) or (e.size and np.abs(e[:, :2]).max() >= _EXACT_INT):
        return None
    return Parsed(fmt, v[:, 0].astype(np.int64), v[:, 1:], lines[kinds == 0], e[:, :2].astype(np.int64),
                  e[:, 2:], lines[kinds == 1], chunks.fix, chunks.equiv)
