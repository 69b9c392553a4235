r"""What the planar and the 3-D pose graph share (``posegraph.PoseGraph``, ``posegraph3d.PoseGraph3D``): the checks
of the edge indices and of the file identifiers every graph is built with, and their base ``PoseGraphBase``: the edge
indices, the sizes, the identifier look-ups, the edge selection and the short ``repr``, none of which depends on the
dimension of the poses.

A graph has ``n_poses`` poses indexed 0 … n−1 and ``m`` edges, edge k from ``tails[k]`` to ``heads[k]``; ``ids``
(n,) are the identifiers of the file (for messages, for writing back, and for the anchor, always given by id).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from .errors import GraphError

__all__ = ["nearest_spd", "REPAIR_FLOOR", "readonly", "edge_indices", "check_endpoints", "pose_ids", "PoseGraphBase", "as_graph"]


#: ``nearest_spd``'s eigenvalue floor, relative to each matrix's largest eigenvalue: the repaired matrix has a
#: condition number of at most 1e8, the range of the public files' own informations (input_INTEL: 11 to 1e8).
REPAIR_FLOOR = 1e-8


def nearest_spd(mats: np.ndarray, *, floor: float = REPAIR_FLOOR) -> np.ndarray:
    """The positive-definite matrices nearest to the symmetric parts S of ``mats`` (m, k, k) in the Frobenius
    norm, with eigenvalues at least ``floor``·λ_max(S) (Higham 1988: S = V diag(λ) Vᵀ → V diag(max(λ, λ_min))
    Vᵀ), shape (m, k, k). A matrix whose largest eigenvalue is not positive has no such neighbour: NaN rows."""
    mats = np.asarray(mats, dtype=float)
    S = 0.5 * (mats + np.swapaxes(mats, -1, -2))
    lam, V = np.linalg.eigh(S)
    top = lam[:, -1:]
    lam = np.maximum(lam, floor * top)
    out = (V * lam[:, None, :]) @ np.swapaxes(V, -1, -2)
    out = 0.5 * (out + np.swapaxes(out, -1, -2))
    out[top[:, 0] <= 0] = np.nan
    return out


def readonly(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous array that cannot be written (a copy only when ``a`` is not contiguous)."""
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def edge_indices(n_poses, tails, heads) -> tuple[int, np.ndarray, np.ndarray]:
    """(n, tails, heads): the number of poses as an int ≥ 1 and the edge endpoints as int64 arrays (m,);
    ``GraphError`` for no pose, arrays of other shapes or non-integer indices."""
    n = int(n_poses)
    if n < 1:
        raise GraphError(f"a pose graph needs at least one pose, got n_poses={n}")
    tails, heads = np.asarray(tails), np.asarray(heads)
    if tails.ndim != 1 or heads.shape != tails.shape:
        raise GraphError(f"tails and heads must be 1-D of equal length, got {tails.shape} and {heads.shape}")
    if tails.shape[0] and not (np.issubdtype(tails.dtype, np.integer) and np.issubdtype(heads.dtype, np.integer)):
        raise GraphError("tails and heads must be integer pose indices")
    return n, tails.astype(np.int64), heads.astype(np.int64)


def check_endpoints(n: int, tails: np.ndarray, heads: np.ndarray) -> None:
    """``GraphError`` unless every endpoint (m,) lies in 0 … n−1 and no edge joins a pose to itself."""
    if tails.shape[0]:
        if tails.min() < 0 or heads.min() < 0 or tails.max() >= n or heads.max() >= n:
            raise GraphError(f"edge endpoints must lie in 0..{n - 1}")
        loops = np.flatnonzero(tails == heads)
        if loops.size:
            raise GraphError(f"self-loop edge(s) at index {loops[:5].tolist()}: an edge must join two "
                             "different poses")


def pose_ids(n: int, ids) -> np.ndarray:
    """The file identifiers as int64 (n,), ``arange(n)`` for None; ``GraphError`` for another shape or a repeat."""
    ids = np.arange(n, dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64)
    if ids.shape != (n,):
        raise GraphError(f"ids must have shape ({n},), got {ids.shape}")
    if n > 1 and not (ids[1:] > ids[:-1]).all():  # sorted and distinct: no sort needed
        s = np.sort(ids)
        if not (s[1:] > s[:-1]).all():
            raise GraphError("pose ids must be unique")
    return ids


