r"""The compiled kernels of ``lago_cvx.sparse.compiled`` (Numba, ``nogil``, cached on disk): assembly and
extend-add of a front, its dense partial Cholesky (a right-looking loop, or LAPACK ``potrf`` with BLAS
``trsm``/``syrk`` called by address), the loop over a range of fronts in postorder, the triangular solves,
and the bookkeeping of the update stacks (their simulated peak, the subtrees of the front tree, copying
an update between stacks). Storage and equations: ``lago_cvx.sparse.compiled``'s docstring.

These are the fallback: ``lago_cvx.sparse.compiled.kernels()`` gives the same functions in C (``c_kernels``, the
same arithmetic in the same order, so the same bits) when their library was built at install, and this module
only when it was not (or when ``compiled.use_kernels("numba")`` asks for it). The reason is each process's start:
Numba's import and the loading of these kernels from its cache cost about half a second before the first one
runs, the C library a few milliseconds. This module imports Numba: ``kernels()`` imports it on first use only.
The kernels are module-level functions (not closures), so Numba's on-disk cache finds them again in a new process.
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

from . import supernodes
from .kernel_checks import checked

__all__ = ["KERNELS", "CACHED"]

log = logging.getLogger(__name__)


def _probe(x):
    return x


def _can_cache() -> bool:
    """True when Numba can keep this module's compiled code on disk: in ``__pycache__`` beside it, or else
    (a read-only install, a shared JupyterHub) in the user's cache folder (``NUMBA_CACHE_DIR`` or
    ``~/.cache/numba``). Numba refuses ``cache=True`` at once when no such place is writable."""
    try:
        njit(cache=True)(_probe)
    except RuntimeError as exc:
        log.warning("Numba cannot keep compiled code on disk here (%s): every new process compiles the sparse "
                    "engine's kernels again, about 10-20 s before its first factorization of more than "
                    "300 000 unknowns; set NUMBA_CACHE_DIR to a writable folder to keep them", exc)
        return False
    return True


#: Whether the kernels are cached on disk (``_can_cache``); the warning above is logged once, on import.
CACHED = _can_cache()


def _jit(fn):
    return njit(nogil=True, cache=CACHED)(fn)


def _addresses() -> np.ndarray:
    """(3,) int64: the addresses of SciPy's LAPACK ``dpotrf`` and BLAS ``dtrsm``, ``dsyrk`` (Fortran
    calling convention: every argument by pointer, 32-bit integers)."""
    from numba.extending import get_cython_function_address as address

    return np.array([address("scipy.linalg.cython_lapack", "dpotrf"), address("scipy.linalg.cython_blas", "dtrsm"),
                     address("scipy.linalg.cython_blas", "dsyrk")], np.int64)


def _pointer_call(n: int):
    """A Numba intrinsic calling the function at an address with ``n`` pointer arguments, all given as
    integers (so compiled code that calls LAPACK/BLAS by address can be cached on disk: the addresses
    are arguments, looked up in each process)."""
    from llvmlite import ir
    from numba import types
    from numba.extending import intrinsic

    def codegen(context, builder, signature, values):
        p = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [p] * n)
        fn = builder.inttoptr(values[0], fnty.as_pointer())
        builder.call(fn, [builder.inttoptr(v, p) for v in values[1:]])
        return context.get_dummy_value()

    def typer(typingctx, *args):
        return types.void(*([types.intp] * (n + 1))), codegen

    names = ", ".join(f"a{i}" for i in range(n + 1))  # Numba types intrinsics by their named parameters
    scope = {"typer": typer}
    exec(f"def _call{n}(typingctx, {names}):\n    return typer(typingctx, {names})\n", scope)
    return intrinsic(scope[f"_call{n}"])


_call5, _call10, _call11 = _pointer_call(5), _pointer_call(10), _pointer_call(11)


@_jit
def assemble(f, b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, stack, st_front,
             st_off, state):
    """Front f's matrix in F (column-major D × D, lower triangle): N's blocks in its pivot columns,
    each computed here from its edge's A_k, B_k (m, q, b) as eq. (N) writes it (pair index
    e = kind·m + k: kind 0 A_kᵀA_k, 1 B_kᵀB_k, 2 B_kᵀA_k), then the extend-add of its children's
    updates, popped from the stack. Returns D."""
    k = (fptr[f + 1] - fptr[f]) * b
    r = (rptr[f + 1] - rptr[f]) * b
    D = k + r
    F[:D * D] = 0.0
    m = A.shape[0]
    nq = A.shape[1]
    for q in range(bptr[f], bptr[f + 1]):
        kind = border[q] // m
        e = border[q] - kind * m
        X = B[e] if kind >= 1 else A[e]  # the block is Xᵀ Y
        Y = B[e] if kind == 1 else A[e]
        li = bli[q] * b
        lj = blj[q] * b
        for i in range(b):
            for j in range(b):
                v = 0.0
                if btr[q]:
                    for s in range(nq):
                        v += X[s, j] * Y[s, i]
                else:
                    for s in range(nq):
                        v += X[s, i] * Y[s, j]
                F[(li + i) + (lj + j) * D] += v
    top = state[0]
    nc = nchild[f]
    for s in range(top - nc, top):
        c = st_front[s]
        off = st_off[s]
        r0 = rptr[c]
        pc = rptr[c + 1] - r0
        rc = pc * b
        for jp in range(pc):  # column pose of the child's update, then its components
            for jc in range(b):
                jj = jp * b + jc
                dst = (rel[r0 + jp] * b + jc) * D
                src = off + jj * rc
                # the column's first pose: components jc … b − 1 only (lower triangle)
                base = dst + rel[r0 + jp] * b
                for ic in range(jc, b):
                    F[base + ic] += stack[src + jp * b + ic]
                for ip in range(jp + 1, pc):
                    base = dst + rel[r0 + ip] * b
                    sb = src + ip * b
                    for ic in range(b):
                        F[base + ic] += stack[sb + ic]
    state[0] = top - nc
    return D

@_jit
def finish(f, b, fptr, rptr, Lptr, L, F, stack, st_front, st_off, state):
    """Keep front f's block column [L_PP; X] in L (packed columns) and push its update U (lower
    triangle) on the stack."""
    k = (fptr[f + 1] - fptr[f]) * b
    r = (rptr[f + 1] - rptr[f]) * b
    D = k + r
    base = Lptr[f]
    for j in range(k):  # column j of [L_PP; X], rows j … D − 1 (packed: no strict upper triangle)
        dst = base + j * D - j * (j + 1) // 2
        src = j * D
        for i in range(j, D):
            L[dst + i] = F[src + i]
    if r > 0:
        top = state[0]
        off = st_off[top]
        for j in range(r):
            src = (k + j) * D + k
            dst = off + j * r
            for i in range(j, r):
                stack[dst + i] = F[src + i]
        st_front[top] = f
        st_off[top + 1] = off + r * r
        state[0] = top + 1

@_jit
def dense(F, D, k):
    """Partial Cholesky of the column-major D × D front F (lower triangle), right-looking: L_PP, X and
    U in place (eq. (MF)). Returns 0, or j + 1 when pivot j is not positive."""
    for j in range(k):
        cj = j * D
        djj = F[cj + j]
        if not djj > 0.0:
            return j + 1
        djj = np.sqrt(djj)
        F[cj + j] = djj
        inv = 1.0 / djj
        for i in range(j + 1, D):
            F[cj + i] *= inv
        for c in range(j + 1, D):
            a = F[cj + c]
            if a != 0.0:
                cc = c * D
                for i in range(c, D):
                    F[cc + i] -= F[cj + i] * a
    return 0

@_jit
def dense_blas(F, D, k, fn, iv, dv):
    """(MF) on the column-major D × D front F by LAPACK/BLAS through the addresses ``fn`` (potrf, trsm,
    syrk of SciPy's ``cython_lapack``/``cython_blas``): L_PP = potrf(F_PP), X = trsm(F_RP, L_PP),
    U = syrk(F_RR, X), all in place. ``iv`` (8,) int32 and ``dv`` (2,) float work arrays.
    Returns LAPACK's info (0: done)."""
    r = D - k
    iv[0] = k
    iv[1] = D
    iv[2] = r
    iv[3] = 0
    iv[4] = 76  # 'L'  (the characters as 4-byte integers: Fortran reads their first byte)
    iv[5] = 82  # 'R'
    iv[6] = 84  # 'T'
    iv[7] = 78  # 'N'
    dv[0] = 1.0
    dv[1] = -1.0
    p_iv = iv.ctypes.data
    p_dv = dv.ctypes.data
    base = F.ctypes.data
    _call5(fn[0], p_iv + 16, p_iv, base, p_iv + 4, p_iv + 12)
    if iv[3] != 0:
        return iv[3]
    if r > 0:
        _call11(fn[1], p_iv + 20, p_iv + 16, p_iv + 24, p_iv + 28, p_iv + 8, p_iv, p_dv, base, p_iv + 4,
                base + 8 * k, p_iv + 4)
        _call10(fn[2], p_iv + 16, p_iv + 28, p_iv + 8, p_iv, p_dv + 8, base + 8 * k, p_iv + 4, p_dv,
                base + 8 * (k + k * D), p_iv + 4)
    return 0

@_jit
def run(f0, f1, big, b, fptr, rptr, rel, nchild, Lptr, bptr, border, bli, blj, btr, A, B, L, F, stack,
        st_front, st_off, state, small_work, fn):
    """Fronts f0, f0 + 1, … of (MF) in postorder, up to f1 or the first front marked ``big`` (left to
    the caller, which gives it more BLAS threads): a front with k·D² below ``small_work`` by the
    right-looking loop, a larger one by LAPACK/BLAS (``dense_blas``). Returns the front it stopped at, or −(f + 1) for a front whose pivot block is not
    positive definite."""
    iv = np.zeros(8, np.int32)
    dv = np.zeros(2)
    for f in range(f0, f1):
        if big[f]:
            return f
        D = assemble(f, b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, stack,
                     st_front, st_off, state)
        k = (fptr[f + 1] - fptr[f]) * b
        if k * D * D >= small_work:
            if dense_blas(F, D, k, fn, iv, dv) != 0:
                return -(f + 1)
        elif dense(F, D, k) != 0:
            return -(f + 1)
        finish(f, b, fptr, rptr, Lptr, L, F, stack, st_front, st_off, state)
    return f1


@_jit
def _front(f, b, fptr, rptr, rows, Lptr, slot):
    """Front f's sizes for the sweeps — (k, r, D, first pivot slot, start of its columns in L) — with the
    slots of its r update variables written to ``slot``."""
    k = (fptr[f + 1] - fptr[f]) * b
    pr = rptr[f + 1] - rptr[f]
    for p in range(pr):
        for c in range(b):
            slot[p * b + c] = rows[rptr[f] + p] * b + c
    return k, pr * b, k + pr * b, fptr[f] * b, Lptr[f]


@_jit
def forward(Y, seq, b, fptr, rptr, rows, Lptr, L, rmax):
    """L z = y in place for Y (nrhs, slots), over the fronts ``seq`` in that order (children before
    parents): z_P = L_PP⁻¹ y_P, y_R −= X z_P, y_R gathered into a local vector so the inner loops run
    down L's contiguous columns."""
    nr = Y.shape[0]
    slot = np.empty(rmax, np.int64)
    t = np.empty(rmax)
    for q in range(seq.size):
        k, r, D, s0, base = _front(seq[q], b, fptr, rptr, rows, Lptr, slot)
        for c in range(nr):
            y = Y[c]
            t[:r] = 0.0
            for j in range(k):
                col = base + j * D - j * (j + 1) // 2  # entry (i, j) at col + i
                v = y[s0 + j] / L[col + j]
                y[s0 + j] = v
                if v != 0.0:
                    for i in range(j + 1, k):
                        y[s0 + i] -= L[col + i] * v
                    for i in range(r):
                        t[i] += L[col + k + i] * v
            for i in range(r):
                y[slot[i]] -= t[i]


@_jit
def backward(Y, seq, b, fptr, rptr, rows, Lptr, L, rmax):
    """Lᵀ x = z in place for Y (nrhs, slots), over the fronts ``seq`` in that order (parents before
    children): x_P = L_PP⁻ᵀ(z_P − Xᵀ x_R)."""
    nr = Y.shape[0]
    slot = np.empty(rmax, np.int64)
    t = np.empty(rmax)
    for q in range(seq.size):
        k, r, D, s0, base = _front(seq[q], b, fptr, rptr, rows, Lptr, slot)
        for c in range(nr):
            y = Y[c]
            for i in range(r):
                t[i] = y[slot[i]]
            for j in range(k - 1, -1, -1):
                col = base + j * D - j * (j + 1) // 2  # entry (i, j) at col + i
                v = y[s0 + j]
                for i in range(j + 1, k):
                    v -= L[col + i] * y[s0 + i]
                for i in range(r):
                    v -= L[col + k + i] * t[i]
                y[s0 + j] = v / L[col + j]


@_jit
def pose_local(f, pos, fptr, rptr, rows):
    """Local pose index of position pos[t] in front f[t] (``_local``)."""
    out = np.empty(f.size, np.int64)
    for t in range(f.size):
        out[t] = _local(f[t], pos[t], fptr, rptr, rows)
    return out


@njit(nogil=True, cache=CACHED, inline="always")
def _local(g, p, fptr, rptr, rows):
    """Local pose index of position p in front g: p − first pivot for a pivot, else the front's pivot
    count plus p's rank among its update rows (binary search; p must be in the front)."""
    if fptr[g] <= p < fptr[g + 1]:
        return p - fptr[g]
    lo, hi = rptr[g], rptr[g + 1]
    while lo < hi:
        mid = (lo + hi) // 2
        if rows[mid] < p:
            lo = mid + 1
        else:
            hi = mid
    return fptr[g + 1] - fptr[g] + lo - rptr[g]


@_jit
def block_map(prow, pcol, position, front_of, fptr, rptr, rows):
    """``CompiledAssembler``'s map in three passes: the pairs (prow[t], pcol[t]) with both ends free,
    bucketed by the front holding their lower end's pivot column (stable), each with its local block
    row and column in that front and whether the stored block is the pair's transposed. Returns (order,
    bptr, li, lj, transposed)."""
    nf = fptr.size - 1
    bptr = np.zeros(nf + 1, np.int64)
    for t in range(prow.size):
        if prow[t] >= 0 and pcol[t] >= 0:
            bptr[front_of[min(position[prow[t]], position[pcol[t]])] + 1] += 1
    for g in range(nf):
        bptr[g + 1] += bptr[g]
    n = bptr[nf]
    fill = bptr[:-1].copy()
    order = np.empty(n, np.int64)
    li = np.empty(n, np.int64)
    lj = np.empty(n, np.int64)
    transposed = np.empty(n, np.bool_)
    for t in range(prow.size):
        if prow[t] < 0 or pcol[t] < 0:
            continue
        pr, pc = position[prow[t]], position[pcol[t]]
        lo, hi = min(pr, pc), max(pr, pc)
        g = front_of[lo]
        s = fill[g]
        fill[g] += 1
        order[s] = t
        transposed[s] = pr < pc
        lj[s] = lo - fptr[g]
        li[s] = _local(g, hi, fptr, rptr, rows)
    return order, bptr, li, lj, transposed


@_jit
def edge_matvec(A, B, t, h, x):
    """M x of the edge system (E) for r right-hand sides: row k is A_k x_{t_k} + B_k x_{h_k} (A, B (m, q, b);
    t, h (m,), −1 at the anchor, whose x is 0; x (d, b, r); out (m, q, r)); the terms added in
    ``normal_equations.EdgeOperator.matvec``'s order."""
    m, q, b = A.shape
    nr = x.shape[2]
    out = np.empty((m, q, nr))
    for k in range(m):
        tk, hk = t[k], h[k]
        for s in range(q):
            for j in range(nr):
                o = 0.0
                for c in range(b):
                    xt = x[tk, c, j] if tk >= 0 else 0.0
                    xh = x[hk, c, j] if hk >= 0 else 0.0
                    if c == 0:
                        o = A[k, s, 0] * xt
                    else:
                        o += A[k, s, c] * xt
                    o += B[k, s, c] * xh
                out[k, s, j] = o
    return out


@_jit
def edge_rmatvec(A, B, t, h, r, d):
    """Mᵀ r (d, b, nr) of the edge system (E) for r (m, q, nr): every tail's A_kᵀ r_k, then every head's
    B_kᵀ r_k, added in edge order (the order of ``normal_equations.EdgeOperator.rmatvec``'s bincount)."""
    m, q, b = A.shape
    nr = r.shape[2]
    out = np.zeros((d, b, nr))
    for J, ends in ((A, t), (B, h)):
        for k in range(m):
            e = ends[k]
            if e < 0:
                continue
            for c in range(b):
                for j in range(nr):
                    u = J[k, 0, c] * r[k, 0, j]
                    for s in range(1, q):
                        u += J[k, s, c] * r[k, s, j]
                    out[e, c, j] += u
    return out


@_jit
def stack_peak(seq, nchild, sizes):
    """The most stack entries alive at once while the fronts ``seq`` are factored in that order, each
    popping its children's updates and pushing its own (``sizes`` (F,) its r²); updates never popped
    (subtree roots whose parent is not in ``seq``) stay to the end."""
    nf = seq.size
    lev = np.zeros(nf + 1, np.int64)
    top = 0
    peak = 0
    for t in range(nf):
        f = seq[t]
        top -= nchild[f]
        if top < 0:
            top = 0
        if sizes[f] > 0:
            lev[top + 1] = lev[top] + sizes[f]
            top += 1
            if lev[top] > peak:
                peak = lev[top]
    return peak

@_jit
def subtrees(parent, work):
    """For fronts in postorder: each subtree's total ``work`` and its first front (the subtree of f is
    the range first[f] … f)."""
    n = parent.size
    total = work.copy()
    first = np.arange(n)
    for f in range(n):
        p = parent[f]
        if p >= 0:
            total[p] += total[f]
            if first[f] < first[p]:
                first[p] = first[f]
    return total, first

@_jit
def push(src, off, size, stack, st_front, st_off, state, f):
    """Push front f's update, ``src[off:off + size]`` (another stack's), onto this stack."""
    top = state[0]
    o = st_off[top]
    stack[o:o + size] = src[off:off + size]
    st_front[top] = f
    st_off[top + 1] = o + size
    state[0] = top + 1

@_jit
def one(f, b, fptr, rptr, Lptr, L, F, D, fn):
    """A front already assembled in F, by LAPACK/BLAS, kept in L (the caller pushes its update)."""
    iv = np.zeros(8, np.int32)
    dv = np.zeros(2)
    return dense_blas(F, D, (fptr[f + 1] - fptr[f]) * b, fn, iv, dv)


#: The kernels by name, and ``fn`` the LAPACK/BLAS addresses of this process; each checks the indices it reads first
#: (``kernel_checks``: a malformed plan raises PlanError; the module's own functions, which call each other in
#: compiled code, do not check).
KERNELS = checked(dict(assemble=assemble, finish=finish, run=run, forward=forward, backward=backward,
               stack_peak=stack_peak, one=one, subtrees=subtrees, push=push, pose_local=pose_local,
               block_map=block_map, edge_matvec=edge_matvec, edge_rmatvec=edge_rmatvec,
               relax=_jit(supernodes.relax), heights=_jit(supernodes.heights),
                       postorder=_jit(supernodes.postorder), fn=_addresses()))
