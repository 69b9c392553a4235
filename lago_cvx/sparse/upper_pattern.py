r"""The upper triangle of a closed-form system's normal matrix (N), as the CSC pattern QDLDL factors in the
pose-level elimination order (``lago_cvx.sparse.ldl``), and the map that scatters each system's blocks into it.

Every system of LAGO's closed forms has the anchor-reduced pose graph's pattern with b×b blocks
(``lago_cvx.sparse.normal_equations``). What does not depend on b — the off-diagonal pose entries of the upper
triangle in elimination order, the pose-level CSC and its elimination tree and column counts — is
computed once per graph (``PoseUpperPattern``); each b expands it (``BlockUpperPattern``): the scalar
CSC, the scatter map of ``EdgeSystem.normal_entries`` into its values (one ``np.bincount`` per system),
and the symbolic analysis expanded from the pose level (``ldl.LDLPattern.expanded``). On it,
``QdldlFactor`` factors a system by QDLDL and ``PoseLaplacian`` the weighted pose Laplacian (phase 1's
Ω_θ).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .linalg import Factor

__all__ = ["PoseUpperPattern", "BlockUpperPattern", "PoseLaplacian", "QdldlFactor", "matrix_blocks"]


def _whole_from_upper(U: sp.spmatrix) -> sp.csc_matrix:
    """The symmetric matrix whose upper triangle (diagonal included) is ``U``: U + Uᵀ − diag(U)."""
    return sp.csc_matrix(U + U.T - sp.diags(U.diagonal()))


def matrix_blocks(N: sp.spmatrix, var_index: np.ndarray):
    """The b×b blocks of a sparse symmetric N (system numbering ``var_index`` (d, b)) at every pose pair
    with an entry, each unordered pair once: ``(prow, pcol, blocks (q, b, b))`` with prow ≥ pcol. For
    tests and for matrices not assembled from edges."""
    var_index = np.asarray(var_index, np.int64)
    d, b = var_index.shape
    pose = np.empty(d * b, np.int64)
    comp = np.empty(d * b, np.int64)
    pose[var_index.reshape(-1)] = np.repeat(np.arange(d), b)
    comp[var_index.reshape(-1)] = np.tile(np.arange(b), d)
    C = sp.coo_matrix(N)
    pi, pj = pose[C.row], pose[C.col]
    lower = pi >= pj
    pi, pj, ci, cj, v = pi[lower], pj[lower], comp[C.row][lower], comp[C.col][lower], C.data[lower]
    key = pi * d + pj
    uk, inv = np.unique(key, return_inverse=True)
    blocks = np.zeros((uk.size, b, b))
    np.add.at(blocks, (inv, ci, cj), v)
    same = (uk // d) == (uk % d)
    blocks[same] = np.tril(blocks[same]) + np.swapaxes(np.tril(blocks[same], -1), 1, 2)
    return uk // d, uk % d, blocks


class PoseUpperPattern:
    """The part of every ``BlockUpperPattern`` of one graph that does not depend on b, computed once: the
    off-diagonal pose entries of N's upper triangle in elimination order, and the pose-level upper CSC
    (d × d) with its ``ldl.LDLPattern`` (elimination tree and column counts, which each b expands).

    ``position`` (d,) each free pose's place in the elimination order; ``pairs`` (prow, pcol, keep) as
    ``GraphElimination.pairs``. The off-diagonal entries (I < J in elimination order), each once, sorted
    by column J then row I: ``uJ``, ``uI`` (U,), ``rank`` (U,) each one's place in its pose column,
    ``offc`` (d,) the count per pose column; ``which`` (m,) the entry of each edge's off-diagonal block,
    + U where it is stored transposed (the head eliminated later), 2U for an edge at the anchor."""

    def __init__(self, position: np.ndarray, pairs):
        from .ldl import LDLPattern

        prow, pcol, _ = pairs
        self.position = position
        self.d = d = int(position.size)
        self.m = m = prow.size // 3  # pairs: tail diagonals, head diagonals, (head, tail) off-diagonals
        self.tails, self.heads = pcol[:m], pcol[m:2 * m]
        t, h = pcol[2 * m:], prow[2 * m:]
        both = np.flatnonzero((t >= 0) & (h >= 0))
        st, sh = position[t[both]], position[h[both]]
        swap = sh > st  # the head eliminated later: its block row becomes the column
        key = np.where(swap, sh * d + st, st * d + sh)  # J·d + I
        srt = np.argsort(key, kind="stable")
        ks = key[srt]
        new_entry = np.ones(ks.size, bool)
        new_entry[1:] = ks[1:] != ks[:-1]
        uk = ks[new_entry]
        inv = np.empty(key.size, np.int64)
        inv[srt] = np.cumsum(new_entry) - 1
        self.uJ, self.uI = uJ, uI = uk // d, uk % d
        self.U = U = uk.size
        self.offc = offc = np.bincount(uJ, minlength=d)
        self.rank = rank = np.arange(U) - np.searchsorted(uJ, uJ)
        self.which = np.full(m, 2 * U, np.int64)  # edges with an end at the anchor: discarded
        self.which[both] = inv + swap * U
        indptr = np.r_[0, np.cumsum(offc + 1)]
        indices = np.empty(indptr[-1], np.int64)
        indices[indptr[uJ] + rank] = uI
        indices[indptr[1:] - 1] = np.arange(d)
        self.ldl = LDLPattern(indptr, indices)


class BlockUpperPattern:
    """The upper triangle of (N)'s pattern with b×b blocks, in elimination order, as the CSC that
    ``ldl.LDLPattern`` factors, and the map that scatters ``EdgeSystem.normal_blocks()`` into its values.

    Built from the graph's ``PoseUpperPattern`` ``pose`` (variable (i, c) gets slot position[i]·b + c).
    Pose column J of the upper triangle holds the poses I ≤ J joined to it (increasing, J itself last);
    scalar column (J, c) holds, for each off-diagonal pose I, the rows I·b + 0 … b−1, then J·b + 0 … c.
    The block of pair (prow, pcol) lands as is when prow is eliminated first, transposed otherwise; of a
    diagonal block only the upper half (r ≤ c) is stored. ``values_from_entries`` sums every block's
    entries into place by one ``np.bincount`` over the map ``dest`` (3·b²·m,), entry-major as
    ``EdgeSystem.normal_entries`` (no COO → CSC conversion per system); ``ldl`` the symbolic analysis,
    the pose-level one expanded to b components (``ldl.LDLPattern.expanded``), shared by every system
    with this b."""

    def __init__(self, pose: PoseUpperPattern, b: int):
        from .ldl import LDLPattern

        position, d, m, U = pose.position, pose.d, pose.m, pose.U
        offc, uJ, rank = pose.offc, pose.uJ, pose.rank
        self.b = b
        pose_at = np.empty(d, np.int64)
        pose_at[position] = np.arange(d)
        comp = np.arange(b)
        self.slots = (position[:, None] * b + comp).reshape(-1)  # slot of pose-major variable i·b + c
        self.order = (pose_at[:, None] * b + comp).reshape(-1)  # pose-major variable in each slot
        base = np.r_[0, np.cumsum(b * b * offc + b * (b + 1) // 2)]
        colstart = base[:-1, None] + comp * (offc[:, None] * b) + comp * (comp + 1) // 2  # (d, b): column (J, c)
        self.indptr = np.r_[colstart.reshape(-1), base[-1]]
        self.nnz = nnz = int(base[-1])
        R, C = np.divmod(np.arange(b * b), b)  # block entry (R, C) at flat index R·b + C
        lower = R > C
        # destinations of a block's b² entries, entry-major (b², ·): at each pose column's diagonal (upper
        # half only; pose rows in elimination order, a last column for the anchor: discarded) ...
        dj = colstart[:, C].T + offc * b + R[:, None]  # (b², d) by elimination position
        dj[lower] = nnz
        diag = np.empty((b * b, d + 1), np.int64)  # column = free pose index, column d = the anchor
        np.take(dj, position, axis=1, out=diag[:, :d], mode="clip")
        diag[:, d] = nnz
        # ... and at each off-diagonal pose entry, as is and transposed (entry (r, c) → (c, r))
        off = np.take(colstart.T, uJ, axis=1)[C] + rank * b + R[:, None]  # (b², U)
        table = np.empty((b * b, 2 * U + 1), np.int64)
        table[:, :U] = off
        table[:, U:2 * U] = off[C * b + R]
        table[:, 2 * U] = nnz
        # kept entry-major, the layout of EdgeSystem.normal_entries: (3, b², m); np.take into out= (NumPy's
        # fancy-index gathers are slower), mode="clip" as every index is in range by construction
        dest = np.empty((3, b * b, m), np.int64)
        np.take(diag, np.where(pose.tails >= 0, pose.tails, d), axis=1, out=dest[0], mode="clip")
        np.take(diag, np.where(pose.heads >= 0, pose.heads, d), axis=1, out=dest[1], mode="clip")
        np.take(table, pose.which, axis=1, out=dest[2], mode="clip")
        self.dest = dest.reshape(-1)
        if b == 1:  # the pose-level pattern itself
            self.ldl = pose.ldl
            return
        # the pattern's rows, scattered to the same places
        indices = np.empty(nnz, np.int64)
        indices[off] = pose.uI * b + R[:, None]
        indices[dj[~lower]] = np.arange(d) * b + R[~lower][:, None]
        self.ldl = LDLPattern.expanded(pose.ldl, b, self.indptr, indices)

    @property
    def indices(self) -> np.ndarray:
        return self.ldl.indices

    def values_from_entries(self, entries: np.ndarray) -> np.ndarray:
        """The upper triangle's values (nnz,) from ``entries`` (3, b, b, m) of ``EdgeSystem.normal_entries``."""
        entries = np.ascontiguousarray(entries)
        return np.bincount(self.dest, weights=entries.reshape(-1), minlength=self.nnz + 1)[:self.nnz]

    def values(self, blocks: np.ndarray) -> np.ndarray:
        """The same from ``blocks`` (3m, b, b) of ``EdgeSystem.normal_blocks`` (reordered entry-major)."""
        b = self.b
        return self.values_from_entries(blocks.reshape(3, -1, b, b).transpose(0, 2, 3, 1))

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        """The whole symmetric matrix (pose-major numbering) with upper-triangle values ``data``."""
        n = self.slots.size
        N = _whole_from_upper(sp.csc_matrix((data, self.ldl.indices, self.indptr), shape=(n, n)))
        return sp.csc_matrix(N[self.slots][:, self.slots])


