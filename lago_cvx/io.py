"""Reading and writing planar pose graphs in the g2o and TORO text formats.

Formats
=======
Both formats are line based: one record per line, whitespace-separated tokens (spaces or tabs; LF or
CRLF line ends). Blank lines and lines whose first non-blank character is ``#`` are skipped. Pose ids
are integers; they need not be contiguous or start at 0 (``PoseGraph.ids`` keeps them, sorted, and
edge endpoints become indices into it).

**g2o** (``VERTEX_SE2`` / ``EDGE_SE2``)::

    VERTEX_SE2 id x y θ
    EDGE_SE2   i j dx dy dθ I11 I12 I13 I22 I23 I33

The edge carries pose j measured in the frame of pose i and the *upper triangle* (row-major, order
x, y, θ) of the 3×3 information matrix Ω of the error ``e = [R_iᵀ(p_j − p_i) − Δˡ ; θ_j − θ_i − δ]``
— the convention of :mod:`lago_cvx.posegraph`. ``FIX id [id ...]`` lines are legal g2o; they are
validated (integer ids), logged at INFO level and otherwise ignored (LAGO picks its own anchor).

**TORO / HOG-Man** (``VERTEX2`` / ``EDGE2``)::

    VERTEX2 id x y θ
    EDGE2   i j dx dy dθ Ixx Ixy Iyy Iθθ Ixθ Iyθ

Same measurement, but the six information entries come in a different order (HOG-Man's
``inf_ff inf_fs inf_ss inf_rr inf_fr inf_sr``; in error messages the fields are called
``Ixx Ixy Iyy Itt Ixt Iyt``, t standing for θ) **and in a different frame**.

TORO → g2o information conversion
---------------------------------
A TORO information matrix Ω_toro is converted on reading to the g2o convention by

    Ω_g2o = Tᵀ Ω_toro T,    T = blkdiag(R(dθ), 1),

where R(dθ) is the 2-D rotation by the edge's *own* measured angle dθ. This rotates the 2×2
translational block (R(dθ)ᵀ Ω_tt R(dθ)) and the x-θ / y-θ cross terms consistently; Ω_θθ is unchanged.
Writing TORO applies the inverse, Ω_toro = T Ω_g2o Tᵀ (T is orthogonal). The rotation and its
direction are an empirical convention, fixed by the data below rather than derived from TORO's code.

Evidence (datasets README §2.3, re-checked by ``tests/test_io.py``): SE-Sync's ``manhattan.g2o`` and
``CSAIL.g2o`` were produced from Carlone's ``M3500_P_toro.graph`` and ``CSAIL_P_toro.graph``. The twins
have the same endpoints and measurements, and after this conversion *every* edge's information agrees
to 1e-4 relative (the g2o files were printed with 6 decimals); without the rotation, or with the
rotation the other way (T Ω_toro Tᵀ), they do not agree (relative differences > 1e-2).

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
import os
import re
import tempfile
import warnings
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .posegraph import PoseGraph, is_spd, rot2, wrap_angle

__all__ = ["ParseError", "read_graph", "write_graph", "detect_format"]

logger = logging.getLogger(__name__)

_FORMATS = ("g2o", "toro")
_FORMAT_LABEL = {"g2o": "g2o", "toro": "TORO"}


class ParseError(ValueError):
    """A pose-graph file that cannot be read.

    Attributes: ``path`` (str, as given by the caller), ``line`` (1-based int, or None for whole-file
    problems) and ``problem`` (str). ``str(err)`` is the one-line ``"{path}:{line}: {problem}"``
    (``"{path}: {problem}"`` when ``line`` is None).
    """

    def __init__(self, path, line: int | None, problem: str):
        super().__init__(path, line, problem)
        self.path = os.fspath(path) if isinstance(path, os.PathLike) else str(path)
        self.line = None if line is None else int(line)
        self.problem = " ".join(str(problem).split("\n"))

    def __str__(self) -> str:
        if self.line is None:
            return f"{self.path}: {self.problem}"
        return f"{self.path}:{self.line}: {self.problem}"


# ----------------------------------------------------------------------------- record types
class _Spec(NamedTuple):
    tag: str
    fmt: str        # "g2o" or "toro"
    fields: tuple   # names of the tokens after the tag (for messages)
    n_ids: int      # how many of the leading fields are integer ids
    n_tokens: int   # tokens on a well-formed line, tag included


_VERTEX_FIELDS = ("id", "x", "y", "theta")
_G2O_EDGE_FIELDS = ("i", "j", "dx", "dy", "dtheta", "I11", "I12", "I13", "I22", "I23", "I33")
_TORO_EDGE_FIELDS = ("i", "j", "dx", "dy", "dtheta", "Ixx", "Ixy", "Iyy", "Itt", "Ixt", "Iyt")

_SPECS = {spec.tag: spec for spec in [
    _Spec("VERTEX_SE2", "g2o", _VERTEX_FIELDS, 1, 5),
    _Spec("EDGE_SE2", "g2o", _G2O_EDGE_FIELDS, 2, 12),
    _Spec("VERTEX2", "toro", _VERTEX_FIELDS, 1, 5),
    _Spec("EDGE2", "toro", _TORO_EDGE_FIELDS, 2, 12),
]}
_FORMAT_SPECS = {"g2o": (_SPECS["VERTEX_SE2"], _SPECS["EDGE_SE2"]),   # (vertex, edge) per format
                 "toro": (_SPECS["VERTEX2"], _SPECS["EDGE2"])}
_TAGS_OF = {"g2o": "VERTEX_SE2/EDGE_SE2", "toro": "VERTEX2/EDGE2"}
_FIX = "FIX"
_UNSET = object()

# Index maps from the six stored information entries to the symmetric 3×3 matrix (order x, y, θ).
_G2O_INFO_INDEX = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])   # I11 I12 I13 I22 I23 I33
_TORO_INFO_INDEX = np.array([[0, 1, 4], [1, 2, 5], [4, 5, 3]])  # Ixx Ixy Iyy Itt Ixt Iyt

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
        return f"unknown tag {_show(tag)} (expected {_TAGS_OF[fmt_forced]} for {fmt_forced})"
    return f"unknown tag {_show(tag)} (expected {_TAGS_OF['g2o']} or {_TAGS_OF['toro']})"


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
    vspec, espec = _FORMAT_SPECS[fmt_forced] if fmt_forced else (_UNSET, _UNSET)
    check_ascii = not text.isascii()
    error = None
    specs_get = _SPECS.get
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
                    if tag == _FIX:
                        error = _fix_line(toks, lineno, path)
                        if error:
                            break
                        continue
                    error = (lineno, _unknown_tag(tag, fmt_forced))
                    break
                if fmt is None:  # auto-detection: the first data tag decides
                    fmt, fmt_line = spec.fmt, lineno
                    vspec, espec = _FORMAT_SPECS[fmt]
                elif fmt_forced:
                    error = (lineno, f"{_FORMAT_LABEL[spec.fmt]} tag {tag!r} in a file read as "
                                     f"{fmt_forced} (expected {_TAGS_OF[fmt_forced]})")
                    break
                else:
                    error = (lineno, f"mixes g2o and TORO tags ({_FORMAT_LABEL[spec.fmt]} tag {tag!r} "
                                     f"here, {_FORMAT_LABEL[fmt]} tag seen on line {fmt_line})")
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
def _convert_fast(rec: _Records, spec: _Spec) -> np.ndarray | None:
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


def _convert_careful(rec: _Records, spec: _Spec):
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


def _convert(rec: _Records, spec: _Spec):
    """``(ids (k, n_ids) int64, values (k, n_values) float, None)`` or ``(None, None, (line, msg))``."""
    n_ids, n_vals = spec.n_ids, len(spec.fields) - spec.n_ids
    if not rec.text:
        return np.empty((0, n_ids), np.int64), np.empty((0, n_vals)), None
    arr = _convert_fast(rec, spec)
    if arr is not None:
        return arr[:, :n_ids].astype(np.int64), np.ascontiguousarray(arr[:, n_ids:]), None
    return _convert_careful(rec, spec)


# ----------------------------------------------------------------------------- information matrices
def _toro_to_g2o(info_toro: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """Ω_g2o = Tᵀ Ω_toro T with T = blkdiag(R(dθ), 1), for (m, 3, 3) stacks; exactly symmetric."""
    T = _rotation_block(dtheta)
    out = np.swapaxes(T, 1, 2) @ info_toro @ T
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def _g2o_to_toro(info_g2o: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_toro_to_g2o`: Ω_toro = T Ω_g2o Tᵀ."""
    T = _rotation_block(dtheta)
    out = T @ info_g2o @ np.swapaxes(T, 1, 2)
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def _rotation_block(dtheta: np.ndarray) -> np.ndarray:
    T = np.zeros((len(dtheta), 3, 3))
    T[:, :2, :2] = rot2(dtheta)
    T[:, 2, 2] = 1.0
    return T


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
def _check_format(format):
    if format is None:
        return None
    f = str(format).lower()
    if f not in _FORMATS:
        raise ValueError(f"format must be None, 'g2o' or 'toro', got {format!r}")
    return f


