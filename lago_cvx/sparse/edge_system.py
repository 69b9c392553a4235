r"""The least-squares problem (E) on the pose graph's pattern, edge by edge: the engine's input.

    minimise_x  Σ_k ‖A_k x_{t_k} + B_k x_{h_k} − c_k‖²,    A_k, B_k (q × b),  c_k (q,)            (E)

over the free poses x_i ∈ ℝ^b (t_k, h_k the free-pose indices of edge k's ends, −1 for the anchor, whose
term is dropped). ``EdgeSystem`` holds (E) as arrays; ``EdgeOperator`` applies M and Mᵀ of ‖M x − c‖²
edge by edge (no sparse matrix is built). ``lago_cvx.sparse.normal_equations`` factors its normal matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

__all__ = ["EdgeSystem", "EdgeOperator"]


@dataclass(frozen=True, eq=False)
class EdgeSystem:
    """The least-squares problem (E): ``tails``, ``heads`` (m,) free-pose indices (−1: the anchor),
    ``A``, ``B`` (m, q, b), ``c`` (m, q) — or (m, q, r) for r problems with the same matrix, solved
    together; ``d`` free poses."""

    tails: np.ndarray
    heads: np.ndarray
    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    d: int

    @property
    def b(self) -> int:
        return self.A.shape[2]

    def operator(self):
        """M and Mᵀ of this system with their set-up done once: by the C loops when they are built
        (``compiled.CompiledEdgeOperator``: the same sums in the same order), else an ``EdgeOperator``."""
        from . import compiled

        return compiled.CompiledEdgeOperator(self) if compiled.available() else EdgeOperator(self)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """M x (m, q[, r]) for x (d, b[, r]): A_k x_{t_k} + B_k x_{h_k} (anchor terms 0)."""
        return self.operator().matvec(x)

    def rmatvec(self, r: np.ndarray) -> np.ndarray:
        """Mᵀ r (d, b[, r]) for r (m, q[, r]) (scatter-add by ``np.bincount``)."""
        return self.operator().rmatvec(r)

    def normal_blocks(self) -> np.ndarray:
        """The blocks of (N) in ``GraphElimination.pairs`` order: [A_kᵀA_k (tail diagonal), B_kᵀB_k (head
        diagonal), B_kᵀA_k (head row, tail column)], (3m, b, b)."""
        At = np.ascontiguousarray(np.swapaxes(self.A, 1, 2))  # contiguous: NumPy's stacked matmul is 2× faster
        Bt = np.ascontiguousarray(np.swapaxes(self.B, 1, 2))
        return np.concatenate([At @ self.A, Bt @ self.B, Bt @ self.A])

    def sparse(self, var_index: np.ndarray | None = None) -> sp.csr_matrix:
        """M as a sparse (m·q) × (d·b) matrix, columns ``var_index`` (d, b) (default pose-major)."""
        m, q, b = self.A.shape
        var = (np.arange(self.d * b).reshape(self.d, b) if var_index is None
               else np.asarray(var_index, np.int64))
        rows = np.repeat(np.arange(m * q).reshape(m, q), b, axis=1).reshape(m, q * b)
        parts_r, parts_c, parts_v = [], [], []
        for ends, J in ((self.tails, self.A), (self.heads, self.B)):
            ok = ends >= 0
            parts_r.append(rows[ok].reshape(-1))
            parts_c.append(np.tile(var[ends[ok]], (1, q)).reshape(-1))
            parts_v.append(J[ok].reshape(-1))
        return sp.csr_matrix((np.concatenate(parts_v), (np.concatenate(parts_r), np.concatenate(parts_c))),
                             shape=(m * q, self.d * b))

    def cost(self, x: np.ndarray) -> float:
        """‖M x − c‖² at x (d, b[, r])."""
        r = self.matvec(x) - self.c
        return float(np.sum(r * r))


class EdgeOperator:
    """M x and Mᵀ r of an ``EdgeSystem`` (E), component-major: A, B kept as (q, b, m) and the ends with the
    anchor mapped to row d, so every product is b·q multiply–adds of length-m vectors (several times
    faster than ``np.einsum`` over (m, q, b)) and Mᵀ's scatter-add one ``np.bincount`` per component and
    right-hand side. Built once per solve (``GraphElimination.solve``, phase 1), not kept with the
    system."""

    def __init__(self, system: EdgeSystem):
        self.m, self.q, self.b = system.A.shape
        self.d = system.d
        self.At = np.ascontiguousarray(system.A.transpose(1, 2, 0))
        self.Bt = np.ascontiguousarray(system.B.transpose(1, 2, 0))
        self.t = np.where(system.tails < 0, self.d, system.tails)
        self.h = np.where(system.heads < 0, self.d, system.heads)
        self.ends = np.concatenate([self.t, self.h])  # (2m,): the tails, then the heads

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """M x (m, q[, r]) for x (d, b[, r])."""
        At, Bt, m, q, b = self.At, self.Bt, self.m, self.q, self.b
        extra = x.shape[2:]
        xe = np.zeros((b, *extra, self.d + 1))  # component-major, column d: the anchor's zero
        xe[..., :self.d] = np.moveaxis(x, 0, -1)
        xt, xh = np.take(xe, self.t, axis=-1), np.take(xe, self.h, axis=-1)  # (b, [r,] m)
        out = np.empty((q, *extra, m))
        for s_ in range(q):
            o = out[s_]
            np.multiply(At[s_, 0], xt[0], out=o)
            o += Bt[s_, 0] * xh[0]
            for c in range(1, b):
                o += At[s_, c] * xt[c]
                o += Bt[s_, c] * xh[c]
        return np.ascontiguousarray(np.moveaxis(out, -1, 0))

    def rmatvec(self, r: np.ndarray) -> np.ndarray:
        """Mᵀ r (d, b[, r]) for r (m, q[, r])."""
        At, Bt, m, q, b = self.At, self.Bt, self.m, self.q, self.b
        extra = r.shape[2:]
        k = int(np.prod(extra, dtype=np.int64))
        rt = np.moveaxis(r, 0, -1)  # (q, [r,] m)
        u = np.empty((b, *extra, 2 * m))  # per component: the tails' terms, then the heads'
        for c in range(b):
            ut, uh = u[c, ..., :m], u[c, ..., m:]
            np.multiply(At[0, c], rt[0], out=ut)
            np.multiply(Bt[0, c], rt[0], out=uh)
            for s_ in range(1, q):
                ut += At[s_, c] * rt[s_]
                uh += Bt[s_, c] * rt[s_]
        rows = u.reshape(b * k, 2 * m)
        out = np.empty((b * k, self.d))
        for i in range(b * k):  # one bincount per (component, right-hand side) over the shared ends
            out[i] = np.bincount(self.ends, rows[i], minlength=self.d + 1)[:self.d]
        return np.ascontiguousarray(np.moveaxis(out.reshape(b, *extra, self.d), -1, 0))
