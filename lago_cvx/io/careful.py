"""The careful line parser: every line split in Python, every problem named with ``file:line`` and the
offending token (formats in ``formats.py``; the vectorized fast path in ``fastpath.py`` hands every
file that looks unusual to this one).

One Python loop splits each line once and files the data lines by record kind (their text, line
number and id tokens — no per-edge objects). All numbers of a kind are then parsed by a single
``np.fromstring`` call on the joined lines, after a character-set check that makes it exactly as strict
as the token grammar. Only when that bulk conversion fails is a token-by-token pass run, to name the
bad token. The first lexical or structural problem in file order is reported.

Token grammar (ASCII only): ids ``[+-]?[0-9]+`` (fitting in 64 bits); numbers
``[+-]?([0-9]+(.[0-9]*)?|.[0-9]+)([eE][+-]?[0-9]+)?``, finite as doubles. No ``nan``/``inf``, no
``1_000``, no non-ASCII digits.
"""

from __future__ import annotations

import gc
import logging
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ParseError
from .formats import EQUIV, FIX, FORMAT_LABEL, FORMAT_SPECS, SPECS, TAGS_3D, TAGS_OF, Spec, non_pose_problem

__all__ = ["Parsed", "Notes", "parse_careful", "read_bytes", "decode", "int_token_problem", "unknown_tag"]

_UNSET = object()

# Token grammar (ASCII only). The bulk conversion enforces the same grammar with a character-set check
# followed by np.fromstring, which must consume every token as exactly one number.
_INT_RE = re.compile(r"[+-]?[0-9]+\Z")
# Linear-time: no two adjacent unbounded digit runs can split the same digits (a 100 kB token fails fast).
_NUM_RE = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
# A comment starts at a token that begins with '#' (\s is str.split's whitespace for str patterns).
_COMMENT_RE = re.compile(r"(?:^|\s)#")
_NUM_CHARS = b"0123456789.+-eE \t\r\n"
_INT_CHARS = b"0123456789+- "
_INT64_MAX = 2 ** 63 - 1
_EXACT_INT = 2 ** 53   # ids parsed as doubles are exact below this
BOM = b"\xef\xbb\xbf"


# ----------------------------------------------------------------------------- what a parse yields
@dataclass
class Notes:
    """Lines that are read and ignored (FIX, EQUIV): how many, the first one's number and text."""
    count: int = 0
    first_line: int | None = None
    first_text: str = ""

    def add(self, lineno: int, toks) -> None:
        if self.count == 0:
            self.first_line, self.first_text = lineno, " ".join(toks)
        self.count += 1


@dataclass
class Parsed:
    """The data lines of a file, converted: vertex ids (k,) int64, values (k, 3), line numbers (k,);
    edge ids (m, 2) int64, values (m, 9) ``dx dy dθ`` + the six information entries as written, line
    numbers (m,); the format; the ignored FIX and EQUIV lines."""
    fmt: str | None
    vid: np.ndarray
    vval: np.ndarray
    vlines: np.ndarray
    eid: np.ndarray
    evals: np.ndarray
    elines: np.ndarray
    fix: Notes = field(default_factory=Notes)
    equiv: Notes = field(default_factory=Notes)


