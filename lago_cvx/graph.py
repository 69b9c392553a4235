"""Graph machinery of the seed's Section III and IV-E: incidence matrices, connectivity, spanning
trees, chords and the fundamental cycle basis.

Notation (seed ↔ code). The seed numbers poses 0 … n (n+1 poses, pose 0 the anchor); here a graph has
``n_poses`` poses indexed 0 … n_poses−1 and any of them may be the anchor.

* A  — incidence matrix, shape (n_poses, m): column k has −1 at the tail and +1 at the head of edge k
  (eq. (6)), so ``Aᵀθ`` is the vector of orientation differences θ_j − θ_i.
* A2 — reduced incidence matrix, A with the anchor's row deleted, shape (n_poses−1, m) (eq. (7)).
  Proposition 1: rank A = rank A2 = n_poses−1 iff the graph is connected.
* spanning tree — n_poses−1 edges; the remaining l = m − n_poses + 1 edges are the *chords*
  (Corollary 1: l is the cyclomatic number; the seed writes l = m − n with its n = n_poses − 1).
* C = [I_l B] — fundamental cycle basis matrix (Corollary 2), shape (l, m): row c is the cycle made of
  chord c and the tree path between its endpoints, with signs such that C·δ = 0 for exact,
  unwrapped relative orientations. Here its columns follow the graph's own edge order;
  ``SpanningTree.edge_order`` gives the permutation [chords, tree edges] in which it reads [I B].

Everything is vectorized (NumPy, ``scipy.sparse``; ``scipy.sparse.csgraph`` only for the minimum spanning
tree, imported when asked for: it loads ``scipy.sparse.linalg``, which the other routes never need); no
Python loop over edges.
Quantities along the tree (orientation potentials, depths) are integrated by pointer jumping:
O(n log depth) vectorized work, so a 100 000-pose chain takes milliseconds.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from .stacks import unique_sorted
from .errors import GraphError, OptionError
from .posegraph import PoseGraph, rot2

__all__ = [
    "incidence_matrix", "reduced_incidence", "free_poses", "connected_components", "check_connected",
    "SpanningTree", "spanning_tree", "SPANNING_TREES", "minimum_spanning_edges", "cycle_basis", "cyclomatic_number",
    "subgraph", "LeafPruning", "prune_leaves", "accumulate_to_root",
]

log = logging.getLogger(__name__)

#: Names accepted by ``spanning_tree(kind=...)``.
SPANNING_TREES = ("bfs", "odometry", "mst")


# --------------------------------------------------------------------------- incidence
def incidence_matrix(graph: PoseGraph) -> sp.csr_matrix:
    """Incidence matrix A of eq. (6), shape (n_poses, m), CSR: A[tail_k, k] = −1, A[head_k, k] = +1."""
    m = graph.n_edges
    rows = np.concatenate([graph.tails, graph.heads])
    cols = np.concatenate([np.arange(m), np.arange(m)])
    vals = np.concatenate([-np.ones(m), np.ones(m)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(graph.n_poses, m))


def reduced_incidence(graph: PoseGraph, anchor=None) -> sp.csr_matrix:
    """Reduced incidence matrix A2 of eq. (7): A without the anchor's row, shape (n_poses−1, m).

    ``anchor`` is a pose id (default the smallest). Row r of A2 belongs to pose
    ``free_poses(n_poses, graph.anchor_index(anchor))[r]``."""
    return _reduced_incidence(graph, graph.anchor_index(anchor))


def _reduced_incidence(graph: PoseGraph, a: int) -> sp.csr_matrix:
    """A2 with the row of the pose of *index* ``a`` deleted."""
    return incidence_matrix(graph)[free_poses(graph.n_poses, a)]


def free_poses(n_poses: int, anchor_index: int) -> np.ndarray:
    """Indices of the non-anchor poses, in increasing order — the row order of A2, shape (n_poses−1,).
    ``anchor_index`` is an index (0 … n_poses−1), not an id."""
    if not 0 <= anchor_index < n_poses:
        raise GraphError(f"anchor index {anchor_index} is outside 0..{n_poses - 1}")
    return np.delete(np.arange(n_poses), anchor_index)


# ------------------------------------------------------------------------- connectivity
def _neighbours(n: int, tails: np.ndarray, heads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undirected adjacency as CSR ``(indptr (n+1,), indices)``: for each pose, its out-neighbours
    (ascending, without repeats), then its in-neighbours (ascending) — the order in which
    ``scipy.sparse.csgraph``'s undirected traversals visit them, so trees come out identical."""
    t = np.asarray(tails, np.int64)
    h = np.asarray(heads, np.int64)
    # one sorted key per (pose, out/in, neighbour): pose·2n + part·n + neighbour, repeats dropped
    key = unique_sorted(np.concatenate([t * (2 * n) + h, h * (2 * n) + (n + t)]))
    src, rest = np.divmod(key, 2 * n)
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=indptr[1:])
    return indptr, rest % n


