"""Reading g2o and TORO files (formats in ``formats.py``).

Two parsers, one result
=======================
``fastpath.py`` reads an ordinary file at the speed of the machine: a few vectorized passes over the
bytes (line starts, tags, comments, the token grammar, token counts per line) and one bulk conversion
of all numbers. The moment anything looks unusual — a bad token, a wrong token count, an unknown tag,
an indented line, non-ASCII bytes outside comments, … — it gives up and ``careful.py`` reads the file
line by line, naming the problem with ``file:line`` and the offending token. Both give the same arrays
(``tests/test_io.py`` checks this on every dataset and on fuzzed files); everything after the
conversion — the semantic checks, the warnings and the :class:`PoseGraph` — is shared and below.

Errors
======
Every problem with the input raises :class:`ParseError` (a ``ValueError``) whose message is one line,
``path:line: problem`` (or ``path: problem`` for whole-file problems), naming the offending token or
field. Rejected: unknown tags (landmark and 3-D records with a message saying so), wrong token counts,
non-numeric tokens (only plain ASCII decimal literals are numbers: no ``nan``/``inf``, no ``1_000``, no
non-ASCII digits), non-finite values (including overflow such as ``1e999``), non-integer ids,
information matrices that are not positive definite (for ``EDGE2``, with a hint when the g2o order
would fit, see ``edge2_order``), duplicate vertex ids, edges to ids no vertex line defines, self-loops,
files mixing g2o and TORO tags, files without vertices and edges, bytes that are not UTF-8 (outside
comments), unreadable files. When a file has several problems, the first lexical/structural one (in file
order) is reported; only a lexically clean file is checked for the semantic problems (duplicate/unknown
ids, self-loops, information), and the earliest of those is reported.

Semantics
=========
With vertex lines, the pose set is the set of vertex ids and ``initial`` holds the vertex poses (in id
order). A file with edges but no vertex line at all (e.g. SE-Sync's ``manhattan.g2o``, GTSAM's
``w20000.txt``) defines the poses that appear in its edges (logged at INFO level): LAGO needs no initial
guess, so ``initial`` is None rather than a made-up guess — whatever needs one (refinement "from the
file's guess") must then say so or build one (``refinement.odometry_guess``). A file with some vertex
lines and an edge naming an undefined vertex is an error. Backward edges (i > j) and parallel edges are
kept exactly as written. ``FIX`` and ``EQUIV`` lines are ignored with one warning each per file (logger
``lago_cvx.io``, WARNING): the count and the first line.
"""

from __future__ import annotations

import logging
from operator import itemgetter
from pathlib import Path

import numpy as np

from ..conventions import COST_OF_FORMAT, check_cost
from ..errors import OptionError, ParseError
from ..posegraph import COST_FRAME, PoseGraph, is_spd, to_tail_frame
from ..posegraph_base import REPAIR_FLOOR, nearest_spd
from .careful import decode, parse_careful, read_bytes, unknown_tag
from .fastpath import parse_fast
from .space import first_tag, is_3d_tag, read_graph3d
from .formats import EQUIV, FIX, G2O_INFO_INDEX, SPECS, TORO_INFO_INDEX, check_edge2_order, check_format

__all__ = ["read_graph", "detect_format", "READ_INFORMATION"]

#: ``read_graph(information=...)``: ``"full"`` every entry as written; ``"blocks"`` the translation–rotation
#: cross terms dropped (Ω_tθ = 0 in the plane, Ω_tR = 0 in 3-D), as SE-Sync reads a file.
READ_INFORMATION = ("full", "blocks")

logger = logging.getLogger("lago_cvx.io")


# ----------------------------------------------------------------------------- semantic checks
def _first(candidates):
    """The candidate (line, message) with the smallest line, or None."""
    candidates = [c for c in candidates if c is not None]
    return min(candidates, key=itemgetter(0)) if candidates else None


def _sorted_ids(vid: np.ndarray, vlines: np.ndarray):
    """(order, sorted ids, duplicate problem or None): a stable argsort does both jobs."""
    order = np.argsort(vid, kind="stable")
    s = vid[order]
    dup = np.flatnonzero(s[1:] == s[:-1]) + 1          # positions (in sorted order) of repeats
    if dup.size == 0:
        return order, s, None
    k = dup[np.argmin(vlines[order[dup]])]              # the earliest repeated definition
    first = order[np.searchsorted(s, s[k])]             # stable sort: first of its group = first line
    return order, s, (int(vlines[order[k]]), f"duplicate vertex id {s[k]} (first defined on line {vlines[first]})")


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


