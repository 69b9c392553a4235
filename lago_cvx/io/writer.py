"""Writing g2o and TORO files (formats in ``formats.py``; where the bytes go in ``output.py``).

Numbers
=======
Ids are written with ``%d``, every other number exactly as ``repr`` writes it (the shortest string
that reads back to the same double), so read → write → read reproduces a graph bit for bit.

Speed
=====
Records are formatted in blocks of :data:`BLOCK` lines, column by column in NumPy, never line by line
in Python: ``floatfmt.py`` finds the shortest digits of a whole column at once (``repr``'s, byte for
byte; the few values it cannot decide with margin go to ``repr`` itself) and lays the columns out side
by side; a column whose values are all equal (same bits) is one literal. As a guard, the first and last
number of every column of every block are compared with ``repr``; should one differ, the block is
formatted by one ``%`` operation instead (a format string repeated once per line, applied to the
flattened values) — the reference the tests compare with. Blocks are formatted by ``WRITE_THREADS`` (one per core)
threads and written in file order.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from ..sparse import cores
from ..stacks import unique_sorted
from ..errors import OptionError
from ..metrics3d import poses_of
from ..posegraph import PoseGraph, wrap_angle
from ..posegraph_base import as_graph
from .floatfmt import int_fields, join_fields, repr_fields
from .formats import check_format
from .output import open_output, same_file

__all__ = ["write_graph", "write_bytes", "format_records", "format_records_py", "open_output", "same_file", "BLOCK"]

logger = logging.getLogger("lago_cvx.io")

#: Lines formatted at once.
BLOCK = 1 << 15

_LIMIT_INTEGRAL = 1e16  # below this, repr(x) of an integral float is str(int(x)) + ".0"


def _wrap_vertex_angles(theta: np.ndarray) -> np.ndarray:
    """Angles outside [−π, π) wrapped into it; angles already inside are kept bit for bit."""
    inside = (theta >= -np.pi) & (theta < np.pi)
    w = wrap_angle(theta)
    w = np.where(w >= np.pi, w - 2.0 * np.pi, w)  # (a + π) mod 2π can round up to 2π
    return np.where(inside, theta, w)


def _column_format(col: np.ndarray):
    """(format piece, values for it or None) for one float column of a block, as ``repr`` would write
    it: a literal when all values have the same bits, ``%d.0`` with int64 values when all are integral
    (no −0.0) and below 1e16 in magnitude, else ``%r``."""
    first = col[0]
    bits = col.view(np.int64)
    if (bits == bits[0]).all():
        return repr(float(first)), None
    if (np.abs(col) < _LIMIT_INTEGRAL).all() and (col == np.rint(col)).all() \
            and not (np.signbit(col) & (col == 0.0)).any():
        return "%d.0", col.astype(np.int64)
    return "%r", col


def format_records_py(tag: str, ids: np.ndarray, values: np.ndarray) -> bytes:
    """``format_records`` by one ``%`` operation on a format string repeated once per line (the
    reference: Python's own ``%d`` and ``%r``)."""
    k = ids.shape[0]
    if k == 0:
        return b""
    pieces, columns = [tag], []
    for c in range(ids.shape[1]):
        pieces.append("%d")
        columns.append(ids[:, c])
    for c in range(values.shape[1]):
        piece, column = _column_format(np.ascontiguousarray(values[:, c]))
        pieces.append(piece.replace("%", "%%") if column is None else piece)
        if column is not None:
            columns.append(column)
    line = " ".join(pieces) + "\n"
    args = np.empty((k, len(columns)), dtype=object)
    for c, column in enumerate(columns):
        args[:, c] = column  # int64 → Python int, float64 → Python float
    return ((line * k) % tuple(args.ravel())).encode("ascii")


def format_records(tag: str, ids: np.ndarray, values: np.ndarray) -> bytes:
    """The lines ``TAG id… v1 v2 …`` for integer ``ids`` (k, n_ids) and float ``values`` (k, n_values):
    bytes identical to ``"".join(f"{tag}" + " %d" * n_ids + " %r" * n_values + "\n" % row)``,
    formatted column by column (module docstring)."""
    k = ids.shape[0]
    if k == 0:
        return b""
    items, probes = [tag.encode("ascii")], []
    for c in range(ids.shape[1]):
        items += [b" ", int_fields(ids[:, c])]
    for c in range(values.shape[1]):
        col = np.ascontiguousarray(values[:, c], dtype=float)
        bits = col.view(np.int64)
        if (bits == bits[0]).all():
            items.append(b" " + repr(float(col[0])).encode("ascii"))
        else:
            items += [b" ", repr_fields(col)]
            probes.append(c)
    text = join_fields(k, items)
    if probes:  # guard: the first and the last line against Python's own formatting
        first = text[:text.index(b"\n") + 1]
        last = text[text.rindex(b"\n", 0, len(text) - 1) + 1:] if k > 1 else first
        if (first != format_records_py(tag, ids[:1], values[:1])
                or last != format_records_py(tag, ids[-1:], values[-1:])):
            logger.debug("vectorized formatting disagrees with %%r; block formatted by Python")
            return format_records_py(tag, ids, values)
    return text


def _edge_block(graph: PoseGraph, info: np.ndarray, fmt: str, rows: slice):
    """(ids (k, 2), values (k, 9): Δx Δy δ and the six stored information entries) of some edges; ``info``
    (m, 3, 3) the information in the format's frame."""
    info, delta = info[rows], graph.delta[rows]
    if fmt == "g2o":
        six = info[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    else:
        six = info[:, [0, 0, 1, 2, 0, 1], [0, 1, 1, 2, 2, 2]]
    ids = np.column_stack([graph.ids[graph.tails[rows]], graph.ids[graph.heads[rows]]])
    return ids, np.column_stack([graph.delta_l[rows], delta, six])


def _checked_poses(path, graph: PoseGraph, poses):
    poses = np.asarray(poses, dtype=float)
    if poses.shape != (graph.n_poses, 3):
        raise OptionError(f"poses must have shape ({graph.n_poses}, 3), got {poses.shape}")
    bad = np.flatnonzero(~np.isfinite(poses).all(axis=1))
    if bad.size:
        k = int(bad[0])
        shown = ", ".join(repr(float(v)) for v in poses[k])
        raise OptionError(f"refusing to write {path}: {bad.size} of {graph.n_poses} poses are not finite "
                          f"(first: id {int(graph.ids[k])} = ({shown})); nothing was written")
    return poses


def _pose_arrays(graph, poses):
    """``poses`` as the graph's arrays ((n, 3), or (t, R) for a 3-D graph): any result of either dimension, a
    generated world (its truth) or the arrays themselves (``metrics3d.poses_of``); ``OptionError`` for poses of
    the other dimension, another length or another type."""
    return None if poses is None else poses_of(graph, poses)


def write_graph(path, graph: PoseGraph, poses=None, *, format: str = "g2o",
                wrap_angles: bool = True) -> Path:
    """Write ``graph`` as a g2o (default) or TORO file and return ``Path(path)``.

    ``graph`` a ``PoseGraph`` or ``PoseGraph3D``, or a generated world (``manhattan_world`` …, ``sphere_world`` …),
    whose ``graph`` is written (its initial guess, dead reckoning, as the vertices unless ``poses`` is given).
    Vertex lines come from ``poses`` ((n, 3); for a 3-D graph (t (n, 3), R (n, 3, 3)); or any result of LAGO, a
    refinement, GNC or SE-Sync; a world: its truth) if given, else from ``graph.initial``; with neither the
    file has edge lines only (poses that appear in no edge are then not represented). Ids are the
    graph's original ``ids``. Numbers are written with ``repr`` (shortest exact round trip), so
    read → write → read reproduces the graph bit for bit. Vertex angles outside [−π, π) are wrapped
    when ``wrap_angles``; edge angles δ are written as stored. The information is written in the frame of the
    format's error (``PoseGraph.information_in``): a written file means the cost the graph was read in —
    g2o's χ² of a g2o file written from a g2o- or paper-cost graph is the graph's χ² at the written poses.

    ``path`` may be a file (written to a temporary file in the same directory and moved into place
    atomically, keeping an existing file's permissions), a symbolic link (written through to its
    target), a FIFO or character device (streamed), or ``"-"`` for standard output: the rules of
    :func:`~lago_cvx.io.output.open_output`. Everything is checked before the target is touched:
    non-finite poses, poses of the other dimension, a wrong shape, type or format raise ``OptionError``, a
    ``graph`` that is no pose graph ``GraphError``, and nothing is written; a target that cannot be written raises
    ``OutputError``.
    """
    graph = as_graph(graph, "write_graph")
    fmt = check_format(format)
    if fmt is None:
        raise OptionError("format must be 'g2o' or 'toro'")
    poses = _pose_arrays(graph, poses)
    if getattr(graph, "dim", 2) == 3:  # a PoseGraph3D: VERTEX_SE3:QUAT / EDGE_SE3:QUAT (space.py)
        if fmt != "g2o":
            raise OptionError("3-D pose graphs are written as g2o (VERTEX_SE3:QUAT/EDGE_SE3:QUAT) only")
        from .space import records3d

        blocks = [format_records(*rec) for rec in records3d(path, graph, poses)]
        with open_output(path) as f:
            for block in blocks:
                f.write(block)
        return Path(path)
    if poses is None:
        poses = graph.initial
    if poses is not None:
        poses = _checked_poses(path, graph, poses)
        if wrap_angles:
            poses = np.column_stack([poses[:, :2], _wrap_vertex_angles(poses[:, 2])])
    elif graph.n_edges == 0:
        raise OptionError("nothing to write: the graph has no edges and no poses were given")
    elif unique_sorted(np.concatenate([graph.tails, graph.heads])).size < graph.n_poses:
        logger.warning("%s: writing an edge-only file; poses that appear in no edge are lost", path)

    vtag = "VERTEX_SE2" if fmt == "g2o" else "VERTEX2"
    etag = "EDGE_SE2" if fmt == "g2o" else "EDGE2"
    jobs = []  # formatting jobs in file order: vertex blocks, then edge blocks (edge arrays built per block)
    if poses is not None:
        jobs += [(lambda s=s: format_records(vtag, graph.ids[s:s + BLOCK, None], poses[s:s + BLOCK]))
                 for s in range(0, graph.n_poses, BLOCK)]
    edge_info = graph.information_in("measurement" if fmt == "g2o" else "tail")
    jobs += [(lambda s=s: format_records(etag, *_edge_block(graph, edge_info, fmt, slice(s, s + BLOCK))))
             for s in range(0, graph.n_edges, BLOCK)]
    with open_output(path) as f:
        for block in _in_order(jobs):
            f.write(block)
    return Path(path)


#: Threads formatting blocks at once: None for one per core of this process (``sparse.cores()``), at
#: most ``_AHEAD`` (NumPy's column operations release the GIL, so two threads write a million-pose file faster
#: than one: ``benchmarks/io.md``); and how many blocks may wait formatted.
WRITE_THREADS: int | None = None
_AHEAD = 4


def _in_order(jobs: list):
    """The results of ``jobs`` (callables), in order, computed by ``WRITE_THREADS`` threads with at most
    ``_AHEAD`` finished blocks held in memory; a job's exception is raised where its result is due."""
    threads = min(_AHEAD, cores()) if WRITE_THREADS is None else WRITE_THREADS
    if threads < 2 or len(jobs) < 2:
        for job in jobs:
            yield job()
        return
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(threads, thread_name_prefix="lago-write") as ex:
        pending = deque()
        for job in jobs:
            pending.append(ex.submit(job))
            if len(pending) >= _AHEAD:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def write_bytes(path, data: bytes) -> Path | None:
    """Write ``data`` (a rendered figure, say) to ``path`` by the rules of :func:`open_output`: an atomic
    replace of a regular file keeping its permissions, symbolic links written through, FIFOs and
    character devices streamed, ``"-"`` for standard output; ``OutputError`` names the path otherwise.
    Returns the path (``None`` for standard output)."""
    with open_output(path) as f:
        f.write(data)
    return None if os.fspath(path) == "-" else Path(path)