def _bfs_parents(n: int, tails: np.ndarray, heads: np.ndarray, root: int) -> np.ndarray:
    """Breadth-first tree of the undirected graph from ``root``: parent index of every pose (−1 at the
    root and where unreachable), shape (n,). Level by level; a pose's parent is the first pose of the
    previous level (in queue order) that reaches it — the tree of
    ``csgraph.breadth_first_order(..., directed=False)``. A wide level is one vectorized step; a narrow
    one (a corridor: long chains make thousands of levels of a few poses) is a plain Python loop over
    the same adjacency, which costs far less than a dozen NumPy calls per level."""
    indptr, nbr = _neighbours(n, tails, heads)
    parent = np.full(n, -1, np.int64)
    seen_bytes = bytearray(n)
    seen = np.frombuffer(seen_bytes, np.bool_)  # one buffer, read and written by both kinds of step
    seen_bytes[root] = 1
    frontier = np.array([root], np.int64)
    lists = None
    while frontier.size:
        if frontier.size <= _NARROW_LEVEL:  # a run of narrow levels, all in Python; NumPy once at its end
            if lists is None:
                lists = indptr.tolist(), nbr.tolist()
            ip, nb = lists
            level = frontier.tolist()
            found, found_par = [], []
            while level and len(level) <= _NARROW_LEVEL:
                new = []
                for u in level:
                    for v in nb[ip[u]:ip[u + 1]]:
                        if not seen_bytes[v]:
                            seen_bytes[v] = 1
                            new.append(v)
                            found_par.append(u)
                found += new
                level = new
            parent[np.array(found, np.int64)] = found_par
            frontier = np.array(level, np.int64)
            continue
        starts = indptr[frontier]
        lens = indptr[frontier + 1] - starts
        total = int(lens.sum())
        if total == 0:
            break
        ends = np.cumsum(lens)
        idx = np.repeat(starts - ends + lens, lens) + np.arange(total)
        cand = nbr[idx]
        fresh = ~seen[cand]
        cand, par = cand[fresh], np.repeat(frontier, lens)[fresh]
        if cand.size == 0:
            break
        _, first = np.unique(cand, return_index=True)
        first.sort()  # discovery order
        frontier = cand[first]
        parent[frontier] = par[first]
        seen[frontier] = True
    return parent


#: Levels of at most this many poses are walked in Python: city10000's BFS has thousands of levels of a few poses
#: each, where NumPy's cost per call dominates (the tree step of ``benchmarks/perf.md``).
_NARROW_LEVEL = 64


def _component_roots(n: int, tails: np.ndarray, heads: np.ndarray) -> np.ndarray:
    """For every pose, the smallest index of its connected component (n,): hooking of roots onto smaller
    roots along the edges and pointer jumping, O((n + m) log n)."""
    root = np.arange(n, dtype=np.int64)
    t = np.asarray(tails, np.int64)
    h = np.asarray(heads, np.int64)
    while True:
        rt, rh = root[t], root[h]
        lo, hi = np.minimum(rt, rh), np.maximum(rt, rh)
        differ = lo != hi
        if not differ.any():
            return root
        np.minimum.at(root, hi[differ], lo[differ])
        while True:  # pointer jumping until every pose points at its root
            jumped = root[root]
            if np.array_equal(jumped, root):
                break
            root = jumped


def connected_components(graph: PoseGraph) -> tuple[int, np.ndarray]:
    """Number of connected components and the component label of each pose, shape (n_poses,). Labels
    are numbered in the order of each component's smallest pose index (as ``csgraph`` numbers them)."""
    roots, labels = np.unique(_component_roots(graph.n_poses, graph.tails, graph.heads), return_inverse=True)
    return int(roots.size), labels.astype(np.int32)


