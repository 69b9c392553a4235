r"""Reading and writing 3-D pose graphs: g2o's ``VERTEX_SE3:QUAT`` and ``EDGE_SE3:QUAT`` records.

Format
======
::

    VERTEX_SE3:QUAT id x y z qx qy qz qw
    EDGE_SE3:QUAT   i j x y z qx qy qz qw I11 I12 I13 I14 I15 I16 I22 … I66

The edge measures pose j in the frame of pose i (t̃_ij = (x, y, z), R̃_ij from the quaternion, scalar
last) and carries the 21 entries of the upper triangle of the 6×6 information matrix, row by row, in the
order (x, y, z, φx, φy, φz): translation first (:mod:`lago_cvx.posegraph3d`). This is the format of
SE-Sync's and Carlone's 3-D benchmarks and of GTSAM's ``pose3example*.txt``. A g2o file's information is written
for g2o's error (``cost="g2o"``, the default); ``cost="gtsam"`` reads the same matrices as GTSAM's ``readG2o``
does, for the Log error (:mod:`lago_cvx.posegraph3d`). The lexical rules are the planar files' (``formats.py``:
``#`` comments, LF, CRLF or CR line ends, a byte-order mark skipped, a missing final newline accepted, ids any
64-bit integers, numbers plain ASCII decimals).

Every problem raises :class:`ParseError` naming ``file:line`` and the offending token or field: a wrong
token count, a bad number or id, a quaternion of zero norm, an information matrix that is not positive
definite (naming ``information="blocks"`` when its translation and rotation blocks are, and ``repair=True``),
duplicate vertex ids, edges to undefined vertices, self-loops, a file mixing planar and 3-D records, other 3-D
records (``VERTEX_SE3:EXPMAP``, ``EDGE3``, … are named as unsupported). A quaternion whose norm differs from 1
by more than :data:`QUATERNION_TOLERANCE` is normalized with one warning per file (logger ``lago_cvx.io``) naming
the count and the first line; every quaternion is normalized (files print 6–7 digits, so norms of 1 ± 1e-6 are
ordinary; g2o itself normalizes the edges' quaternions but not the vertices'). ``FIX`` lines are ignored with one warning, as in
planar files. A file without vertex lines defines the poses of its edges and has no initial guess.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..conventions import COST_OF_FORMAT, check_cost
from ..errors import OptionError, ParseError
from ..posegraph3d import PoseGraph3D, is_spd6, without_cross_terms
from ..posegraph_base import REPAIR_FLOOR, nearest_spd
from ..so3 import quat_to_rot, rot_to_quat
from .careful import Notes, _convert, _Records, decode, ignored_line, read_bytes, unknown_tag, without_comment
from .fastpath import parse_fast
from .formats import EQUIV, FIX, NON_POSE_TAGS, SPECS, Spec

__all__ = ["VERTEX3", "EDGE3", "TAGS3", "QUATERNION_TOLERANCE", "is_3d_tag", "first_tag", "read_graph3d",
           "records3d"]

logger = logging.getLogger("lago_cvx.io")

_INFO_FIELDS = tuple(f"I{r + 1}{c + 1}" for r in range(6) for c in range(r, 6))
VERTEX3 = Spec("VERTEX_SE3:QUAT", "g2o", ("id", "x", "y", "z", "qx", "qy", "qz", "qw"), 1, 9)
EDGE3 = Spec("EDGE_SE3:QUAT", "g2o", ("i", "j", "x", "y", "z", "qx", "qy", "qz", "qw") + _INFO_FIELDS, 2, 31)
TAGS3 = {VERTEX3.tag: VERTEX3, EDGE3.tag: EDGE3}

#: |‖q‖ − 1| above which a quaternion is reported (once per file) before it is normalized.
QUATERNION_TOLERANCE = 1e-4

_UPPER = np.triu_indices(6)


def is_3d_tag(tag: str) -> bool:
    return tag in TAGS3


def first_tag(data: bytes) -> str | None:
    """The first data tag of a file's bytes (comments, blank, FIX and EQUIV lines skipped), or None."""
    start = 3 if data.startswith(b"\xef\xbb\xbf") else 0
    while start < len(data):
        end = data.find(b"\n", start)
        end = len(data) if end < 0 else end
        toks = data[start:end].split(None, 1)
        start = end + 1
        if toks and not toks[0].startswith(b"#"):
            tag = toks[0].decode("utf-8", "replace")
            if tag not in (FIX, EQUIV):
                return tag
    return None