class PoseLaplacian:
    """Ω_θ = A2 diag(w) A2ᵀ (d × d: the weighted Laplacian of the anchor-reduced pose graph, phase 1's
    normal matrix when w = 1/P_δ) factored by QDLDL's routines (``lago_cvx.sparse.ldl``) on the graph's b = 1
    pattern ``pattern`` (a ``BlockUpperPattern``), in the AMD order ``perm`` (d,) it was built in (the
    pose eliminated at each position). It stands where ``qdldl.Solver`` stood: ``solve(rhs)`` for rhs
    (d,) or (d, r) in free-pose order; ``factors()`` → (L strictly lower, CSC, in elimination order; D;
    perm); ``matrix()`` the whole Laplacian (CSR, free-pose order). Raises ``NumericalError`` on a zero
    pivot, as ``qdldl.Solver`` does."""

    def __init__(self, pattern: BlockUpperPattern, weights: np.ndarray, perm: np.ndarray):
        w = np.asarray(weights, dtype=float)
        self._pattern, self.perm = pattern, perm
        self._data = pattern.values_from_entries(np.stack([w, w, -w]).reshape(3, 1, 1, -1))  # (N): A = −√w, B = √w
        self._ldl = pattern.ldl.factor(self._data)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        p = self._pattern
        return self._ldl.solve(rhs[p.order])[p.slots]

    def factors(self):
        f, n = self._ldl, self._pattern.ldl.n
        nnz = f.pattern.nnz_L
        return sp.csc_matrix((f.Lx[:nnz], f.Li[:nnz], f.Lp), shape=(n, n)), f.D, self.perm

    def matrix(self) -> sp.csr_matrix:
        return self._pattern.matrix(self._data).tocsr()


