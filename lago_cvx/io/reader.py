"""Reading g2o and TORO files (formats in ``formats.py``).

Errors
======
Every problem with the input raises :class:`ParseError` (a ``ValueError``) whose message is one line,
``path:line: problem`` (or ``path: problem`` for whole-file problems), naming the offending token or
field. Rejected: unknown tags, wrong token counts, non-numeric tokens (only plain ASCII decimal literals
are numbers: no ``nan``/``inf``, no ``1_000``, no non-ASCII digits), non-finite values (including
overflow such as ``1e999``), non-integer ids, information matrices that are not positive definite,
duplicate vertex ids, edges to ids no vertex line defines, self-loops, files mixing g2o and TORO tags,
files without vertices and edges, bytes that are not UTF-8 (outside comments), unreadable files.
When a file has several problems, the first lexical/structural one (in file order) is reported; only a
lexically clean file is checked for the semantic problems (duplicate/unknown ids, self-loops,
information), and the earliest of those is reported.

Semantics: with vertex lines, the pose set is the set of vertex ids and ``initial`` holds the vertex
poses (in id order); an edge-only file defines the poses that appear in its edges and has no initial
guess. Backward edges (i > j) and parallel edges are kept exactly as written.

Speed
=====
One Python loop splits each line once and files the data lines by record kind (their text, line
number and id tokens — no per-edge objects). All numbers of a kind are then parsed by a single
``np.fromstring`` call on the joined lines, after a character-set check that makes it exactly as strict
as the token grammar, and everything else is validated vectorized. Only when that bulk conversion
fails is a token-by-token pass run, to name the bad token. A 100k-edge file loads in well under a
second.
"""

from __future__ import annotations

import gc
import logging
import re
import warnings
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path

import numpy as np

from ..errors import ParseError
from ..posegraph import PoseGraph, is_spd
from .formats import (FIX, FORMAT_LABEL, FORMAT_SPECS, G2O_INFO_INDEX, SPECS, TAGS_OF, TORO_INFO_INDEX, Spec,
                      check_format, toro_to_g2o)

__all__ = ["read_graph", "detect_format"]

logger = logging.getLogger("lago_cvx.io")

_UNSET = object()

# Token grammar (ASCII only). The fast path enforces the same grammar with a character-set check
# followed by np.fromstring, which must consume every token as exactly one number.
_INT_RE = re.compile(r"[+-]?[0-9]+\Z")
# Linear-time: no two adjacent unbounded digit runs can split the same digits (a 100 kB token fails fast).
_NUM_RE = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
_NUM_CHARS = b"0123456789.+-eE \t\r\n"
_INT_CHARS = b"0123456789+- "
_INT64_MAX = 2 ** 63 - 1
_EXACT_INT = 2 ** 53   # ids parsed as doubles are exact below this


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


def _int_problem(tok: str, field: str) -> tuple[int | None, str | None]:
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


def _read_text(path) -> str:
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ParseError(path, None, f"cannot read file ({exc.strerror or exc})") from None
    if data.startswith(b"\xef\xbb\xbf"):  # UTF-8 byte-order mark
        data = data[3:]
    # Undecodable bytes survive as lone surrogates and are reported where they are used.
    return data.decode("utf-8", "surrogateescape")


def _bad_whitespace(line: str) -> str | None:
    """Message for a data line with non-ASCII characters that ``str.split`` would swallow."""
    for c in line:
        if not c.isascii() and c.isspace():
            return f"non-ASCII whitespace U+{ord(c):04X} in a data line"
    return None


def _unknown_tag(tag: str, fmt_forced: str | None) -> str:
    if _has_undecodable(tag):
        return f"undecodable bytes {_show(tag)} in the tag (the file is not valid UTF-8)"
    if fmt_forced:
        return f"unknown tag {_show(tag)} (expected {TAGS_OF[fmt_forced]} for {fmt_forced})"
    return f"unknown tag {_show(tag)} (expected {TAGS_OF['g2o']} or {TAGS_OF['toro']})"


