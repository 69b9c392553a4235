"""Writing g2o and TORO files (formats in ``formats.py``), replacing a file atomically."""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ..posegraph import PoseGraph, wrap_angle
from .formats import check_format, g2o_to_toro

__all__ = ["write_graph", "write_bytes"]

logger = logging.getLogger("lago_cvx.io")


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
    fmt = check_format(format)
    if fmt is None:
        raise OptionError("format must be 'g2o' or 'toro'")
    path = Path(path)
    if poses is None:
        poses = graph.initial
    if poses is not None:
        poses = np.asarray(poses, dtype=float)
        if poses.shape != (graph.n_poses, 3):
            raise OptionError(f"poses must have shape ({graph.n_poses}, 3), got {poses.shape}")
        if not np.isfinite(poses).all():
            raise OptionError("poses must be finite")
        if wrap_angles:
            poses = np.column_stack([poses[:, :2], _wrap_vertex_angles(poses[:, 2])])
    elif graph.n_edges == 0:
        raise OptionError("nothing to write: the graph has no edges and no poses were given")
    elif np.unique(np.concatenate([graph.tails, graph.heads])).size < graph.n_poses:
        logger.warning("%s: writing an edge-only file; poses that appear in no edge are lost", path)

    vtag = "VERTEX_SE2" if fmt == "g2o" else "VERTEX2"
    etag = "EDGE_SE2" if fmt == "g2o" else "EDGE2"
    info = graph.information
    if fmt == "g2o":
        six = info[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    else:
        t = g2o_to_toro(info, graph.delta)
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


def write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same directory, then an atomic rename."""
    import tempfile

    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".lago-cvx-", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