def read_graph(path, *, format: str | None = None) -> PoseGraph:
    """Read a g2o or TORO pose-graph file into a :class:`PoseGraph` (``name`` = the file's name).

    ``format``: None (auto-detect: the first data tag decides), ``"g2o"`` or ``"toro"``. TORO
    information matrices are converted to the g2o convention (see the module docstring).
    Raises :class:`ParseError` for every unreadable or invalid input.
    """
    fmt_forced = _check_format(format)
    text = _read_text(path)
    scan = _scan(text, fmt_forced, path)
    vspec = _SPECS["VERTEX_SE2" if scan.fmt != "toro" else "VERTEX2"]
    espec = _SPECS["EDGE_SE2" if scan.fmt != "toro" else "EDGE2"]

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
    raw = evals[:, 3:][:, _TORO_INFO_INDEX if espec.fmt == "toro" else _G2O_INFO_INDEX]
    if espec.fmt == "toro":
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported per edge below
            info = _toro_to_g2o(raw, evals[:, 2])
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
    except ValueError as exc:
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
        if not toks or toks[0][0] == "#" or toks[0] == _FIX:
            continue
        spec = _SPECS.get(toks[0])
        if spec is None:
            raise ParseError(path, lineno, _unknown_tag(toks[0], None))
        return spec.fmt
    raise ParseError(path, None, "file contains no vertices and no edges")


