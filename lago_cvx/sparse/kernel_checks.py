"""What the compiled kernels (``c_kernels`` in C, ``compiled_kernels`` in Numba) read without checking, checked
before any of them runs: ``checked(KERNELS)`` gives the same kernels, each first validating its arguments and
raising ``PlanError`` (a ``LagoError`` and a ``ValueError``) instead of reading or writing out of bounds.

* The plan (``multifrontal.EliminationPlan`` as ``compiled.CompiledLayout`` expands it): ``fptr`` (F + 1,) and
  ``rptr`` (F + 1,) start at 0, never decrease, end at the sizes of what they point into; ``rows`` positions in
  [0, d); ``Lptr`` (F + 1,) leaves each front room for its packed column block; ``rel`` local indices inside the
  largest front; ``nchild`` ≥ 0; ``parent`` pointers −1 or a later front (postorder); ``position`` a permutation;
  every front's order D = (k + r)·b at most 2³¹ − 1 (LAPACK/BLAS take 32-bit sizes: checked, never narrowed).
  O(F + |rows|) array operations, once per plan: the arrays checked are made read-only and remembered (by
  identity, weakly), so a factorization's hundreds of kernel calls each pay a dictionary look-up.
* The assembler (``bptr``, ``order``, ``li``, ``lj``): pointers as above, local block indices inside their front.
* Per call, O(1) or O(size of the call's own input): front numbers in range, buffers (F, L, Y, the stacks' tops)
  large enough for the plan, edge ends in [−1, d), trees' parent pointers in range.

The update stacks' contents (``st_front``, ``st_off``) are the kernels' own scratch, written only by them; their
sizes and tops are checked, their entries trusted.
"""

from __future__ import annotations

import weakref

import numpy as np

from ..errors import PlanError

__all__ = ["checked", "forest", "permutation", "plan", "INT_MAX"]

#: The largest size LAPACK/BLAS (32-bit Fortran integers) accept.
INT_MAX = 2**31 - 1

_KNOWN: dict = {}  # key (kind, b, ids) → (info, weakrefs of the arrays checked)


