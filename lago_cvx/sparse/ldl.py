r"""QDLDL's sparse LDLᵀ factorization in an ordering given by the caller.

The ``qdldl`` package (a dependency of cvxpy, and the KKT solver of OSQP and Clarabel) exposes one
Python entry point, ``qdldl.Solver(A)``, which always computes AMD on the scalar matrix before
factoring. LAGO's systems do not need that: every system of a graph has b×b blocks on the pattern of
the anchor-reduced pose graph, whose fill-reducing ordering is computed once at the pose level
(``normal_equations.GraphElimination``, AMD of the d × d pose Laplacian) and serves b = 1, 2, 3 alike.
Repeating AMD on the 3d × 3d scalar matrix of phase 3 costs more than half the numeric factorization's time and
finds no better ordering: on se-sync/city10000.g2o L has 1 015 974 entries under scalar AMD and 1 016 856 under
the pose ordering expanded to 3 components per pose (phase 3's times: ``benchmarks/perf.md``).

So this module calls QDLDL's three C routines directly through ``ctypes``, on an upper-triangular CSC
already in elimination order:

    QDLDL_etree(n, Ap, Ai, work, Lnz, etree)            elimination tree, column counts of L
    QDLDL_factor(n, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, Lnz, etree, bwork, iwork, fwork)     A = (I+L) D (I+L)ᵀ
    QDLDL_solve(n, Lp, Li, Lx, Dinv, x)                  x ← A⁻¹x in place

(the C API of QDLDL, ``qdldl.h``; no allocation inside, every array allocated here with NumPy). The
symbolic part (``LDLPattern``: etree and column counts) is kept and reused by every factorization with
the same pattern.

**ABI check.** The routines are looked up in the ``qdldl`` extension module's shared object. Its
integer and float types are fixed when the package is built; the package's own C++ class
``qdldl::Solver(QDLDL_int, QDLDL_int*, QDLDL_int*, QDLDL_float*)`` is exported under the mangled name
``_ZN5qdldl6SolverC1ExPxS1_Pd``, which spells QDLDL_int = ``long long`` (x) and QDLDL_float =
``double`` (d). ``available()`` is True only when that symbol and the three routines are all present;
otherwise (another build or version of qdldl) callers use ``qdldl.Solver`` as before. QDLDL_bool's
size is not part of that check: its work array is allocated with 8 bytes per entry, enough for any
boolean type.
"""

from __future__ import annotations

import ctypes
import logging
import mmap
import os
import threading
import weakref

import numpy as np

from ..errors import NumericalError

__all__ = ["available", "huge_empty", "HUGE_MIN", "HUGE_POOL", "LDLPattern", "LDLFactor", "column_work"]

log = logging.getLogger(__name__)

#: The C++ constructor whose mangled name fixes QDLDL_int = long long and QDLDL_float = double.
_ABI_SYMBOL = "_ZN5qdldl6SolverC1ExPxS1_Pd"

_LIB: list = []  # [ctypes library or None], resolved on first use


def _library():
    """The ``qdldl`` extension module as a ``ctypes`` library with typed routines, or None."""
    if not _LIB:
        lib = None
        try:
            import qdldl

            cand = ctypes.CDLL(qdldl.__file__)
            if all(hasattr(cand, s) for s in (_ABI_SYMBOL, "QDLDL_etree", "QDLDL_factor", "QDLDL_solve")):
                ptr, i64 = ctypes.c_void_p, ctypes.c_longlong
                cand.QDLDL_etree.restype = i64
                cand.QDLDL_etree.argtypes = [i64] + [ptr] * 5
                cand.QDLDL_factor.restype = i64
                cand.QDLDL_factor.argtypes = [i64] + [ptr] * 13
                cand.QDLDL_solve.restype = None
                cand.QDLDL_solve.argtypes = [i64] + [ptr] * 5
                lib = cand
            else:
                log.info("qdldl's C routines are not exported as expected: using qdldl.Solver (with its AMD)")
        except Exception as exc:  # no qdldl, or a shared object ctypes cannot open
            log.info("qdldl's C routines unavailable (%s): using qdldl.Solver", exc)
        _LIB.append(lib)
    return _LIB[0]


def available() -> bool:
    """True when QDLDL's C routines can be called directly (module docstring, "ABI check")."""
    return _library() is not None