def _wrap_vertex_angles(theta: np.ndarray) -> np.ndarray:
    """Angles outside [−π, π) wrapped into it; angles already inside are kept bit for bit."""
    inside = (theta >= -np.pi) & (theta < np.pi)
    w = wrap_angle(theta)
    w = np.where(w >= np.pi, w - 2.0 * np.pi, w)  # (a + π) mod 2π can round up to 2π
    return np.where(inside, theta, w)


def _file_mode(path: Path) -> int:
    """Permissions for the new file: the existing file's, else the usual 0666 & ~umask."""
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        pass
    try:  # Linux: read the umask without changing it
        with open("/proc/self/status") as f:
            mask = next(int(ln.split()[1], 8) for ln in f if ln.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0)  # elsewhere: the classic (briefly process-wide) set-and-restore
        os.umask(mask)
    return 0o666 & ~mask


def write_graph(path, graph: PoseGraph, poses=None, *, format: str = "g2o",
                wrap_angles: bool = True) -> Path:
    """Write ``graph`` as a g2o (default) or TORO file and return its path.

    Vertex lines come from ``poses`` ((n, 3)) if given, else from ``graph.initial``; with neither the
    file has edge lines only (poses that appear in no edge are then not represented). Ids are the
    graph's original ``ids``. Numbers are written with ``repr`` (shortest exact round trip), so
    read → write → read reproduces the graph bit for bit. Vertex angles outside [−π, π) are wrapped
    when ``wrap_angles``; edge angles δ are written as stored. TORO output converts the information
    back to the TORO frame (Ω_toro = T Ω Tᵀ). The file is written to a temporary file in the same
    directory and moved into place with ``os.replace`` (atomic).
    """
    fmt = _check_format(format)
    if fmt is None:
        raise ValueError("format must be 'g2o' or 'toro'")
    path = Path(path)
    if poses is None:
        poses = graph.initial
    if poses is not None:
        poses = np.asarray(poses, dtype=float)
        if poses.shape != (graph.n_poses, 3):
            raise ValueError(f"poses must have shape ({graph.n_poses}, 3), got {poses.shape}")
        if not np.isfinite(poses).all():
            raise ValueError("poses must be finite")
        if wrap_angles:
            poses = np.column_stack([poses[:, :2], _wrap_vertex_angles(poses[:, 2])])
    elif graph.n_edges == 0:
        raise ValueError("nothing to write: the graph has no edges and no poses were given")
    elif np.unique(np.concatenate([graph.tails, graph.heads])).size < graph.n_poses:
        logger.warning("%s: writing an edge-only file; poses that appear in no edge are lost", path)

    vtag = "VERTEX_SE2" if fmt == "g2o" else "VERTEX2"
    etag = "EDGE_SE2" if fmt == "g2o" else "EDGE2"
    info = graph.information
    if fmt == "g2o":
        six = info[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    else:
        t = _g2o_to_toro(info, graph.delta)
        six = t[:, [0, 0, 1, 2, 0, 1], [0, 1, 1, 2, 2, 2]]
    ids = graph.ids.tolist()
    parts = []
    if poses is not None:
        vfmt = vtag + " %d %r %r %r\n"
        parts.extend(vfmt % (i, *p) for i, p in zip(ids, poses.tolist()))
    efmt = etag + " %d %d" + " %r" * 9 + "\n"
    eids = np.column_stack([graph.ids[graph.tails], graph.ids[graph.heads]]).tolist()
    evals = np.column_stack([graph.delta_l, graph.delta, six]).tolist()
    parts.extend(efmt % (*e, *v) for e, v in zip(eids, evals))
    text = "".join(parts)

    mode = _file_mode(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="ascii", newline="\n") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path