_ORDER_NAMES = {"toro": "the TORO order (Ixx Ixy Iyy Itt Ixt Iyt)", "g2o": "the g2o order (I11 I12 I13 I22 I23 I33)"}


def _symmetric(six: np.ndarray, index: np.ndarray) -> np.ndarray:
    """(m, 3, 3) from the six stored entries (columns of ``six``) by the index map, in cache-sized
    blocks of rows (3× faster than one fancy index on millions of rows)."""
    out = np.empty((six.shape[0], 9))
    flat = index.ravel()
    for start in range(0, six.shape[0], 1 << 14):
        np.take(six[start:start + (1 << 14)], flat, axis=1, out=out[start:start + (1 << 14)])
    return out.reshape(-1, 3, 3)


def _information(evals: np.ndarray, fmt: str, order: str) -> np.ndarray:
    """The information matrices as written (m, 3, 3), read in ``order`` for TORO files."""
    six = evals[:, 3:]
    return _symmetric(six, G2O_INFO_INDEX if fmt != "toro" or order == "g2o" else TORO_INFO_INDEX)


def _graph_information(raw: np.ndarray, dtheta: np.ndarray, cost: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(the information of eq. (3) (m, 3, 3), the given matrices when they differ from it, else None): the file's
    matrices ``raw`` taken for ``cost``'s error (``formats.py``, "The cost each format means")."""
    if COST_FRAME[cost] == "tail":
        return raw, None
    return to_tail_frame(raw, dtheta), raw


def _drop_cross_terms(raw: np.ndarray) -> np.ndarray:
    """``information="blocks"``: Ω with its translation–rotation entries Ω_tθ set to 0, shape (m, 3, 3)."""
    out = raw.copy()
    out[:, :2, 2] = 0.0
    out[:, 2, :2] = 0.0
    return out


def _repair(path, raw: np.ndarray, elines: np.ndarray) -> np.ndarray:
    """``repair=True``: every matrix of ``raw`` that fails :func:`is_spd` replaced by the nearest positive-definite
    one (``posegraph_base.nearest_spd``), counted and logged; matrices with no positive eigenvalue stay (refused
    later, as without the repair)."""
    with np.errstate(over="ignore", invalid="ignore"):
        bad = np.flatnonzero(~is_spd(raw))
    if bad.size == 0:
        return raw
    fixed = nearest_spd(np.where(np.isfinite(raw[bad]), raw[bad], 0.0))
    ok = np.isfinite(fixed).all(axis=(1, 2)) & np.isfinite(raw[bad]).all(axis=(1, 2))
    out = raw.copy()
    out[bad[ok]] = fixed[ok]
    if ok.any():
        logger.warning("%s: %d information matrix(es) not positive definite replaced by the nearest positive-definite "
                       "matrix (eigenvalues raised to %g of the largest; the first on line %d)",
                       path, int(ok.sum()), REPAIR_FLOOR, int(elines[bad[ok][0]]))
    return out


def _order_hint(evals: np.ndarray, order: str) -> str:
    """For an EDGE2 file whose information fails in ``order``: a hint when every EDGE2 line would be
    positive definite in the other order, else ""."""
    other = "g2o" if order == "toro" else "toro"
    info = _information(evals, "toro", other)
    with np.errstate(over="ignore", invalid="ignore"):
        fits = bool(is_spd(info).all())
    if not fits:
        return ""
    fix = "edge2_order='g2o'" if other == "g2o" else "edge2_order='toro' (the default)"
    flag = "--edge2-order g2o" if other == "g2o" else "--edge2-order toro"
    return (f" in {_ORDER_NAMES[order]}; every EDGE2 line of this file is positive definite in "
            f"{_ORDER_NAMES[other]}: if the file stores its information that way, read it with "
            f"read_graph(path, {fix}) (CLI: {flag})")


def _blocks_hint(raw: np.ndarray) -> str:
    """For a matrix that is not positive definite: the fixes that would read it (``information="blocks"`` when its
    translation and rotation blocks are each positive definite; ``repair=True`` always)."""
    blocks = _drop_cross_terms(raw[None])[0]
    with np.errstate(over="ignore", invalid="ignore"):
        fits = bool(is_spd(blocks[None])[0])
    first = ("its translation and rotation blocks are each positive definite: read_graph(path, information='blocks') "
             "(CLI: --information blocks) drops the cross terms, as SE-Sync does; or " if fits else "")
    return (f"; {first}read_graph(path, repair=True) (CLI: --repair-information) replaces such matrices by the "
            f"nearest positive-definite one")


def _bad_information(info: np.ndarray, raw: np.ndarray, elines: np.ndarray, hint):
    """First edge whose information (as the graph would hold it) fails :func:`is_spd` — the very test PoseGraph
    applies. ``hint()`` gives the EDGE2-order hint appended to a "not positive definite" message."""
    with np.errstate(over="ignore", invalid="ignore"):  # absurdly large entries: reported below
        bad = np.flatnonzero(~is_spd(info))
    if bad.size == 0:
        return None
    k = bad[0]
    if not np.isfinite(info[k]).all():
        return int(elines[k]), "information matrix overflows when rotated to the frame of eq. (3)"
    with np.errstate(over="ignore", invalid="ignore"):
        ev = np.linalg.eigvalsh(raw[k]) if np.isfinite(2.0 * raw[k]).all() else np.full(3, np.nan)
    shown = ", ".join(f"{e:.6g}" for e in ev)
    if ev.min() > 0:  # positive definite on paper, but not usable in floating point
        return int(elines[k]), (f"information matrix is not numerically positive definite "
                                f"(entries too large or too badly scaled; eigenvalues {shown})")
    if np.isnan(ev).any():
        return int(elines[k]), "information matrix is not numerically positive definite (entries too large)"
    extra = hint() or _blocks_hint(raw[k])
    return int(elines[k]), f"information matrix is not positive definite (eigenvalues {shown}){extra}"


def _warn_ignored(path, parsed, graph: PoseGraph) -> None:
    if parsed.fix.count:
        logger.warning("%s: ignoring %d FIX line(s) (the first on line %d: %s): LAGO anchors the estimate "
                       "at the smallest pose id, %d (lago(graph, anchor=ID); CLI: --anchor ID)",
                       path, parsed.fix.count, parsed.fix.first_line, parsed.fix.first_text,
                       int(graph.ids.min()))
    if parsed.equiv.count:
        logger.warning("%s: ignoring %d EQUIV line(s) (the first on line %d: %s): TORO collapses such "
                       "vertex pairs only on request; lago_cvx keeps every vertex and edge as written",
                       path, parsed.equiv.count, parsed.equiv.first_line, parsed.equiv.first_text)


def _build(path, parsed, order: str, cost: str | None, information: str, repair: bool) -> PoseGraph:
    vid, vval, vlines = parsed.vid, parsed.vval, parsed.vlines
    eid, evals, elines = parsed.eid, parsed.evals, parsed.elines
    if vid.size == 0 and eid.shape[0] == 0:
        raise ParseError(path, None, "file contains no vertices and no edges")
    if cost is None:  # EDGE2 lines in the g2o order are g2o records under the TORO tag: g2o's cost
        cost = COST_OF_FORMAT["g2o" if order == "g2o" else parsed.fmt]
    raw = _information(evals, parsed.fmt, order)
    if information == "blocks":
        raw = _drop_cross_terms(raw)
    if repair:
        raw = _repair(path, raw, elines)
    info, given = _graph_information(raw, evals[:, 2], cost)
    hint = (lambda: _order_hint(evals, order)) if parsed.fmt == "toro" else (lambda: "")

    # Semantic problems; the earliest line among them is reported. Duplicate and unknown ids are
    # checked here. Self-loops and information matrices are checked by PoseGraph itself (with the
    # same is_spd test), so they are only located here when it objects — or when another semantic
    # problem was found and the earliest one must be chosen.
    if vid.size:
        order_v, ids, duplicate = _sorted_ids(vid, vlines)
        initial = vval[order_v]
    else:
        flat = np.sort(eid.ravel())
        ids = flat[np.r_[True, flat[1:] != flat[:-1]]] if flat.size else flat
        duplicate, initial = None, None
        logger.info("%s: no VERTEX lines; %d poses inferred from the ids of the %d edges (no initial guess)",
                    path, ids.size, eid.shape[0])
    if ids.size and ids[-1] - ids[0] == ids.size - 1:  # contiguous ids (the usual 0 … n−1): no search
        pos = np.clip(eid - ids[0], 0, ids.size)
    else:
        pos = np.searchsorted(ids, eid)  # (m, 2) pose indices of the endpoints, if the ids are known
    problem = _first([duplicate, _unknown_vertex(eid, pos, elines, ids) if vid.size and eid.size else None])
    if problem:
        raise ParseError(path, *_first([problem, _self_loop(eid, elines), _bad_information(info, raw, elines, hint)]))
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # absurd magnitudes are reported below
            return PoseGraph(n_poses=ids.size, tails=pos[:, 0], heads=pos[:, 1], delta_l=evals[:, 0:2],
                             delta=evals[:, 2], information=info, initial=initial, ids=ids,
                             name=Path(path).name, cost=cost, given_information=given)
    except ValueError as exc:  # GraphError from PoseGraph
        problem = _first([_self_loop(eid, elines), _bad_information(info, raw, elines, hint)])
        if problem:
            raise ParseError(path, *problem) from None
        raise ParseError(path, None, f"invalid pose graph: {exc}") from None  # not expected


# ----------------------------------------------------------------------------- public API
def read_graph(path, *, format: str | None = None, edge2_order: str | None = None, cost: str | None = None,
               information: str = "full", repair: bool = False) -> PoseGraph:
    """Read a g2o or TORO pose-graph file into a :class:`PoseGraph` (``name`` = the file's name).

    A file whose first record is ``VERTEX_SE3:QUAT`` or ``EDGE_SE3:QUAT`` is a 3-D graph: it is read by
    :func:`lago_cvx.io.space.read_graph3d` into a :class:`~lago_cvx.posegraph3d.PoseGraph3D` (``dim`` 3;
    ``format`` and ``edge2_order`` do not apply).

    ``format``: None (auto-detect: the first data tag decides), ``"g2o"`` or ``"toro"``.

    ``cost``: the error the file's information matrices are read for, one of ``lago_cvx.conventions.COSTS``;
    None (the default) takes the format's own — ``"g2o"`` for g2o files (and ``EDGE2`` lines read with
    ``edge2_order="g2o"``, g2o records under the TORO tag), ``"paper"`` (eq. (3)) for TORO files.
    The graph holds the information of eq. (3) for that cost (``formats.py``; ``PoseGraph.cost``).

    ``information``: ``"full"`` (every entry as written) or ``"blocks"`` (the translation–rotation cross terms
    dropped, as SE-Sync reads a file; for files whose whole matrices are not positive definite while their blocks
    are). ``repair``: replace every information matrix that is not positive definite (e.g. g2o's own saved files,
    written with 6 significant digits) by the nearest positive-definite one (``posegraph_base.nearest_spd``),
    counted and logged; without it such a file is refused, naming both options.

    ``edge2_order``: how the six information entries of ``EDGE2`` lines are read — None or ``"toro"``
    (the documented TORO order ``Ixx Ixy Iyy Itt Ixt Iyt`` in the TORO frame), or ``"g2o"`` for files
    that store g2o records under the TORO tag (``I11 I12 I13 I22 I23 I33``, read exactly like
    ``EDGE_SE2``). Never guessed: a TORO reading that is not positive definite says so when the other
    order would fit every line. Ignored for g2o files.

    Raises :class:`ParseError` for every unreadable or invalid input; FIX and EQUIV lines are ignored
    with one warning each (module docstring).
    """
    fmt_forced = check_format(format)
    order = check_edge2_order(edge2_order)
    if information not in READ_INFORMATION:
        raise OptionError(f"unknown information {information!r}; expected one of {READ_INFORMATION}")
    data = read_bytes(path)
    if is_3d_tag(first_tag(data) or ""):  # VERTEX_SE3:QUAT / EDGE_SE3:QUAT: a 3-D graph (space.py)
        return read_graph3d(path, data=data, cost=cost, information=information, repair=repair)
    cost = None if cost is None else check_cost(cost)
    parsed = parse_fast(data, fmt_forced)
    if parsed is None:
        parsed = parse_careful(decode(data), fmt_forced, path)
    del data  # the text is not needed any more (a third of the peak memory at a million poses)
    graph = _build(path, parsed, order, cost, information, bool(repair))
    _warn_ignored(path, parsed, graph)
    return graph


def detect_format(path) -> str:
    """``"g2o"`` or ``"toro"``, decided by the first data tag of the file (comments, FIX and EQUIV
    lines are neutral).

    Raises :class:`ParseError` for an unreadable file, an unknown first tag or a file without data.
    """
    text = decode(read_bytes(path))
    for lineno, line in enumerate(text.split("\n"), 1):
        toks = line.split(maxsplit=1)
        if not toks or toks[0][0] == "#" or toks[0] in (FIX, EQUIV):
            continue
        if is_3d_tag(toks[0]):
            return "g2o"  # the 3-D g2o records (space.py)
        spec = SPECS.get(toks[0])
        if spec is None:
            raise ParseError(path, lineno, unknown_tag(toks[0], None))
        return spec.fmt
    raise ParseError(path, None, "file contains no vertices and no edges")