@dataclass(frozen=True, eq=False, repr=False)
class PoseGraphBase:
    """The first fields of every pose graph: ``n_poses`` n and the edge endpoints ``tails``, ``heads`` (m,) pose
    indices. A graph (a frozen dataclass declared with ``repr=False``, so that this ``repr`` serves) adds the fields
    ``ids`` (n,) and ``name``, the property or field ``initial`` (None without an initial guess), and the class
    attribute ``MEASUREMENTS``: the names of its per-edge measurement arrays (information included) with the shape
    of one edge's, e.g. ``("delta_l", (2,))``."""

    n_poses: int
    tails: np.ndarray
    heads: np.ndarray

    MEASUREMENTS: ClassVar[tuple[tuple[str, tuple[int, ...]], ...]] = ()
    #: Per-edge arrays that may be None (e.g. the information as given, ``PoseGraph.given_information``).
    OPTIONAL_MEASUREMENTS: ClassVar[tuple[str, ...]] = ()

    def _checked_edges(self) -> tuple[int, np.ndarray, np.ndarray, list[np.ndarray]]:
        """For ``__post_init__``: (n, tails, heads, measurements) with ``n_poses`` stored as the int n, the
        endpoints as by ``edge_indices`` and ``check_endpoints``, and the measurement arrays as floats of shapes
        (m, *shape) in the order of ``MEASUREMENTS`` (not yet checked for finiteness)."""
        n, tails, heads = edge_indices(self.n_poses, self.tails, self.heads)
        object.__setattr__(self, "n_poses", n)
        m = tails.shape[0]
        arrays = [np.asarray(getattr(self, name), dtype=float).reshape((m, *shape))
                  for name, shape in self.MEASUREMENTS]
        check_endpoints(n, tails, heads)
        return n, tails, heads, arrays

    def _store_readonly(self, **arrays: np.ndarray) -> None:
        """For ``__post_init__``: each checked array stored in its field, made read-only (``readonly``)."""
        for name, value in arrays.items():
            object.__setattr__(self, name, readonly(value))

    @property
    def n_edges(self) -> int:
        """m, the number of edges (measurements)."""
        return int(self.tails.shape[0])

    @property
    def is_odometric(self) -> np.ndarray:
        """Boolean (m,): edge joins poses with consecutive ids (|id_i − id_j| = 1)."""
        return np.abs(self.ids[self.tails] - self.ids[self.heads]) == 1

    @property
    def n_odometric(self) -> int:
        return int(self.is_odometric.sum())

    @property
    def n_loop_closures(self) -> int:
        return self.n_edges - self.n_odometric

    def index_of(self, pose_id: int) -> int:
        """Index (0 … n−1) of the pose with file identifier ``pose_id``."""
        hit = np.flatnonzero(self.ids == int(pose_id))
        if hit.size == 0:
            raise GraphError(f"no pose with id {pose_id} (ids range {self.ids.min()}..{self.ids.max()})")
        return int(hit[0])

    def anchor_index(self, anchor=None) -> int:
        """Index of the anchor pose. Everywhere in lago_cvx an anchor is given as a pose **id** (as in
        the file); ``None`` means the smallest id. Raises ``GraphError`` for an id the graph lacks."""
        if anchor is None:
            return int(np.argmin(self.ids))
        return self.index_of(anchor)

    def subgraph_edges(self, mask):
        """A copy keeping only the edges selected by ``mask`` (bool (m,) or indices; poses unchanged)."""
        sel = np.zeros(self.n_edges, bool)
        sel[mask] = True
        edge_fields = ("tails", "heads") + tuple(name for name, _ in self.MEASUREMENTS)
        optional = {name: getattr(self, name)[sel] for name in self.OPTIONAL_MEASUREMENTS
                    if getattr(self, name) is not None}
        return replace(self, **{name: getattr(self, name)[sel] for name in edge_fields}, **optional)

    def __repr__(self) -> str:
        nm = f" {self.name!r}" if self.name else ""
        return (f"<{type(self).__name__}{nm}: {self.n_poses} poses, {self.n_edges} edges "
                f"({self.n_odometric} odometric, {self.n_loop_closures} loop closures)"
                f"{', with initial guess' if self.initial is not None else ''}>")


def as_graph(x, what: str = "graph"):
    """``x`` itself when it is a pose graph (a ``PoseGraph`` or ``PoseGraph3D``), a generated world's ``graph``
    (``SyntheticWorld``, ``SyntheticWorld3D``: anything with ``graph`` and ``truth``); a one-line ``GraphError``
    naming ``what`` and the type given otherwise."""
    if isinstance(x, PoseGraphBase):
        return x
    g = getattr(x, "graph", None)
    if isinstance(g, PoseGraphBase) and hasattr(x, "truth"):
        return g
    raise GraphError(f"{what}: expected a pose graph (PoseGraph or PoseGraph3D: read_graph, a world's .graph), "
                     f"got {type(x).__name__}")