def _ints(a, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 1 or a.dtype.kind not in "iu":
        raise PlanError(f"sparse engine: {name} must be a 1-D integer array, not {a.dtype} of shape {a.shape}")
    return a


def _range(a, lo: int, hi: int, name: str) -> None:
    """Every entry of ``a`` in [lo, hi)."""
    a = np.asarray(a)
    if a.size and (int(a.min()) < lo or int(a.max()) >= hi):
        raise PlanError(f"sparse engine: {name} has entries outside [{lo}, {hi}) (from {int(a.min())} to "
                        f"{int(a.max())})")


def forest(parent, name: str = "parent", *, postorder: bool = False) -> None:
    """``parent`` (n,): each entry −1 (a root) or a node in [0, n) (with ``postorder``, a later one)."""
    parent = _ints(parent, name)
    _range(parent, -1, max(parent.size, 0), name)
    if postorder and parent.size:
        i = np.flatnonzero(parent >= 0)
        if (parent[i] <= i).any():
            raise PlanError(f"sparse engine: {name} is not in postorder (a parent at or before its child)")


def permutation(p, n: int, name: str = "position") -> None:
    """``p`` (n,) a permutation of 0 … n − 1."""
    p = _ints(p, name)
    if p.size != n:
        raise PlanError(f"sparse engine: {name} must have {n} entries, not {p.size}")
    _range(p, 0, max(n, 1), name)
    if n and np.bincount(p, minlength=n).max() != 1:
        raise PlanError(f"sparse engine: {name} is not a permutation (repeated entries)")


def plan(plan) -> None:
    """An ``EliminationPlan``'s tree and order, before its fronts reach compiled code: ``parent`` a forest in
    postorder, ``position`` a permutation of the d poses, ``fptr`` ending at d (``_fronts`` checks the rest)."""
    forest(plan.parent, postorder=True)
    permutation(plan.position, int(plan.d))
    _pointers(plan.fptr, int(plan.parent.size), int(plan.d), "fptr")


def _pointers(ptr, count: int, end: int | None, name: str) -> np.ndarray:
    """``ptr`` (count + 1,) from 0, never decreasing, ending at ``end`` (or anywhere when None)."""
    ptr = _ints(ptr, name)
    if ptr.size != count + 1 or (ptr.size and int(ptr[0]) != 0) or (np.diff(ptr) < 0).any():
        raise PlanError(f"sparse engine: {name} must be {count + 1} increasing pointers from 0")
    if end is not None and int(ptr[-1]) != end:
        raise PlanError(f"sparse engine: {name} ends at {int(ptr[-1])}, not at {end}")
    return ptr


def _remember(key, info, arrays):
    if len(_KNOWN) > 512:  # forget the plans no longer alive
        for dead in [k for k, (_, refs) in _KNOWN.items() if any(r() is None for r in refs)]:
            del _KNOWN[dead]
    if not all(isinstance(a, np.ndarray) for a in arrays):
        return info  # not kept: the kernel's own wrapper refuses what is not an array
    for a in arrays:
        if a.flags.writeable:
            a.flags.writeable = False  # checked once: it must not change afterwards
    _KNOWN[key] = (info, [weakref.ref(a) for a in arrays])
    return info


def _known(key, arrays):
    hit = _KNOWN.get(key)
    if hit is not None and all(r() is a for r, a in zip(hit[1], arrays)):
        return hit[0]
    return None


def _fronts(b, fptr, rptr, rows=None, Lptr=None, rel=None, nchild=None) -> dict:
    """The plan's sizes (``F``, ``d``, ``maxD``, ``rmax``, ``Lsize``), its arrays checked once (module docstring)."""
    arrays = [a for a in (fptr, rptr, rows, Lptr, rel, nchild) if a is not None]
    key = ("fronts", int(b), tuple(id(a) for a in arrays), rows is None, Lptr is None, rel is None)
    info = _known(key, arrays)
    if info is not None:
        return info
    b = int(b)
    if b < 1:
        raise PlanError(f"sparse engine: block size {b} < 1")
    fptr = _ints(fptr, "fptr")
    F = fptr.size - 1
    if F < 0:
        raise PlanError("sparse engine: fptr is empty")
    fptr = _pointers(fptr, F, None, "fptr")
    d = int(fptr[-1])
    rptr = _pointers(rptr, F, None if rows is None else np.size(rows), "rptr")
    k, r = np.diff(fptr) * b, np.diff(rptr) * b
    D = k + r
    maxD = int(D.max()) if F else 0
    if maxD > INT_MAX:
        raise PlanError(f"sparse engine: a front of order {maxD} exceeds LAPACK's 32-bit sizes ({INT_MAX})")
    if rows is not None:
        _range(_ints(rows, "rows"), 0, d, "rows")
    if Lptr is not None:
        Lptr = _pointers(Lptr, F, None, "Lptr")
        if (np.diff(Lptr) < D * k - k * (k - 1) // 2).any():
            raise PlanError("sparse engine: Lptr leaves a front less room than its column block")
    if rel is not None:
        rel = _ints(rel, "rel")
        if rel.size != int(rptr[-1]):
            raise PlanError(f"sparse engine: rel must have {int(rptr[-1])} entries, not {rel.size}")
        _range(rel, -1, max(maxD // b, 1), "rel")
    if nchild is not None:
        nchild = _ints(nchild, "nchild")
        if nchild.size != F or (nchild.size and (int(nchild.min()) < 0 or int(nchild.sum()) > max(F - 1, 0))):
            raise PlanError("sparse engine: nchild must be F counts ≥ 0 of at most F − 1 children")
    info = dict(F=F, d=d, maxD=maxD, rmax=int(r.max()) if F else 0, Lsize=None if Lptr is None else int(Lptr[-1]),
                D=D, k=k)
    return _remember(key, info, arrays)


def _assembler(info, bptr, border, bli, blj, btr) -> int:
    """The largest entry of ``order`` (its pairs kind·m + k), the assembler checked once against the plan."""
    arrays = [bptr, border, bli, blj, btr]
    key = ("assembler", id(info), tuple(id(a) for a in arrays))
    top = _known(key, arrays)
    if top is not None:
        return top
    n = np.size(border)
    bptr = _pointers(bptr, info["F"], n, "bptr")
    for a, name in ((border, "order"), (bli, "li"), (blj, "lj")):
        if _ints(a, name).size != n:
            raise PlanError(f"sparse engine: {name} must have {n} entries")
    if np.size(btr) != n:
        raise PlanError(f"sparse engine: transposed must have {n} entries")
    if n and (int(np.min(border)) < 0 or int(np.min(bli)) < 0 or int(np.min(blj)) < 0):
        raise PlanError("sparse engine: negative assembler indices")
    return _remember(key, int(border.max()) if n else -1, arrays)


def _local_blocks(info, b, bli, blj, bptr) -> None:
    front = np.repeat(np.arange(info["F"]), np.diff(bptr))
    if np.size(bli) and (((np.asarray(bli) + 1) * b > info["D"][front]).any()
                         or ((np.asarray(blj) + 1) * b > info["k"][front]).any()):
        raise PlanError("sparse engine: an assembler block lies outside its front")


def _front_no(f, info, name="front") -> int:
    f = int(f)
    if not 0 <= f < info["F"]:
        raise PlanError(f"sparse engine: {name} {f} is not in [0, {info['F']})")
    return f


def _size(a, need: int, name: str) -> None:
    if np.size(a) < need:
        raise PlanError(f"sparse engine: {name} has {np.size(a)} entries, the plan needs {need}")


def _stack(info, st_front, st_off, state, pop: int = 0) -> None:
    top = int(np.asarray(state).reshape(-1)[0]) if np.size(state) else -1
    if np.size(st_front) < info["F"] + 1 or np.size(st_off) < info["F"] + 2 or not pop <= top <= info["F"]:
        raise PlanError(f"sparse engine: update stack of the wrong size or top ({top})")


def _edges(A, B, m_pairs_top, b) -> None:
    A, B = np.asarray(A), np.asarray(B)
    if A.ndim != 3 or A.shape != B.shape or A.shape[2] != b or m_pairs_top >= 3 * A.shape[0]:
        raise PlanError(f"sparse engine: edge blocks of shape {A.shape}, {B.shape} do not fit the assembler")


def checked(raw: dict) -> dict:
    """The kernels of ``raw`` (``compiled_kernels.KERNELS``'s keys), each validating its arguments first."""

    def heights(parent):
        forest(parent)
        return raw["heights"](parent)

    def postorder(parent):
        forest(parent, postorder=True)
        return raw["postorder"](parent)

    def subtrees(parent, work):
        forest(parent)
        _size(work, np.size(parent), "work")
        return raw["subtrees"](parent, work)

    def relax(k, r, true_nnz, sparent, *rest):
        forest(sparent, "sparent")
        for a, name in ((k, "k"), (r, "r"), (true_nnz, "true_nnz")):
            if np.shape(a) != np.shape(sparent):
                raise PlanError(f"sparse engine: relax's {name} must have the shape of sparent")
        return raw["relax"](k, r, true_nnz, sparent, *rest)

    def stack_peak(seq, nchild, sizes):
        _range(_ints(seq, "seq"), 0, np.size(nchild), "seq")
        if np.size(sizes) != np.size(nchild):
            raise PlanError("sparse engine: sizes must have one entry per front")
        return raw["stack_peak"](seq, nchild, sizes)

    def push(src, off, size, stack, st_front, st_off, state, f):
        top = int(np.asarray(state).reshape(-1)[0]) if np.size(state) else -1
        if not 0 <= top < min(np.size(st_front), np.size(st_off) - 1):
            raise PlanError(f"sparse engine: update stack top {top} outside its arrays")
        off, size, o = int(off), int(size), int(st_off[top])
        if off < 0 or size < 0 or off + size > np.size(src):
            raise PlanError(f"sparse engine: push of src[{off}:{off + size}] beyond its {np.size(src)} entries")
        if o < 0 or o + size > np.size(stack):
            raise PlanError("sparse engine: the update does not fit on the stack")
        return raw["push"](src, off, size, stack, st_front, st_off, state, f)

    def pose_local(f, pos, fptr, rptr, rows):
        info = _fronts(1, fptr, rptr, rows)
        _range(_ints(f, "f"), 0, info["F"], "f")
        return raw["pose_local"](f, pos, fptr, rptr, rows)

    def block_map(prow, pcol, position, front_of, fptr, rptr, rows):
        info = _fronts(1, fptr, rptr, rows)
        d = info["d"]
        if np.size(position) != d or np.size(front_of) != d:
            raise PlanError(f"sparse engine: position and front_of must have {d} entries")
        _range(_ints(position, "position"), 0, d, "position")
        _range(_ints(front_of, "front_of"), 0, max(info["F"], 1), "front_of")
        _range(_ints(prow, "prow"), -1, d, "prow")
        _range(_ints(pcol, "pcol"), -1, d, "pcol")
        return raw["block_map"](prow, pcol, position, front_of, fptr, rptr, rows)

    def edge_matvec(A, B, t, h, x):
        d = np.shape(x)[0] if np.ndim(x) else 0
        _range(_ints(t, "tails"), -1, d, "tails")
        _range(_ints(h, "heads"), -1, d, "heads")
        return raw["edge_matvec"](A, B, t, h, x)

    def edge_rmatvec(A, B, t, h, r, d):
        _range(_ints(t, "tails"), -1, int(d), "tails")
        _range(_ints(h, "heads"), -1, int(d), "heads")
        if np.ndim(r) != 3 or np.shape(r)[:2] != np.shape(A)[:2]:
            raise PlanError(f"sparse engine: r of shape {np.shape(r)} does not match the edges {np.shape(A)}")
        return raw["edge_rmatvec"](A, B, t, h, r, d)

    def _frontal(b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, st_front, st_off, state,
                 Lptr=None):
        info = _fronts(b, fptr, rptr, Lptr=Lptr, rel=rel, nchild=nchild)
        top = _assembler(info, bptr, border, bli, blj, btr)
        key = ("blocks", id(info), int(b), id(bli))
        if key not in _KNOWN:
            _local_blocks(info, int(b), bli, blj, bptr)
            _remember(key, True, [bli])
        _edges(A, B, top, int(b))
        _size(F, info["maxD"] ** 2, "F")
        _stack(info, st_front, st_off, state)
        return info

    def assemble(f, b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, stack, st_front, st_off,
                 state):
        info = _frontal(b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, st_front, st_off, state)
        f = _front_no(f, info)
        _stack(info, st_front, st_off, state, pop=int(nchild[f]))
        return raw["assemble"](f, b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, stack,
                               st_front, st_off, state)

    def run(f0, f1, big, b, fptr, rptr, rel, nchild, Lptr, bptr, border, bli, blj, btr, A, B, L, F, stack,
            st_front, st_off, state, small_work, fn):
        info = _frontal(b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, st_front, st_off, state,
                        Lptr=Lptr)
        if not 0 <= int(f0) <= int(f1) <= info["F"]:
            raise PlanError(f"sparse engine: fronts {f0} … {f1} outside [0, {info['F']}]")
        _size(big, info["F"], "big")
        _size(L, info["Lsize"], "L")
        return raw["run"](f0, f1, big, b, fptr, rptr, rel, nchild, Lptr, bptr, border, bli, blj, btr, A, B, L, F,
                          stack, st_front, st_off, state, small_work, fn)

    def finish(f, b, fptr, rptr, Lptr, L, F, stack, st_front, st_off, state):
        info = _fronts(b, fptr, rptr, Lptr=Lptr)
        f = _front_no(f, info)
        _size(L, info["Lsize"], "L")
        _size(F, info["maxD"] ** 2, "F")
        _stack(info, st_front, st_off, state)
        return raw["finish"](f, b, fptr, rptr, Lptr, L, F, stack, st_front, st_off, state)

    def one(f, b, fptr, rptr, Lptr, L, F, D, fn):
        info = _fronts(b, fptr, rptr, Lptr=Lptr)
        f = _front_no(f, info)
        if int(D) != int(info["D"][f]):
            raise PlanError(f"sparse engine: front {f} has order {int(info['D'][f])}, not {int(D)}")
        _size(F, int(D) ** 2, "F")
        return raw["one"](f, b, fptr, rptr, Lptr, L, F, D, fn)

    def _sweep(name):
        def sweep(Y, seq, b, fptr, rptr, rows, Lptr, L, rmax):
            info = _fronts(b, fptr, rptr, rows=rows, Lptr=Lptr)
            _range(_ints(seq, "seq"), 0, info["F"], "seq")
            if np.ndim(Y) != 2 or np.shape(Y)[1] < info["d"] * int(b) or int(rmax) < info["rmax"]:
                raise PlanError(f"sparse engine: Y of shape {np.shape(Y)} or rmax {rmax} too small for the plan")
            _size(L, info["Lsize"], "L")
            return raw[name](Y, seq, b, fptr, rptr, rows, Lptr, L, rmax)
        return sweep

    out = dict(heights=heights, postorder=postorder, subtrees=subtrees, relax=relax, stack_peak=stack_peak, push=push,
               pose_local=pose_local, block_map=block_map, edge_matvec=edge_matvec, edge_rmatvec=edge_rmatvec,
               assemble=assemble, run=run, finish=finish, one=one, forward=_sweep("forward"),
               backward=_sweep("backward"), fn=raw["fn"])
    for name, fn in out.items():
        if name != "fn":  # each check stands for its kernel: same module, doc string, and the kernel itself
            fn.__module__, fn.__doc__, fn.__wrapped__ = raw[name].__module__, raw[name].__doc__, raw[name]
    missing = set(raw) - set(out)
    if missing:
        raise ImportError(f"kernel_checks: no check for {sorted(missing)}")
    return out