def _p(a: np.ndarray) -> int:
    return a.ctypes.data


#: L's arrays of at least this many bytes are placed on transparent huge pages (``huge_empty``): a 2 MiB threshold
#: left input_M3500's phase 3 (L's arrays 1.4 MiB each) slower after a fragmenting run (``benchmarks/perf.md``).
HUGE_MIN = 256 << 10
#: Freed huge-page regions kept for the next factorization, up to this many bytes in all.
HUGE_POOL = 64 << 20
_HUGE = 2 << 20  # the size of a huge page
_POOL: list = []  # free regions (mmap objects), smallest first; read and changed under _POOL_LOCK
_RETURNED: list = []  # regions given back since, moved into _POOL by the next huge_empty
_POOL_LOCK = threading.Lock()


def _forget_pool_in_child() -> None:
    """After ``fork``: the child starts with an empty pool and a fresh lock. The regions are private
    (``MAP_PRIVATE``: a child's writes never reach its parent's memory, nor the parent's the child's), and
    a lock another thread of the parent held at the fork would never be released in the child."""
    global _POOL_LOCK
    _POOL_LOCK = threading.Lock()
    _POOL.clear()
    _RETURNED.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool_in_child)


def _give_back(region) -> None:
    """A region whose array is going: kept for reuse while the pool has room; else left to be unmapped
    when the array lets go of it (it still holds the region's buffer while this runs). No lock: this runs
    whenever the array is freed, possibly inside ``huge_empty`` (a garbage collection), and ``append`` is
    atomic."""
    if sum(map(len, _POOL)) + sum(map(len, _RETURNED)) + len(region) <= HUGE_POOL:
        _RETURNED.append(region)