def _scan(text: str, fmt_forced: str | None, path) -> _Scan:
    """Sort the data lines by record kind (keeping their text, line number and id tokens). Stops at
    the first structural problem (unknown tag, wrong token count, format mix, bad FIX line) and
    records it. The hot path for an ordinary data line is: split, one dict look-up, two identity
    tests, a length test and the appends."""
    vertices, edges = _Records([], [], []), _Records([], [], [])
    v_text, v_lines, v_ids = vertices.text.append, vertices.lines.append, vertices.ids.append
    e_text, e_lines, e_ids = edges.text.append, edges.lines.append, edges.ids.append
    fmt, fmt_line = fmt_forced, None
    # The current format's specs; a sentinel (never returned by the look-up) until the format is known.
    vspec, espec = FORMAT_SPECS[fmt_forced] if fmt_forced else (_UNSET, _UNSET)
    check_ascii = not text.isascii()
    error = None
    specs_get = SPECS.get
    gc_was_enabled = gc.isenabled()
    gc.disable()  # the loop allocates one list per line; cyclic GC passes would only slow it down
    try:
        for lineno, line in enumerate(text.split("\n"), 1):
            toks = line.split()
            if not toks:
                continue
            spec = specs_get(toks[0])
            if spec is not espec and spec is not vspec:
                # Rare lines: comments, FIX, unknown tags, the first data line, a format mix.
                tag = toks[0]
                if spec is None:
                    if tag[0] == "#":
                        continue
                    if tag == FIX:
                        error = _fix_line(toks, lineno, path)
                        if error:
                            break
                        continue
                    error = (lineno, _unknown_tag(tag, fmt_forced))
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
    return _Scan(fmt, vertices, edges, error)


def _fix_line(toks: list, lineno: int, path) -> tuple[int, str] | None:
    """Validate a ``FIX id [id ...]`` line and log it; return a (line, message) problem or None."""
    if len(toks) < 2:
        return lineno, "FIX expects at least one vertex id after the tag, got 0"
    ids = []
    for tok in toks[1:]:
        v, problem = _int_problem(tok, "id")
        if problem:
            return lineno, problem
        ids.append(v)
    logger.info("%s:%d: ignoring FIX %s (LAGO fixes its own reference pose)",
                path, lineno, " ".join(map(str, ids)))
    return None