# ----------------------------------------------------------------------------- scanning
def _other_tag_problem(tag: str, seen_line: int | None) -> str:
    if tag in SPECS:
        where = f" (3-D records from line {seen_line})" if seen_line else ""
        return (f"mixes planar and 3-D records: planar tag {tag!r} in a file of VERTEX_SE3:QUAT/EDGE_SE3:QUAT "
                f"records{where}")
    if NON_POSE_TAGS.get(tag) == "3-D":
        return f"{tag!r} is not supported: 3-D pose graphs are read as VERTEX_SE3:QUAT/EDGE_SE3:QUAT records"
    problem = unknown_tag(tag, None)
    if problem.startswith("unknown tag"):
        return f"unknown tag {tag!r} (expected VERTEX_SE3:QUAT/EDGE_SE3:QUAT)"
    return problem


def _scan(text: str):
    """(vertex records, edge records, first structural problem or None, FIX notes)."""
    verts, edges = _Records([], [], []), _Records([], [], [])
    fix, equiv = Notes(), Notes()
    seen = None
    for lineno, line in enumerate(text.split("\n"), 1):
        if "#" in line:
            line = without_comment(line)
        toks = line.split()
        if not toks:
            continue
        spec = TAGS3.get(toks[0])
        if spec is None:
            if toks[0] in (FIX, EQUIV):
                problem = ignored_line(toks, lineno, fix, equiv)
                if problem:
                    return verts, edges, problem, fix
                continue
            return verts, edges, (lineno, _other_tag_problem(toks[0], seen)), fix
        seen = seen or lineno
        if len(toks) != spec.n_tokens:
            return verts, edges, (lineno, f"{spec.tag} expects {spec.n_tokens - 1} numbers after the tag, got "
                                          f"{len(toks) - 1}"), fix
        rec = edges if spec is EDGE3 else verts
        rec.text.append(line)
        rec.lines.append(lineno)
        rec.ids.extend(toks[1:1 + spec.n_ids])
    return verts, edges, None, fix


def _rotations(q: np.ndarray, lines: np.ndarray, path, bad_norms: list):
    """Rotation matrices of quaternions (k, 4); ParseError at a zero quaternion; far-from-unit ones noted."""
    norm = np.linalg.norm(q, axis=1)
    zero = np.flatnonzero(~(norm > 1e-12))
    if zero.size:
        raise ParseError(path, int(lines[zero[0]]), "quaternion (qx, qy, qz, qw) has zero norm: no rotation")
    far = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_TOLERANCE)
    if far.size:
        bad_norms.append((int(lines[far[0]]), float(norm[far[0]]), far.size))
    return quat_to_rot(q / norm[:, None])


def _fixes(matrix: np.ndarray) -> str:
    """The options that would read a matrix (6, 6) that is not positive definite: ``information="blocks"`` when its
    translation and rotation blocks are each positive definite, ``repair=True`` always."""
    blocks = is_spd6(without_cross_terms(matrix[None]))[0] if np.isfinite(matrix).all() else False
    first = ("its translation and rotation blocks are each positive definite: read_graph(path, "
             "information='blocks') (CLI: --information blocks) drops the cross terms, as SE-Sync does; or "
             if blocks else "")
    return (f"; {first}read_graph(path, repair=True) (CLI: --repair-information) replaces such matrices by the "
            f"nearest positive-definite one")