def huge_empty(n: int, dtype) -> np.ndarray:
    """An uninitialized array of n entries on transparent huge pages when it takes at least ``HUGE_MIN``
    bytes (else, or where ``MADV_HUGEPAGE`` is not available, ``np.empty``): a 2 MiB-aligned part of an
    anonymous ``mmap`` advised ``MADV_HUGEPAGE``, taken from the regions freed arrays left (``HUGE_POOL``
    bytes of them are kept), or mapped anew. The mapping is private (copy-on-write across ``fork``) and a
    forked child starts with an empty pool.

    Why: QDLDL writes L row by row, so each row's entries land in as many columns, far apart in ``Li``
    and ``Lx``; on 4 KiB pages those writes miss the TLB, and the same factorization's time then depends on where
    NumPy's allocator put L (up to threefold on city10000's chordal system; ``benchmarks/perf.md``). Fresh huge
    pages must be zeroed, hence the pool: a LAGO run after another reuses the last run's regions."""
    dtype = np.dtype(dtype)
    nbytes = int(n) * dtype.itemsize
    advice = getattr(mmap, "MADV_HUGEPAGE", None)
    if nbytes < HUGE_MIN or advice is None:
        return np.empty(n, dtype)
    need = (nbytes + 2 * _HUGE - 1) // _HUGE * _HUGE  # a huge page more than the array: room to align
    region = None
    with _POOL_LOCK:
        while _RETURNED:
            _POOL.append(_RETURNED.pop())
        _POOL.sort(key=len)
        fit = [i for i, r in enumerate(_POOL) if len(r) >= need]
        if fit:
            region = _POOL.pop(fit[0])
    try:
        if region is None:
            # private: anonymous mappings are shared with forked children by default, and a child
            # factoring into memory its parent also writes corrupts both
            region = mmap.mmap(-1, need, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
            region.madvise(advice)
        raw = np.frombuffer(region, np.uint8)
    except (OSError, ValueError) as exc:  # no such advice on this kernel, or no memory map
        log.debug("huge pages not used (%s)", exc)
        return np.empty(n, dtype)
    weakref.finalize(raw, _give_back, region).atexit = False  # every view holds raw: after the last one
    start = (-raw.ctypes.data) % _HUGE
    return raw[start:start + nbytes].view(dtype)


def column_work(counts: np.ndarray) -> np.ndarray:
    """(count + 1)² for the strictly-lower entry counts (n,) of L's columns: each column's multiply–adds in
    the factorization (their sum is Σ colcount², the flop count quoted throughout)."""
    return (np.asarray(counts, dtype=float) + 1.0) ** 2


class LDLPattern:
    """The symbolic analysis of an n × n symmetric matrix given by its upper triangle in CSC form:
    ``indptr`` (n+1,), ``indices`` (nnz,) (rows increasing within a column, the diagonal present in every
    column), already in elimination order. Holds QDLDL's elimination tree and the column counts ``Lnz``
    (n,) of L (strictly below the diagonal); ``nnz_L`` their sum. Raises ``NumericalError`` if QDLDL
    rejects the pattern (an entry below the diagonal, an empty column, a column whose last entry is not
    its diagonal)."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        lib = _library()
        if lib is None:
            raise RuntimeError("QDLDL's C routines are not available (ldl.available() is False)")
        self.n = n = int(indptr.size - 1)
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int64)
        self.indices = np.ascontiguousarray(indices, dtype=np.int64)
        self.etree = np.empty(n, np.int64)
        self.Lnz = np.empty(n, np.int64)
        work = np.empty(n, np.int64)
        total = lib.QDLDL_etree(n, _p(self.indptr), _p(self.indices), _p(work), _p(self.Lnz), _p(self.etree))
        if total < 0:
            raise NumericalError(f"QDLDL_etree rejected the pattern (status {total}): not upper triangular, "
                                 "an empty column, or a column whose last entry is not its diagonal")
        self.nnz_L = int(total)

    @classmethod
    def expanded(cls, pose: "LDLPattern", b: int, indptr: np.ndarray, indices: np.ndarray) -> "LDLPattern":
        """The analysis of ``pose``'s pattern with every entry expanded to a dense b×b block (a diagonal
        entry to the block's upper half), variable (pose J, component c) numbered J·b + c; ``indptr``,
        ``indices`` that expanded pattern. No second ``QDLDL_etree``: with dense blocks the fill is the
        pose-level fill, so column (J, c) of L holds components c+1 … b−1 of pose J and every component of
        each pose in column J of the pose-level L, i.e.

            Lnz[J·b + c] = b·Lnz_pose[J] + (b − 1 − c),   parent (J, c + 1) for c < b − 1,
            and (parent_pose(J), 0) for c = b − 1 (none at a root).

        ``tests/test_ldl.py`` holds it equal to ``QDLDL_etree`` on the expanded pattern."""
        if _library() is None:
            raise RuntimeError("QDLDL's C routines are not available (ldl.available() is False)")
        self = cls.__new__(cls)
        self.n = pose.n * b
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int64)
        self.indices = np.ascontiguousarray(indices, dtype=np.int64)
        comp = np.arange(b)
        self.Lnz = (b * pose.Lnz[:, None] + (b - 1 - comp)).reshape(-1)
        up = np.where(pose.etree >= 0, pose.etree * b, -1)  # parent of each pose's last component
        self.etree = np.where(comp < b - 1, (np.arange(pose.n)[:, None] * b + comp + 1), up[:, None]).reshape(-1)
        self.nnz_L = int(self.Lnz.sum())
        return self

    def flops(self) -> float:
        """Σ over the columns of L of colcount² (diagonal included): the multiply–adds of the
        factorization."""
        return float(column_work(self.Lnz).sum())

    def factor(self, data: np.ndarray, *, progress=None, meanwhile=None) -> "LDLFactor":
        """Factor the matrix with values ``data`` (nnz,) on this pattern; ``progress(done, total)`` and
        ``meanwhile()`` as ``LDLFactor`` takes them."""
        return LDLFactor(self, data, progress=progress, meanwhile=meanwhile)


#: Seconds between two looks at a running factorization when progress is asked for.
PROGRESS_POLL = 0.25


class LDLFactor:
    """A = (I + L) D (I + L)ᵀ by ``QDLDL_factor`` on an ``LDLPattern``; ``solve(rhs)`` for rhs (n,) or
    (n, r) in the pattern's (elimination) numbering. Raises ``NumericalError`` when a pivot D_jj is zero
    (QDLDL's status −1), as ``qdldl.Solver`` does; ``n_positive`` the number of positive pivots (n for a
    numerically positive definite A).

    ``progress(done, total)``, when given, is called while the factorization runs: QDLDL computes L row
    by row (up-looking) and writes D_kk⁻¹ when row k is done, so the C call runs in a worker thread
    (``ctypes`` releases the GIL) while this one looks every ``PROGRESS_POLL`` s at how many of those are
    written; the rows done are weighted by (count of L's column + 1)², the column's share of the
    multiply–adds, so the fraction is an estimate of the work done, not of the time.

    ``meanwhile()``, when given, is called in this thread while the worker factors: independent work
    (another system's pattern or factorization, ``GraphElimination.defer``) done on the second core."""

    def __init__(self, pattern: LDLPattern, data: np.ndarray, *, progress=None, meanwhile=None):
        lib = _library()
        n = pattern.n
        self.pattern = pattern
        self._lib = lib
        Ax = np.ascontiguousarray(data, dtype=float)
        if Ax.size != pattern.indices.size:
            raise ValueError(f"{Ax.size} values for a pattern of {pattern.indices.size} entries")
        self.Lp = np.empty(n + 1, np.int64)
        self.Li = huge_empty(max(pattern.nnz_L, 1), np.int64)  # QDLDL's scattered writes: huge pages
        self.Lx = huge_empty(max(pattern.nnz_L, 1), np.float64)
        self.D = np.empty(n)
        self.Dinv = np.empty(n)
        bwork = np.empty(n, np.int64)  # QDLDL_bool[n]; 8 bytes each covers any boolean type
        iwork = np.empty(3 * n, np.int64)
        fwork = np.empty(n)
        args = (n, _p(pattern.indptr), _p(pattern.indices), _p(Ax), _p(self.Lp), _p(self.Li), _p(self.Lx),
                _p(self.D), _p(self.Dinv), _p(pattern.Lnz), _p(pattern.etree), _p(bwork), _p(iwork), _p(fwork))
        if (progress is None and meanwhile is None) or n == 0:
            status = lib.QDLDL_factor(*args)
        else:
            status = self._factor_watched(lib, args, progress, (Ax, bwork, iwork, fwork), meanwhile)
        if status < 0:
            raise NumericalError("QDLDL_factor: a zero pivot (the matrix is not quasi-definite in floating point)")
        self.n_positive = int(status)

    def _factor_watched(self, lib, args, progress, keep_alive, meanwhile=None) -> int:
        """``QDLDL_factor(*args)`` in a worker thread, ``meanwhile()`` run here first, then ``progress`` fed
        from the rows done (class docstring). ``keep_alive`` holds the work arrays the call points into
        until it returns."""
        import threading

        if progress is not None:
            self.Dinv.fill(np.nan)  # QDLDL writes Dinv[k] once, when row k is done
            work = np.cumsum(column_work(self.pattern.Lnz))
            total = float(work[-1])
        status = []
        worker = threading.Thread(target=lambda: status.append(lib.QDLDL_factor(*args)), daemon=True,
                                  name="qdldl-factor")
        worker.start()
        raised = None
        try:
            if meanwhile is not None:
                meanwhile()
            if progress is not None:
                progress(0.0, total)
            while progress is not None:
                worker.join(PROGRESS_POLL)
                if not worker.is_alive():
                    break
                pending = np.isnan(self.Dinv)
                done = int(pending.argmax()) if pending.any() else pending.size  # the first row not done yet
                progress(float(work[done - 1]) if done else 0.0, total)
        except BaseException as exc:  # a failing callback, Ctrl-C: raised once the C call has returned
            raised = exc
        while worker.is_alive():  # the call cannot be interrupted and writes into arrays held here
            try:
                worker.join()
            except BaseException as exc:
                raised = raised or exc
        del keep_alive
        if raised is not None:
            raise raised
        if not status:  # the thread ended without a result (cannot happen short of a crash in C)
            raise NumericalError("QDLDL_factor did not return")
        if progress is not None:
            progress(total, total)
        return int(status[0])

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        n = self.pattern.n
        x = np.array(rhs, dtype=float, order="F")  # a copy; each column contiguous
        if x.shape[0] != n:
            raise ValueError(f"right-hand side of {x.shape[0]} rows for a {n} × {n} factor")
        cols = x.reshape(n, -1, order="F")
        for j in range(cols.shape[1]):
            col = cols[:, j]
            self._lib.QDLDL_solve(n, _p(self.Lp), _p(self.Li), _p(self.Lx), _p(self.Dinv), _p(col))
        return x