# ----------------------------------------------------------------------------- number conversion
def _convert_fast(rec: _Records, spec: Spec) -> np.ndarray | None:
    """All numbers of the records (ids included) as one (k, n_fields) float array, or None when
    anything is off (then the careful pass finds and names the problem).

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
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # older NumPy only warns about unparsed data
            arr = np.fromstring(data, dtype=float, sep=" ")
    except (ValueError, DeprecationWarning):
        return None
    if arr.size != k * n_fields:
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
        for c, (tok, field) in enumerate(zip(line.split()[1:], spec.fields)):
            if c < n_ids:
                v, problem = _int_problem(tok, field)
                if problem is None:
                    ids[r, c] = v
            else:
                v, problem = _float_problem(tok, field)
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


# ----------------------------------------------------------------------------- semantic checks
def _first(candidates):
    """The candidate (line, message) with the smallest line, or None."""
    candidates = [c for c in candidates if c is not None]
    return min(candidates, key=itemgetter(0)) if candidates else None


def _duplicate_vertex(vid: np.ndarray, vlines: np.ndarray):
    if vid.size < 2:
        return None
    order = np.argsort(vid, kind="stable")
    s = vid[order]
    dup = np.flatnonzero(s[1:] == s[:-1]) + 1          # positions (in sorted order) of repeats
    if dup.size == 0:
        return None
    k = dup[np.argmin(vlines[order[dup]])]              # the earliest repeated definition
    first = order[np.searchsorted(s, s[k])]             # stable sort: first of its group = first line
    return int(vlines[order[k]]), f"duplicate vertex id {s[k]} (first defined on line {vlines[first]})"


def _self_loop(eid: np.ndarray, elines: np.ndarray):
    bad = np.flatnonzero(eid[:, 0] == eid[:, 1])
    if bad.size == 0:
        return None
    k = bad[0]
    return int(elines[k]), f"self-loop edge {eid[k, 0]} -> {eid[k, 1]}"


def _unknown_vertex(eid: np.ndarray, pos: np.ndarray, elines: np.ndarray, ids: np.ndarray):
    """First edge with an endpoint id not in ``ids`` (``pos = searchsorted(ids, eid)``)."""
    known = ids[np.minimum(pos, ids.size - 1)] == eid
    bad = np.flatnonzero(~known.all(axis=1))
    if bad.size == 0:
        return None
    k = bad[0]
    v = eid[k, 0] if not known[k, 0] else eid[k, 1]
    return int(elines[k]), f"edge refers to vertex {v}, which no VERTEX line defines"


def _bad_information(info: np.ndarray, raw: np.ndarray, elines: np.ndarray):
    """First edge whose (converted) information fails :func:`is_spd` — the very test PoseGraph applies."""
    with np.errstate(over="ignore", invalid="ignore"):  # absurdly large entries: reported below
        bad = np.flatnonzero(~is_spd(info))
    if bad.size == 0:
        return None
    k = bad[0]
    if not np.isfinite(info[k]).all():
        return int(elines[k]), "information matrix overflows when rotated to the g2o convention"
    with np.errstate(over="ignore", invalid="ignore"):
        ev = np.linalg.eigvalsh(raw[k]) if np.isfinite(2.0 * raw[k]).all() else np.full(3, np.nan)
    shown = ", ".join(f"{e:.6g}" for e in ev)
    if ev.min() > 0:  # positive definite on paper, but not usable in floating point
        return int(elines[k]), (f"information matrix is not numerically positive definite "
                                f"(entries too large or too badly scaled; eigenvalues {shown})")
    if np.isnan(ev).any():
        return int(elines[k]), "information matrix is not numerically positive definite (entries too large)"
    return int(elines[k]), f"information matrix is not positive definite (eigenvalues {shown})"


# ----------------------------------------------------------------------------- public API
def read_graph(path, *, format: str | None = None) -> PoseGraph:
    """Read a g2o or TORO pose-graph file into a :class:`PoseGraph` (``name`` = the file's name).

    ``format``: None (auto-detect: the first data tag decides), ``"g2o"`` or ``"toro"``. TORO
    information matrices are converted to the g2o convention (see the module docstring).
    Raises :class:`ParseError` for every unreadable or invalid input.
    """
    fmt_forced = check_format(format)
    text = _read_text(path)
    scan = _scan(text, fmt_forced, path)
    vspec = SPECS["VERTEX_SE2" if scan.fmt != "toro" else "VERTEX2"]
    espec = SPECS["EDGE_SE2" if scan.fmt != "toro" else "EDGE2"]

    # Lexical problems: the scan stopped at its first structural problem, and every token before it
    # is converted, so the earliest problem wins.
    vid, vval, verr = _convert(scan.vertices, vspec)
    eid, evals, eerr = _convert(scan.edges, espec)
    problem = _first([scan.error, verr, eerr])
    if problem:
        raise ParseError(path, *problem)
    if vid.shape[0] == 0 and eid.shape[0] == 0:
        raise ParseError(path, None, "file contains no vertices and no edges")

    vid = vid[:, 0]
    vlines = np.asarray(scan.vertices.lines, np.int64)
    elines = np.asarray(scan.edges.lines, np.int64)
    raw = evals[:, 3:][:, TORO_INFO_INDEX if espec.fmt == "toro" else G2O_INFO_INDEX]
    if espec.fmt == "toro":
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported per edge below
            info = toro_to_g2o(raw, evals[:, 2])
    else:
        info = raw

    # Semantic problems; the earliest line among them is reported. Duplicate and unknown ids are
    # checked here. Self-loops and information matrices are checked by PoseGraph itself (with the
    # same is_spd test), so they are only located here when it objects — or when another semantic
    # problem was found and the earliest one must be chosen.
    ids = np.unique(vid if vid.size else eid)
    pos = np.searchsorted(ids, eid)  # (m, 2) pose indices of the endpoints, if the ids are known
    problem = _first([_duplicate_vertex(vid, vlines),
                      _unknown_vertex(eid, pos, elines, ids) if vid.size and eid.size else None])
    if problem:
        raise ParseError(path, *_first([problem, _self_loop(eid, elines),
                                        _bad_information(info, raw, elines)]))
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # absurd magnitudes are reported below
            return PoseGraph(
                n_poses=ids.size,
                tails=pos[:, 0],
                heads=pos[:, 1],
                delta_l=evals[:, 0:2],
                delta=evals[:, 2],
                information=info,
                initial=vval[np.argsort(vid)] if vid.size else None,
                ids=ids,
                name=Path(path).name,
            )
    except ValueError as exc:  # GraphError from PoseGraph
        problem = _first([_self_loop(eid, elines), _bad_information(info, raw, elines)])
        if problem:
            raise ParseError(path, *problem) from None
        raise ParseError(path, None, f"invalid pose graph: {exc}") from None  # not expected


def detect_format(path) -> str:
    """``"g2o"`` or ``"toro"``, decided by the first data tag of the file (FIX lines are neutral).

    Raises :class:`ParseError` for an unreadable file, an unknown first tag or a file without data.
    """
    text = _read_text(path)
    for lineno, line in enumerate(text.split("\n"), 1):
        toks = line.split(maxsplit=1)
        if not toks or toks[0][0] == "#" or toks[0] == FIX:
            continue
        spec = SPECS.get(toks[0])
        if spec is None:
            raise ParseError(path, lineno, _unknown_tag(toks[0], None))
        return spec.fmt
    raise ParseError(path, None, "file contains no vertices and no edges")