def check_connected(graph: PoseGraph) -> None:
    """Raise ``GraphError`` naming the components' sizes if the graph is not connected.

    LAGO needs a connected graph (Proposition 1: A2 has full row rank only then)."""
    k, labels = connected_components(graph)
    if k > 1:
        sizes = np.bincount(labels)
        order = np.argsort(-sizes, kind="stable")
        desc = ", ".join(
            f"{sizes[c]} pose{'s' if sizes[c] != 1 else ''} (e.g. id {graph.ids[np.flatnonzero(labels == c)[0]]})"
            for c in order[:6])
        more = f", and {k - 6} more" if k > 6 else ""
        raise GraphError(f"the pose graph is not connected: {k} components of sizes {desc}{more}; "
                         "LAGO needs a connected graph")


def cyclomatic_number(graph: PoseGraph) -> int:
    """l = m − n_poses + (number of components) (Corollary 1; l = m − n for a connected graph)."""
    k, _ = connected_components(graph)
    return graph.n_edges - graph.n_poses + k


# ------------------------------------------------------------------------- spanning tree
@dataclass(frozen=True, eq=False)
class SpanningTree:
    """A spanning tree rooted at the anchor.

    ``tree_edges`` (n_poses−1,) edge indices; ``chords`` (l,) the other edge indices (increasing);
    ``parent`` (n_poses,) parent pose (−1 at the root); ``parent_edge`` (n_poses,) the tree edge to the
    parent (−1 at the root); ``forward`` (n_poses,) bool, True when that edge points parent → child
    (tail = parent); ``depth`` (n_poses,) number of tree edges to the root; ``kind`` the rule used."""

    root: int
    tree_edges: np.ndarray
    chords: np.ndarray
    parent: np.ndarray
    parent_edge: np.ndarray
    forward: np.ndarray
    depth: np.ndarray
    kind: str

    @property
    def n_chords(self) -> int:
        return int(self.chords.size)

    @property
    def edge_order(self) -> np.ndarray:
        """Edge permutation [chords, tree edges] in which C reads [I_l B] (Corollary 2)."""
        return np.concatenate([self.chords, self.tree_edges])

    def integrate(self, graph: PoseGraph, values=None) -> np.ndarray:
        """Integrate per-edge orientation measurements along the tree from the root (θ_root = 0).

        Returns θ_tree (n_poses,) with θ_tree[child] = θ_tree[parent] ± δ[parent_edge] (+ when the edge
        points parent → child). ``values`` defaults to ``graph.delta`` (shape (m,))."""
        d = graph.delta if values is None else np.asarray(values, dtype=float)
        step = np.zeros(graph.n_poses)
        nonroot = self.parent >= 0
        e = self.parent_edge[nonroot]
        step[nonroot] = np.where(self.forward[nonroot], d[e], -d[e])
        return accumulate_to_root(self.parent, step)

    def path_sums(self, graph: PoseGraph, values=None) -> np.ndarray:
        """For every edge k: (integral to head − integral to tail) along the tree, shape (m,).

        Equals ``values[k]`` on tree edges; on chords it is the tree path's orientation change, so
        ``values − path_sums`` is C·values spread over the chords (the cycle-basis residuals)."""
        pot = self.integrate(graph, values)
        return pot[graph.heads] - pot[graph.tails]