# ----------------------------------------------------------------------------- reading the bytes
def read_bytes(path) -> bytes:
    """The file's bytes; ``ParseError`` (``path: cannot read file (...)``) when it cannot be read. A file whose
    lines end in CR alone (classic Mac OS: a CR and no LF in its first 64 KiB) comes back with LF endings."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ParseError(path, None, f"cannot read file ({exc.strerror or exc})") from None
    head = data[:65536]
    if b"\r" in head and b"\n" not in head:
        logging.getLogger("lago_cvx.io").info("%s: lines end in CR alone (classic Mac OS), read as LF", path)
        data = data.replace(b"\r", b"\n")
    return data


def decode(data: bytes) -> str:
    """UTF-8 text without a byte-order mark. Undecodable bytes survive as lone surrogates
    (``surrogateescape``) and are reported where they are used (ignored in comments)."""
    if data.startswith(BOM):
        data = data[3:]
    return data.decode("utf-8", "surrogateescape")


# ----------------------------------------------------------------------------- token helpers
def _show(tok: str, limit: int = 40) -> str:
    """A token for an error message: repr, shortened; undecodable bytes shown as bytes."""
    if len(tok) > limit:
        tok = tok[:limit] + "..."
    if _has_undecodable(tok):
        return repr(tok.encode("utf-8", "surrogateescape"))
    return repr(tok)


def _has_undecodable(s: str) -> bool:
    """Bytes that were not UTF-8 survive decoding (``surrogateescape``) as U+DC80…U+DCFF."""
    return any("\udc80" <= c <= "\udcff" for c in s)


def int_token_problem(tok: str, field: str) -> tuple[int | None, str | None]:
    """Parse an id token: (value, None) or (None, message)."""
    if _has_undecodable(tok):
        return None, f"undecodable bytes {_show(tok)} in vertex id {field} (the file is not valid UTF-8)"
    if not _INT_RE.match(tok):
        return None, f"vertex id must be an integer, got {_show(tok)} for {field}"
    v = int(tok)
    if abs(v) > _INT64_MAX:
        return None, f"vertex id {_show(tok)} for {field} is out of range (must fit in 64 bits)"
    return v, None


def _float_problem(tok: str, field: str) -> tuple[float | None, str | None]:
    """Parse a number token: (value, None) or (None, message)."""
    if _NUM_RE.match(tok):
        v = float(tok)
        if np.isfinite(v):
            return v, None
        return None, f"non-finite value {_show(tok)} for {field} (overflows a double)"
    if _has_undecodable(tok):
        return None, f"undecodable bytes {_show(tok)} in {field} (the file is not valid UTF-8)"
    if tok.lstrip("+-").lower() in ("nan", "inf", "infinity"):
        return None, f"non-finite value {_show(tok)} for {field}"
    if not tok.isascii():
        return None, f"non-numeric value {_show(tok)} for {field} (only ASCII digits are accepted)"
    return None, f"non-numeric value {_show(tok)} for {field}"


def _bad_whitespace(line: str) -> str | None:
    """Message for a data line with non-ASCII characters that ``str.split`` would swallow."""
    for c in line:
        if not c.isascii() and c.isspace():
            return f"non-ASCII whitespace U+{ord(c):04X} in a data line"
    return None


def unknown_tag(tag: str, fmt_forced: str | None, *, first: bool = False) -> str:
    """The message for a first token that is no tag of the format(s) read. On the ``first`` data line of a file
    whose format is detected, the 3-D tags are named too: the first record is what makes a file 3-D, so a
    corrupted one reads as an unknown planar tag otherwise."""
    if _has_undecodable(tag):
        return f"undecodable bytes {_show(tag)} in the tag (the file is not valid UTF-8)"
    targeted = non_pose_problem(tag)
    if targeted:
        return targeted
    if fmt_forced:
        return f"unknown tag {_show(tag)} (expected {TAGS_OF[fmt_forced]} for {fmt_forced})"
    if first:
        return (f"unknown tag {_show(tag)} (expected {TAGS_OF['g2o']} or {TAGS_OF['toro']} for a planar file, "
                f"{TAGS_3D} for a 3-D one)")
    return f"unknown tag {_show(tag)} (expected {TAGS_OF['g2o']} or {TAGS_OF['toro']})"


def floats_or_none(data: bytes) -> np.ndarray | None:
    """The whitespace-separated decimal numbers of ``data`` as one float array (NumPy's C converter), or
    None when it finds anything it cannot parse (older NumPy only warns about unparsed data)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            return np.fromstring(data, dtype=float, sep=" ")
    except (ValueError, DeprecationWarning):
        return None


def without_comment(line: str) -> str:
    """The line up to the first token that starts with ``#``."""
    m = _COMMENT_RE.search(line)
    return line if m is None else line[:m.start()]


def ignored_line(toks: list, lineno: int, fix: Notes, equiv: Notes) -> tuple[int, str] | None:
    """Validate a ``FIX id [id ...]`` or ``EQUIV i j`` line and note it; a (line, message) problem or None."""
    tag = toks[0]
    if tag == FIX and len(toks) < 2:
        return lineno, "FIX expects at least one vertex id after the tag, got 0"
    if tag == EQUIV and len(toks) != 3:
        return lineno, f"EQUIV expects 2 vertex ids after the tag, got {len(toks) - 1}"
    for tok in toks[1:]:
        _, problem = int_token_problem(tok, "id")
        if problem:
            return lineno, problem
    (fix if tag == FIX else equiv).add(lineno, toks)
    return None


# ----------------------------------------------------------------------------- line scanning
@dataclass
class _Records:
    """The data lines of one record kind, as read (``text``), their 1-based line numbers
    (``lines``) and their id tokens, flattened (``ids``: 1 per vertex, 2 per edge)."""
    text: list
    lines: list
    ids: list


@dataclass
class _Scan:
    fmt: str | None
    vertices: _Records
    edges: _Records
    error: tuple[int, str] | None   # first structural problem (line, message); scanning stopped there
    fix: Notes
    equiv: Notes


def _scan(text: str, fmt_forced: str | None) -> _Scan:
    """Sort the data lines by record kind (keeping their text, line number and id tokens). Stops at
    the first structural problem (unknown tag, wrong token count, format mix, bad FIX/EQUIV line) and
    records it. The hot path for an ordinary data line is: a ``#`` test, split, one dict look-up, two
    identity tests, a length test and the appends."""
    vertices, edges = _Records([], [], []), _Records([], [], [])
    v_text, v_lines, v_ids = vertices.text.append, vertices.lines.append, vertices.ids.append
    e_text, e_lines, e_ids = edges.text.append, edges.lines.append, edges.ids.append
    fmt, fmt_line = fmt_forced, None
    fix, equiv = Notes(), Notes()
    # The current format's specs; a sentinel (never returned by the look-up) until the format is known.
    vspec, espec = FORMAT_SPECS[fmt_forced] if fmt_forced else (_UNSET, _UNSET)
    check_ascii = not text.isascii()
    error = None
    specs_get = SPECS.get
    gc_was_enabled = gc.isenabled()
    gc.disable()  # the loop allocates one list per line; cyclic GC passes would only slow it down
    try:
        for lineno, line in enumerate(text.split("\n"), 1):
            if "#" in line:
                line = without_comment(line)
            toks = line.split()
            if not toks:
                continue
            spec = specs_get(toks[0])
            if spec is not espec and spec is not vspec:
                # Rare lines: FIX, EQUIV, unknown tags, the first data line, a format mix.
                tag = toks[0]
                if spec is None:
                    if tag in (FIX, EQUIV):
                        error = ignored_line(toks, lineno, fix, equiv)
                        if error:
                            break
                        continue
                    error = (lineno, unknown_tag(tag, fmt_forced, first=fmt is None))
                    break
                if fmt is None:  # auto-detection: the first data tag decides
                    fmt, fmt_line = spec.fmt, lineno
                    vspec, espec = FORMAT_SPECS[fmt]
                elif fmt_forced:
                    error = (lineno, f"{FORMAT_LABEL[spec.fmt]} tag {tag!r} in a file read as "
                                     f"{fmt_forced} (expected {TAGS_OF[fmt_forced]})")
                    break
                else:
                    error = (lineno, f"mixes g2o and TORO tags ({FORMAT_LABEL[spec.fmt]} tag {tag!r} "
                                     f"here, {FORMAT_LABEL[fmt]} tag seen on line {fmt_line})")
                    break
            if len(toks) != spec.n_tokens:
                error = (lineno, f"{spec.tag} expects {spec.n_tokens - 1} numbers after the tag, "
                                 f"got {len(toks) - 1}")
                break
            if check_ascii and not line.isascii():
                problem = _bad_whitespace(line)
                if problem:
                    error = (lineno, problem)
                    break
            if spec is espec:
                e_text(line)
                e_lines(lineno)
                e_ids(toks[1])
                e_ids(toks[2])
            else:
                v_text(line)
                v_lines(lineno)
                v_ids(toks[1])
    finally:
        if gc_was_enabled:
            gc.enable()
    return _Scan(fmt, vertices, edges, error, fix, equiv)


# ----------------------------------------------------------------------------- number conversion
def _convert_fast(rec: _Records, spec: Spec) -> np.ndarray | None:
    """All numbers of the records (ids included) as one (k, n_fields) float array, or None when
    anything is off (then the token-by-token pass finds and names the problem).

    The lines are joined, their tag removed, and parsed by one ``np.fromstring`` call. This is exactly
    as strict as the token grammar: the tag must occur once per line (so it can only be the first
    token), numbers may only contain ``[0-9.+-eE]`` and ids only ``[0-9+-]``, fromstring must consume
    everything and produce exactly one number per token (``1-2`` would give two), all finite, ids
    exact integers."""
    k, n_fields, n_ids = len(rec.text), len(spec.fields), spec.n_ids
    data = "\n".join(rec.text)
    if not data.isascii() or data.count(spec.tag) != k:
        return None
    data = data.replace(spec.tag, " ").encode("ascii")
    ids = " ".join(rec.ids).encode("ascii")
    if data.translate(None, _NUM_CHARS) or ids.translate(None, _INT_CHARS):
        return None
    arr = floats_or_none(data)
    if arr is None or arr.size != k * n_fields:
        return None
    arr = arr.reshape(k, n_fields)
    if not np.isfinite(arr).all() or np.abs(arr[:, :n_ids]).max() >= _EXACT_INT:
        return None
    return arr


def _convert_careful(rec: _Records, spec: Spec):
    """Token-by-token conversion: ``(ids, values, None)`` or ``(None, None, (line, message))`` for
    the first bad token."""
    n_ids = spec.n_ids
    ids = np.empty((len(rec.text), n_ids), np.int64)
    vals = np.empty((len(rec.text), len(spec.fields) - n_ids))
    for r, (line, lineno) in enumerate(zip(rec.text, rec.lines)):
        for c, (tok, field_name) in enumerate(zip(line.split()[1:], spec.fields)):
            if c < n_ids:
                v, problem = int_token_problem(tok, field_name)
                if problem is None:
                    ids[r, c] = v
            else:
                v, problem = _float_problem(tok, field_name)
                if problem is None:
                    vals[r, c - n_ids] = v
            if problem:
                return None, None, (lineno, problem)
    return ids, vals, None


def _convert(rec: _Records, spec: Spec):
    """``(ids (k, n_ids) int64, values (k, n_values) float, None)`` or ``(None, None, (line, msg))``."""
    n_ids, n_vals = spec.n_ids, len(spec.fields) - spec.n_ids
    if not rec.text:
        return np.empty((0, n_ids), np.int64), np.empty((0, n_vals)), None
    arr = _convert_fast(rec, spec)
    if arr is not None:
        return arr[:, :n_ids].astype(np.int64), np.ascontiguousarray(arr[:, n_ids:]), None
    return _convert_careful(rec, spec)


def _first(candidates):
    candidates = [c for c in candidates if c is not None]
    return min(candidates, key=lambda c: c[0]) if candidates else None


def parse_careful(text: str, fmt_forced: str | None, path) -> Parsed:
    """Parse decoded text line by line; ``ParseError`` for the first lexical or structural problem in
    file order (every token before the line where scanning stopped is converted, so the earliest
    problem wins)."""
    scan = _scan(text, fmt_forced)
    vspec = SPECS["VERTEX_SE2" if scan.fmt != "toro" else "VERTEX2"]
    espec = SPECS["EDGE_SE2" if scan.fmt != "toro" else "EDGE2"]
    vid, vval, verr = _convert(scan.vertices, vspec)
    eid, evals, eerr = _convert(scan.edges, espec)
    problem = _first([scan.error, verr, eerr])
    if problem:
        raise ParseError(path, *problem)
    return Parsed(scan.fmt, vid[:, 0], vval, np.asarray(scan.vertices.lines, np.int64), eid, evals,
                  np.asarray(scan.edges.lines, np.int64), scan.fix, scan.equiv)