class QdldlFactor(Factor):
    """A system of (N) factored by QDLDL's LDLᵀ in C: below ``ENGINE_MIN`` unknowns faster than the
    multifrontal engine, whose Python cost per level of fronts does not pay there.

    With ``pattern`` (a ``BlockUpperPattern``, when ``ldl.available()``): the values scattered into the
    pattern's upper triangle and factored in the pose-level elimination order by QDLDL's C routines
    (``lago_cvx.sparse.ldl``), the symbolic analysis shared; ``progress(done, total)`` fed while QDLDL runs.
    Without: assembled as an upper-triangular CSC (pose-major variables i·b + c) and factored by
    ``qdldl.Solver``, which orders it by AMD first (no progress from inside)."""

    def __init__(self, system, pairs, keep, *, pattern: BlockUpperPattern | None = None, elimination=None,
                 progress=None):  # system: an EdgeSystem; elimination: its GraphElimination
        b = system.b
        n = system.d * b
        self._system, self._elimination = system, elimination
        if pattern is not None:
            data = pattern.values_from_entries(system.normal_entries())
            meanwhile = elimination.deferred_work() if elimination is not None else None
            ldl = pattern.ldl.factor(data, progress=progress, meanwhile=meanwhile)
            order, slots = pattern.order, pattern.slots
            self._flops = pattern.ldl.flops

            def solve(rhs: np.ndarray) -> np.ndarray:
                return ldl.solve(rhs[order])[slots]

            super().__init__(solve, n, "qdldl", lambda: pattern.matrix(data))
            return
        import qdldl

        prow, pcol = pairs
        blocks = system.normal_blocks()[keep]
        pr, pc = prow[keep], pcol[keep]
        cr, cc = np.divmod(np.arange(b * b), b)
        rows = (pr[:, None] * b + cr).reshape(-1)
        cols = (pc[:, None] * b + cc).reshape(-1)
        vals = blocks.reshape(-1)
        up = rows <= cols
        lo = ~up  # an entry below the diagonal is stored transposed (N is symmetric; only the upper half)
        dup = (pr == pc)[:, None].repeat(b * b, 1).reshape(-1) & lo  # diagonal blocks: lower half is a copy
        r_ = np.where(up, rows, cols)[~dup]
        c_ = np.where(up, cols, rows)[~dup]
        upper = sp.csc_matrix((vals[~dup], (r_, c_)), shape=(n, n))
        solver = qdldl.Solver(upper, upper=True)

        def solve(rhs: np.ndarray) -> np.ndarray:
            if rhs.ndim == 1:
                return solver.solve(rhs)
            return np.column_stack([solver.solve(np.ascontiguousarray(rhs[:, j])) for j in range(rhs.shape[1])])

        def whole() -> sp.csc_matrix:  # built only if someone asks for it
            return _whole_from_upper(upper)

        def flops() -> float:
            L = solver.factors()[0]
            from .ldl import column_work

            return float(column_work(np.diff(L.indptr)).sum())

        self._flops = flops
        super().__init__(solve, n, "qdldl", whole)

    def flops(self) -> float:
        """Σ colcount² over the columns of L (diagonal included): the factorization's multiply–adds."""
        return self._flops()

    def engine_factor(self):
        """A ``PoseFactor``: the same matrix factored by the multifrontal engine on the graph's shared
        pose-level plan (what the selected inversion of ``Phase3.pose_covariances`` needs), or None without
        the elimination."""
        if self._elimination is None:
            return None
        return self._elimination.factor(self._system, engine=True)