def _repair(path, info: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """``repair=True``: every matrix of ``info`` (m, 6, 6) that fails :func:`is_spd6` replaced by the nearest
    positive-definite one (``posegraph_base.nearest_spd``), counted and logged; matrices with no positive
    eigenvalue or with non-finite entries stay (refused below, as without the repair)."""
    bad = np.flatnonzero(~is_spd6(info))
    if bad.size == 0:
        return info
    finite = np.isfinite(info[bad]).all(axis=(1, 2))
    fixed = nearest_spd(np.where(np.isfinite(info[bad]), info[bad], 0.0))
    ok = finite & np.isfinite(fixed).all(axis=(1, 2))
    out = info.copy()
    out[bad[ok]] = fixed[ok]
    if ok.any():
        logger.warning("%s: %d information matrix(es) not positive definite replaced by the nearest positive-definite "
                       "matrix (eigenvalues raised to %g of the largest; the first on line %d)", path, int(ok.sum()),
                       REPAIR_FLOOR, int(lines[bad[ok][0]]))
    return out


def _information(vals: np.ndarray, lines: np.ndarray, path, information: str = "full",
                 repair: bool = False) -> np.ndarray:
    """The 6×6 information matrices (m, 6, 6) of the 21 upper-triangle entries ``vals`` (m, 21), cross terms
    dropped for ``information="blocks"``, repaired for ``repair``; ``ParseError`` at the first line whose matrix is
    not positive definite, naming the options that would read it (:func:`_fixes`)."""
    info = np.zeros((vals.shape[0], 6, 6))
    info[:, _UPPER[0], _UPPER[1]] = vals
    info[:, _UPPER[1], _UPPER[0]] = vals
    if information == "blocks":
        info = without_cross_terms(info)
    if repair:
        info = _repair(path, info, lines)
    bad = np.flatnonzero(~is_spd6(info))
    if bad.size:
        k = int(bad[0])
        ev = np.linalg.eigvalsh(info[k]) if np.isfinite(info[k]).all() else np.full(6, np.nan)
        shown = ", ".join(f"{e:.6g}" for e in ev)
        what = "information matrix" + (" without its cross terms" if information == "blocks" else "")
        raise ParseError(path, int(lines[k]), f"{what} is not positive definite (eigenvalues {shown})"
                         + ("" if information == "blocks" or repair else _fixes(info[k])))
    return info


def _ids(path, vid, vlines, eid, elines):
    """(sorted ids (n,), vertex order or None, edge endpoints as indices (m, 2)); ParseError for duplicate
    vertex ids, edges to undefined vertices and self-loops (the earliest line among them)."""
    problems = []
    if vid.size:
        order = np.argsort(vid, kind="stable")
        s = vid[order]
        dup = np.flatnonzero(s[1:] == s[:-1]) + 1
        if dup.size:
            k = dup[np.argmin(vlines[order[dup]])]
            first = order[np.searchsorted(s, s[k])]
            problems.append((int(vlines[order[k]]), f"duplicate vertex id {s[k]} (first defined on line "
                                                     f"{vlines[first]})"))
        ids = np.unique(vid)
    else:
        order = None
        ids = np.unique(eid.ravel())
    pos = np.searchsorted(ids, eid)
    if vid.size and eid.size:
        known = ids[np.minimum(pos, ids.size - 1)] == eid
        bad = np.flatnonzero(~known.all(axis=1))
        if bad.size:
            k = bad[0]
            v = eid[k, 0] if not known[k, 0] else eid[k, 1]
            problems.append((int(elines[k]), f"edge refers to vertex {v}, which no VERTEX_SE3:QUAT line defines"))
    loops = np.flatnonzero(eid[:, 0] == eid[:, 1]) if eid.size else np.zeros(0, np.int64)
    if loops.size:
        k = loops[0]
        problems.append((int(elines[k]), f"self-loop edge {eid[k, 0]} -> {eid[k, 1]}"))
    if problems:
        raise ParseError(path, *min(problems, key=lambda p: p[0]))
    return ids, order, pos


def read_graph3d(path, *, data: bytes | None = None, cost: str | None = None, information: str = "full",
                 repair: bool = False) -> PoseGraph3D:
    """Read a g2o file of ``VERTEX_SE3:QUAT`` / ``EDGE_SE3:QUAT`` records into a :class:`PoseGraph3D`
    (``name`` = the file's name). ``data``: the file's bytes when read already. ``cost``: the error the
    information matrices are read for, ``"g2o"`` (None, the format's own: ``conventions.COST_OF_FORMAT``) or
    ``"gtsam"`` (``posegraph3d``; the matrices are kept as written either way). ``information``: ``"full"`` (every
    entry) or ``"blocks"`` (the translation–rotation cross terms dropped, as SE-Sync reads a file: for files whose
    6×6 matrices are not positive definite while their two blocks are). ``repair``: replace every matrix that is
    not positive definite by the nearest positive-definite one, counted and logged. Every problem raises
    :class:`ParseError` with ``path:line:`` (module docstring); a matrix that is not positive definite names the
    option that would read it."""
    cost = COST_OF_FORMAT["g2o"] if cost is None else check_cost(cost, dim=3)
    if information not in ("full", "blocks"):
        raise OptionError(f"unknown information {information!r}; expected one of ('full', 'blocks')")
    data = read_bytes(path) if data is None else data
    parsed = parse_fast(data, "g2o", specs=(VERTEX3, EDGE3))  # ordinary files: vectorized (fastpath.py)
    if parsed is not None:
        vid, vval, vlines, eid, evals, elines, fix = (parsed.vid, parsed.vval, parsed.vlines, parsed.eid,
                                                      parsed.evals, parsed.elines, parsed.fix)
    else:  # anything unusual: line by line, naming the first problem
        verts, edges, problem, fix = _scan(decode(data))
        vid, vval, verr = _convert(verts, VERTEX3)
        eid, evals, eerr = _convert(edges, EDGE3)
        found = [p for p in (problem, verr, eerr) if p is not None]
        if found:
            raise ParseError(path, *min(found, key=lambda p: p[0]))
        vlines, elines = np.asarray(verts.lines, np.int64), np.asarray(edges.lines, np.int64)
        vid = vid[:, 0]
    if vid.size == 0 and eid.shape[0] == 0:
        raise ParseError(path, None, "file contains no vertices and no edges")
    bad_norms: list = []
    vR = _rotations(vval[:, 3:7], vlines, path, bad_norms) if vid.size else None
    eR = _rotations(evals[:, 3:7], elines, path, bad_norms)
    info = _information(evals[:, 7:], elines, path, information, bool(repair))
    ids, order, pos = _ids(path, vid, vlines, eid, elines)
    if bad_norms:
        line, norm, _ = min(bad_norms)
        logger.warning("%s: %d quaternion(s) differ from unit norm by more than %g (the first on line %d: norm %.9g); "
                       "normalized", path, sum(b[2] for b in bad_norms), QUATERNION_TOLERANCE, line, norm)
    if fix.count:
        logger.warning("%s: ignoring %d FIX line(s) (the first on line %d: %s): the estimate is anchored at the "
                       "smallest pose id, %d (--anchor ID to choose another)", path, fix.count, fix.first_line,
                       fix.first_text, int(ids.min()))
    it = iR = None
    if vid.size:
        it, iR = vval[order, :3], vR[order]
    else:
        logger.info("%s: no VERTEX lines; %d poses inferred from the ids of the %d edges (no initial guess)",
                    path, ids.size, eid.shape[0])
    return PoseGraph3D(n_poses=ids.size, tails=pos[:, 0], heads=pos[:, 1], delta_t=evals[:, :3], delta_R=eR,
                       information=info, initial_t=it, initial_R=iR, ids=ids, name=Path(path).name, cost=cost)


# ----------------------------------------------------------------------------- writing
def records3d(path, graph: PoseGraph3D, poses=None) -> list:
    """The records of ``graph`` as ``[(tag, ids (k, n_ids), values (k, n_values)), …]`` for
    ``writer.write_graph``: vertex lines from ``poses`` = (t (n, 3), R (n, 3, 3)) if given, else from the
    graph's initial guess, else none; quaternions with qw ≥ 0. Non-finite poses raise ``OptionError``."""
    if poses is None:
        poses = graph.initial
    out = []
    if poses is not None:
        t, R = (np.asarray(p, dtype=float) for p in poses)
        if t.shape != (graph.n_poses, 3) or R.shape != (graph.n_poses, 3, 3):
            raise OptionError(f"poses must have shapes ({graph.n_poses}, 3), ({graph.n_poses}, 3, 3), got "
                              f"{t.shape}, {R.shape}")
        if not (np.isfinite(t).all() and np.isfinite(R).all()):
            raise OptionError(f"refusing to write {path}: poses are not finite; nothing was written")
        out.append((VERTEX3.tag, graph.ids[:, None], np.column_stack([t, rot_to_quat(R)])))
    elif graph.n_edges == 0:
        raise OptionError("nothing to write: the graph has no edges and no poses were given")
    ids = np.column_stack([graph.ids[graph.tails], graph.ids[graph.heads]])
    vals = np.column_stack([graph.delta_t, rot_to_quat(graph.delta_R), graph.information[:, _UPPER[0], _UPPER[1]]])
    out.append((EDGE3.tag, ids, vals))
    return out