def accumulate_to_root(parent: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Sum of ``step`` over the path from every node up to (excluding) the root, by pointer jumping.

    ``parent`` (n,) with −1 at the root. After t rounds, acc[v] holds the sum over the 2ᵗ nearest
    ancestors' steps, so ⌈log₂ depth⌉ vectorized rounds suffice."""
    n = parent.size
    root_mask = parent < 0
    anc = np.where(root_mask, np.arange(n), parent)
    acc = np.where(root_mask, 0.0, step).astype(float)
    done = root_mask | root_mask[anc]
    while not done.all():
        acc = acc + np.where(done, 0.0, acc[anc])
        anc = anc[anc]
        done = root_mask[anc]
    # Nodes whose pointer reached the root: acc holds the full path sum (root's step is 0).
    return acc


def _depth(parent: np.ndarray) -> np.ndarray:
    return accumulate_to_root(parent, np.where(parent < 0, 0.0, 1.0)).astype(np.int64)


def _pair_keys(graph: PoseGraph, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return lo.astype(np.int64) * graph.n_poses + hi


def _best_edge_per_pair(graph: PoseGraph, candidates: np.ndarray, weight: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Among parallel edges, keep for every unordered pose pair the one of smallest ``weight`` (m,)
    (default: the marginal variance of δ, i.e. the most informative about the orientation; ties to the
    lowest index). Returns (sorted keys, edge index)."""
    w = graph.delta_variance(candidates) if weight is None else np.asarray(weight, dtype=float)[candidates]
    keys = _pair_keys(graph, graph.tails[candidates], graph.heads[candidates])
    order = np.lexsort((candidates, w, keys))
    keys_sorted = keys[order]
    first = np.ones(order.size, bool)
    first[1:] = keys_sorted[1:] != keys_sorted[:-1]
    return keys_sorted[first], candidates[order[first]]


def minimum_spanning_edges(graph: PoseGraph, weight: np.ndarray | None = None) -> np.ndarray:
    """Edge indices (n_poses−1,) of a minimum spanning tree for the edge ``weight`` (m,) (default: the
    marginal variance of δ); among parallel edges the lightest. Vectorized (``scipy.sparse.csgraph``)."""
    n = graph.n_poses
    keys, best = _best_edge_per_pair(graph, np.arange(graph.n_edges), weight)
    w = graph.delta_variance(best) if weight is None else np.asarray(weight, dtype=float)[best]
    # csgraph treats explicit zeros as missing edges: a monotone map to [1, 2] keeps the tree and the zeros
    top = float(w.max()) if w.size else 0.0
    w = (w / top if top > 0 else np.zeros_like(w)) + 1.0
    W = sp.csr_matrix((w, (graph.tails[best], graph.heads[best])), shape=(n, n))
    from scipy.sparse import csgraph  # loads scipy.sparse.linalg: only when an MST is asked for

    T = csgraph.minimum_spanning_tree(W + W.T).tocoo()
    return best[np.searchsorted(keys, _pair_keys(graph, T.row, T.col))]


def _tree_from_parent(graph: PoseGraph, root: int, parent: np.ndarray, kind: str) -> SpanningTree:
    """Build the SpanningTree from a parent array (−1 at the root; −9999 = unreachable not allowed)."""
    n = graph.n_poses
    child = np.flatnonzero(parent >= 0)
    keys_all, best = _best_edge_per_pair(graph, np.arange(graph.n_edges))
    want = _pair_keys(graph, parent[child], child)
    pos = np.searchsorted(keys_all, want)
    pe = np.full(n, -1, np.int64)
    pe[child] = best[pos]
    forward = np.zeros(n, bool)
    forward[child] = graph.tails[pe[child]] == parent[child]
    tree_edges = np.sort(pe[child])
    chords = np.setdiff1d(np.arange(graph.n_edges), tree_edges, assume_unique=True)
    return SpanningTree(root=root, tree_edges=tree_edges, chords=chords, parent=parent.astype(np.int64),
                        parent_edge=pe, forward=forward, depth=_depth(parent), kind=kind)


def _parent_from_edges(graph: PoseGraph, root: int, edges: np.ndarray) -> np.ndarray:
    """Parent array of the tree formed by ``edges`` (must be a spanning tree), rooted at ``root``. In a
    tree every pose has one path to the root, so any traversal gives the same parents: a large tree
    (a long odometric chain is a million levels of one pose) is rooted by ``csgraph``'s traversal in C,
    a small one by ``_bfs_parents`` (no csgraph import)."""
    return _bfs(graph.n_poses, graph.tails[edges], graph.heads[edges], root)


def _bfs(n: int, tails: np.ndarray, heads: np.ndarray, root: int) -> np.ndarray:
    """``_bfs_parents``'s tree (the same parents): from ``_CSGRAPH_TREE`` poses by ``csgraph``'s traversal
    in C, below by ``_bfs_parents`` (no csgraph import)."""
    if n < _CSGRAPH_TREE:
        return _bfs_parents(n, tails, heads, root)
    from scipy.sparse import csgraph

    T = sp.csr_matrix((np.ones(tails.size), (tails, heads)), shape=(n, n))
    _, pred = csgraph.breadth_first_order(T, root, directed=False, return_predecessors=True)
    return np.where(pred < 0, -1, pred).astype(np.int64)


#: Trees of at least this many poses are rooted by ``scipy.sparse.csgraph`` (the same parents; level by level costs a
#: Python step per level, ruinous on a long odometric chain: ``benchmarks/million.md``).
_CSGRAPH_TREE = 50_000


def _broken_chain(graph: PoseGraph, odo: np.ndarray) -> str:
    """Why the odometric chain (edges between consecutive ids, Proposition 2) is not a spanning tree:
    the first gap in the sorted ids, or the first pair of consecutive ids without an edge."""
    ids = np.sort(graph.ids)
    linked = {(int(a), int(b)) for a, b in zip(*np.sort(np.stack([graph.ids[graph.tails[odo]],
                                                                  graph.ids[graph.heads[odo]]]), axis=0))}
    gaps = np.flatnonzero(np.diff(ids) != 1)
    absent = [k for k in range(ids.size - 1) if (int(ids[k]), int(ids[k]) + 1) not in linked]
    n_missing = len(absent)
    if gaps.size and (not absent or gaps[0] <= absent[0]):
        k = int(gaps[0])
        where = (f"the ids are not consecutive (they jump from {ids[k]} to {ids[k + 1]}: no pose has id "
                 f"{ids[k] + 1})")
    else:
        k = absent[0]
        where = f"no edge between poses {ids[k]} and {ids[k] + 1}"
    return (f"the odometric chain is broken: {where}; {n_missing} of {ids.size - 1} consecutive links missing. "
            'Use another spanning tree: spanning_tree="bfs" or "mst"')


def spanning_tree(graph: PoseGraph, kind="bfs", *, anchor=None) -> SpanningTree:
    """Spanning tree of a connected graph, rooted at the anchor (a pose id, default the smallest;
    ``SpanningTree.root`` is its index).

    ``kind``:
      * ``"bfs"`` (default) — shortest-depth tree: breadth-first from the anchor, so every pose is
        reached through as few measurements as possible. Errors accumulated along tree paths, which
        decide the 2kπ regularization, stay small; on M3500a and MIT this is what makes LAGO land in the
        global basin (the odometric tree does not — see the benchmarks).
      * ``"odometry"`` — the chain of edges between consecutive ids (the seed's choice, Section V).
        Raises ``GraphError`` naming the first missing link if the chain is broken.
      * ``"mst"`` — minimum spanning tree with weight = marginal variance of δ, i.e. the most
        informative orientation measurements.
      * an array of edge indices (or a boolean mask over edges) — a user-given tree; checked.
    Among parallel edges the one with the smallest variance of δ is used.
    """
    anchor = graph.anchor_index(anchor)  # from here on an index
    n = graph.n_poses
    if isinstance(kind, str) and kind == "bfs" and n > 1:  # the traversal finds unreachable poses itself:
        parent = _bfs(n, graph.tails, graph.heads, anchor)  # the components are counted only to name them
        if np.count_nonzero(parent < 0) > 1:
            check_connected(graph)
        return _tree_from_parent(graph, anchor, parent, "bfs")
    check_connected(graph)
    if n == 1:
        return SpanningTree(anchor, np.zeros(0, np.int64), np.arange(graph.n_edges), np.array([-1]),
                            np.array([-1]), np.zeros(1, bool), np.zeros(1, np.int64), str(kind))
    if isinstance(kind, str):
        if kind == "odometry":
            odo = np.flatnonzero(graph.is_odometric)
            keys, best = _best_edge_per_pair(graph, odo)
            if keys.size != n - 1:
                raise GraphError(_broken_chain(graph, odo))
            return _tree_from_parent(graph, anchor, _parent_from_edges(graph, anchor, best), "odometry")
        if kind == "mst":
            edges = minimum_spanning_edges(graph)
            return _tree_from_parent(graph, anchor, _parent_from_edges(graph, anchor, edges), "mst")
        raise OptionError(f"unknown spanning tree {kind!r}; expected one of {SPANNING_TREES} or edge indices")
    edges = np.asarray(kind)
    if edges.dtype == bool:
        if edges.shape != (graph.n_edges,):
            raise OptionError(f"a boolean tree mask must have shape ({graph.n_edges},)")
        edges = np.flatnonzero(edges)
    edges = unique_sorted(edges.astype(np.int64))
    if edges.size != n - 1 or edges.min() < 0 or edges.max() >= graph.n_edges:
        raise GraphError(f"a spanning tree of {n} poses has {n - 1} distinct edges in 0..{graph.n_edges - 1}; "
                         f"got {edges.size}")
    sub = graph.subgraph_edges(edges)
    k, _ = connected_components(sub)
    if k != 1:
        raise GraphError(f"the given edge set is not a spanning tree ({k} components: it contains a cycle)")
    parent = _parent_from_edges(graph, anchor, edges)
    # Use exactly the given edges (not the best parallel one).
    child = np.flatnonzero(parent >= 0)
    pe = np.full(n, -1, np.int64)
    keys = _pair_keys(graph, graph.tails[edges], graph.heads[edges])
    order = np.argsort(keys)
    pe[child] = edges[order][np.searchsorted(keys[order], _pair_keys(graph, parent[child], child))]
    forward = np.zeros(n, bool)
    forward[child] = graph.tails[pe[child]] == parent[child]
    chords = np.setdiff1d(np.arange(graph.n_edges), edges, assume_unique=True)
    return SpanningTree(anchor, edges, chords, parent, pe, forward, _depth(parent), "given")


# --------------------------------------------------------------------------- cycle basis
def cycle_basis(graph: PoseGraph, tree: SpanningTree) -> sp.csr_matrix:
    """Fundamental cycle basis matrix C (Corollary 2), shape (l, m), columns in graph edge order.

    Row c (chord k = tree.chords[c]) is +1 at k and, on the tree edges of the path between the chord's
    endpoints, −1 (+1) where the edge points along (against) the direction tail_k → head_k, so that
    C·δ = δ_k − (θ_head − θ_tail)_tree = 0 for exact unwrapped orientations. In the edge order
    ``tree.edge_order`` it reads C = [I_l B].

    Built as Bᵀ = −(A2_T)⁻¹ A2_C with A2_T the reduced incidence of the tree edges (square,
    invertible, Proposition 1) — a sparse triangular-like solve. nnz(C) is the total length of the
    fundamental cycles, which can be large (≈ l × n for an odometric tree on a long trajectory); LAGO
    itself never forms C (regularization uses ``SpanningTree.path_sums``), this is for inspection
    and checks."""
    A2 = _reduced_incidence(graph, tree.root).tocsc()
    A2_T = A2[:, tree.tree_edges]
    A2_C = A2[:, tree.chords]
    if tree.n_chords == 0:
        return sp.csr_matrix((0, graph.n_edges))
    lu = sp.linalg.splu(A2_T.tocsc())
    Bt = lu.solve(A2_C.toarray()) if A2_C.shape[1] * A2_T.shape[0] <= 4e7 else None
    if Bt is None:  # large: column blocks, kept sparse
        blocks = []
        dense_c = A2_C.tocsc()
        for s in range(0, tree.n_chords, 256):
            blk = lu.solve(dense_c[:, s:s + 256].toarray())
            blk[np.abs(blk) < 0.5] = 0.0
            blocks.append(sp.csc_matrix(np.rint(blk)))
        Bt = sp.hstack(blocks).tocsc()
    else:
        Bt = sp.csc_matrix(np.rint(Bt))
    B = -Bt.T  # (l, n−1), columns = tree edges in tree.tree_edges order
    l, m = tree.n_chords, graph.n_edges
    B = B.tocoo()
    rows = np.concatenate([np.arange(l), B.row])
    cols = np.concatenate([tree.chords, tree.tree_edges[B.col]])
    vals = np.concatenate([np.ones(l), B.data])
    C = sp.csr_matrix((vals, (rows, cols)), shape=(l, m))
    C.eliminate_zeros()
    return C


# --------------------------------------------------------------------------- subgraphs
def subgraph(graph: PoseGraph, n_first: int) -> PoseGraph:
    """The subgraph induced by the first ``n_first`` poses (indices 0 … n_first−1): those poses and the
    edges between them; ids and initial guess are cut to match. The result may be disconnected if the
    file's odometry chain is broken."""
    n_first = int(n_first)
    if not 1 <= n_first <= graph.n_poses:
        raise OptionError(f"n_first must lie in 1..{graph.n_poses}, got {n_first}")
    inner = (graph.tails < n_first) & (graph.heads < n_first)
    g = graph.subgraph_edges(inner)
    initial = None if graph.initial is None else graph.initial[:n_first]
    name = f"{graph.name}[:{n_first}]" if graph.name else f"[:{n_first}]"
    return replace(g, n_poses=n_first, ids=graph.ids[:n_first], initial=initial, name=name)


@dataclass(eq=False)
class LeafPruning:
    """The 2-core of a pose graph (``prune_leaves``): ``core`` the core graph, ``index`` (n_core,) the
    original indices of its poses, ``rounds`` the peeled (leaf, edge, leaf_is_head) arrays, outermost
    last; ``extend(core_poses)`` rebuilds all n poses with zero residual on every peeled edge."""

    graph: PoseGraph
    core: PoseGraph
    index: np.ndarray
    rounds: list

    @property
    def n_removed(self) -> int:
        return self.graph.n_poses - self.core.n_poses

    def extend(self, core_poses) -> np.ndarray:
        """Poses (n, 3) of the whole graph from ``core_poses`` (n_core, 3): each peeled leaf ℓ is put
        where its one edge says — head ℓ of i → ℓ: θ_ℓ = θ_i + δ, t_ℓ = t_i + R_i t̃; tail ℓ of ℓ → i:
        θ_ℓ = θ_i − δ, t_ℓ = t_i − R_ℓ t̃ — processing the rounds innermost first (vectorized per round)."""
        g = self.graph
        out = np.zeros((g.n_poses, 3))
        out[self.index] = np.asarray(core_poses, dtype=float)
        for leaf, edge, is_head in reversed(self.rounds):
            other = np.where(is_head, g.tails[edge], g.heads[edge])
            theta = out[other, 2] + np.where(is_head, g.delta[edge], -g.delta[edge])
            Rt = np.einsum("kab,kb->ka", rot2(np.where(is_head, out[other, 2], theta)), g.delta_l[edge])
            out[leaf, 2] = theta
            out[leaf, :2] = out[other, :2] + np.where(is_head[:, None], Rt, -Rt)
        return out


def prune_leaves(graph: PoseGraph, *, anchor=None) -> LeafPruning:
    """Remove degree-1 poses (one edge) repeatedly, never the anchor (id, default the smallest), down to
    the 2-core. One vectorized pass per peeling round. Used by the SDP relaxation, where it is exact
    (``lago_cvx.certification.sdp``): a leaf can always be placed with zero residual on its one edge."""
    a = graph.anchor_index(anchor)
    n, m = graph.n_poses, graph.n_edges
    alive_pose = np.ones(n, bool)
    alive_edge = np.ones(m, bool)
    rounds = []
    while True:
        t, h = graph.tails[alive_edge], graph.heads[alive_edge]
        deg = np.bincount(t, minlength=n) + np.bincount(h, minlength=n)
        is_leaf = (deg == 1) & alive_pose
        is_leaf[a] = False
        if not is_leaf.any():
            break
        edges = np.flatnonzero(alive_edge)
        head_leaf = is_leaf[graph.heads[edges]]
        tail_leaf = is_leaf[graph.tails[edges]] & ~head_leaf  # an edge with two leaves: peel its head only
        sel = head_leaf | tail_leaf
        edge = edges[sel]
        is_head = head_leaf[sel]
        leaf = np.where(is_head, graph.heads[edge], graph.tails[edge])
        alive_pose[leaf] = False
        alive_edge[edge] = False
        rounds.append((leaf, edge, is_head))
    index = np.flatnonzero(alive_pose)
    if index.size == n:
        return LeafPruning(graph=graph, core=graph, index=index, rounds=[])
    relabel = np.full(n, -1, dtype=np.int64)
    relabel[index] = np.arange(index.size)
    g = graph.subgraph_edges(alive_edge)
    core = replace(g, n_poses=index.size, tails=relabel[g.tails], heads=relabel[g.heads], ids=graph.ids[index],
                   initial=None if graph.initial is None else graph.initial[index],
                   name=f"{graph.name} (2-core)")
    return LeafPruning(graph=graph, core=core, index=index, rounds=rounds)
