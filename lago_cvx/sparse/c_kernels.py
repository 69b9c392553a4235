r"""The kernels of ``compiled`` in C (``_ckernels.c``, an optional extension module built at install), called through
ctypes (which releases the GIL); importing this module raises ImportError when it was not built.

Each wrapper checks the dtype, C order and writability of every array and the shapes of the edge blocks (TypeError,
ValueError; nothing is copied), and through ``kernel_checks`` every index the C code reads: plan arrays in O(1) as
those of a checked layout, trees, sequences and edge ends handed over alone in full. Outputs and scratch are
allocated here: the C functions keep no state, so threads may call them at once on different data.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util

import numpy as np

from . import kernel_checks as chk

__all__ = ["KERNELS"]


def _library() -> ctypes.CDLL:
    spec = importlib.util.find_spec("lago_cvx.sparse._ckernels")
    if spec is None or not spec.origin:
        raise ImportError("the sparse engine's C kernels (lago_cvx/sparse/_ckernels.c) are not built")
    try:
        return ctypes.CDLL(spec.origin)
    except OSError as exc:
        raise ImportError(f"the sparse engine's C kernels cannot be loaded: {exc}") from exc


_LIB = _library()
_CODES = {"i": ctypes.c_int64, "d": ctypes.c_double, "p": ctypes.c_void_p, "-": None}


def _c(name: str, sig: str):
    """The C function ``ck_<name>`` with its result and argument types (``SIGNATURES``)."""
    try:
        fn = getattr(_LIB, "ck_" + name)
    except AttributeError as exc:
        raise ImportError(f"the C kernels' library has no ck_{name}: rebuild it") from exc
    fn.restype = _CODES[sig[0]]
    fn.argtypes = [_CODES[c] for c in sig[1:]]
    return fn


_F64, _I64, _BOOL = np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.bool_)


def _p(a, dtype: np.dtype, name: str, write: bool = False) -> int:
    """The address of array ``a`` once it is of ``dtype``, C-contiguous and (``write``) writable."""
    if not isinstance(a, np.ndarray) or a.dtype != dtype:
        got = f"{a.dtype} array" if isinstance(a, np.ndarray) else type(a).__name__
        raise TypeError(f"C kernels: {name} must be a {dtype} NumPy array, not {got}")
    if not a.flags.c_contiguous:
        raise ValueError(f"C kernels: {name} must be C-contiguous (the kernel reads it in place; no copy is made)")
    if write and not a.flags.writeable:
        raise ValueError(f"C kernels: {name} is written in place but is read-only")
    try:
        return ctypes.addressof(_BUFFER(a))  # a third of ``a.ctypes.data``'s time
    except (TypeError, ValueError):  # read-only, or empty
        return a.ctypes.data


_BUFFER = ctypes.c_char.from_buffer


def _i(**arrays):
    """The addresses of int64 arrays (read only), by name."""
    return [_p(a, _I64, name) for name, a in arrays.items()]


def _edges(A, B, b=None) -> tuple[int, int, int]:
    """(m, q, b) of the edge blocks A, B (m, q, b), checked alike (and b as given)."""
    if np.ndim(A) != 3 or np.shape(B) != np.shape(A) or (b is not None and np.shape(A)[2] != b):
        raise ValueError(f"C kernels: A and B must both be (m, q, b) arrays, b = {b}; got {np.shape(A)}, "
                         f"{np.shape(B)}")
    return np.shape(A)


#: Each C function's result then its arguments, one letter each (i int64, d double, p pointer, - no result);
#: tests hold this table to the prototypes of _ckernels.c.
SIGNATURES = dict(run="iiipippppppppppppiippppppip", forward="-piipiippppppp", backward="-piipiippppppp",
                  pose_local="-ppipppp", block_count="ippippip", block_fill="-ppipppppipppppp",
                  edge_matvec="-ppiiipppip", edge_rmatvec="-ppiiipppip", stack_peak="ipippp", subtrees="-ppipp",
                  relax="-ppppiiiidddp", postorder="-pippp")
_C = {name: _c(name, sig) for name, sig in SIGNATURES.items()}


def run(f0, f1, big, b, fptr, rptr, rel, nchild, Lptr, bptr, border, bli, blj, btr, A, B, L, F, stack,
        st_front, st_off, state, small_work, fn):
    """Fronts f0 … f1 − 1 up to the first ``big`` one, each assembled in F (N's blocks, then its children's updates
    popped), factored (LAPACK/BLAS at ``fn`` once k·D² ≥ ``small_work``), kept in L, its update pushed. Returns
    where it stopped, −1 − f if front f is not SPD."""
    m, q, _ = _edges(A, B, b)
    args = (_p(big, _BOOL, "big"), int(b), *_i(fptr=fptr, rptr=rptr, rel=rel, nchild=nchild, Lptr=Lptr, bptr=bptr,
                                                border=border, bli=bli, blj=blj),
            _p(btr, _BOOL, "transposed"), _p(A, _F64, "A"), _p(B, _F64, "B"), m, q, _p(L, _F64, "L", True),
            _p(F, _F64, "F", True), _p(stack, _F64, "stack", True), _p(st_front, _I64, "st_front", True),
            _p(st_off, _I64, "st_off", True), _p(state, _I64, "state", True), int(small_work), _p(fn, _I64, "fn"))
    info, top = chk.arrays(b, fptr, rptr=rptr, rel=rel, nchild=nchild, Lptr=Lptr), int(state[0]) if state.size else -1
    chk.need(0 <= int(f0) <= int(f1) <= info["F"] and np.size(big) >= info["F"] and np.size(L) >= info["Lsize"]
             and np.size(fn) == 3 and np.size(bptr) == info["F"] + 1 and int(bptr[-1]) == np.size(border)
             and (not np.size(border) or int(np.max(border)) < 3 * m) and np.size(F) >= info["maxD"] ** 2
             and np.size(st_front) >= info["F"] + 1 and np.size(st_off) >= info["F"] + 2 and 0 <= top <= info["F"],
             f"fronts {f0} … {f1}, the assembler, the buffers or the stack top {top} do not fit the plan")
    return _C["run"](int(f0), int(f1), *args)


def _sweep(kernel, Y, seq, b, fptr, rptr, rows, Lptr, L, rmax):
    """L z = y (``forward``) or Lᵀ x = z (``backward``) in place for Y (nrhs, slots), fronts in the order ``seq``."""
    if np.ndim(Y) != 2:
        raise ValueError(f"C kernels: Y must be (right-hand sides, slots), not of shape {np.shape(Y)}")
    y, sq = _p(Y, _F64, "Y", True), _p(seq, _I64, "seq")
    info = chk.arrays(b, fptr, rptr=rptr, rows=rows, Lptr=Lptr)
    chk.ints(seq, "seq", 0, info["F"])
    chk.need(Y.shape[1] >= info["d"] * int(b) and int(rmax) >= info["rmax"] and np.size(L) >= info["Lsize"],
             f"Y of shape {Y.shape}, rmax {rmax} or L too small for the plan")
    n = max(int(rmax), 1)
    slot, t = np.empty(n, np.int64), np.empty(n)
    kernel(y, Y.shape[0], Y.shape[1], sq, seq.size, int(b),
           *_i(fptr=fptr, rptr=rptr, rows=rows, Lptr=Lptr), _p(L, _F64, "L"), slot.ctypes.data, t.ctypes.data)


forward, backward = functools.partial(_sweep, _C["forward"]), functools.partial(_sweep, _C["backward"])


def pose_local(f, pos, fptr, rptr, rows):
    """Local pose index of position pos[t] in front f[t]."""
    if np.shape(pos) != np.shape(f):
        raise ValueError("C kernels: f and pos must have one shape")
    addresses = _i(f=f, pos=pos, fptr=fptr, rptr=rptr, rows=rows)
    F, d = chk.fronts(fptr, rptr, rows)
    chk.ints(f, "f", 0, F)
    chk.ints(pos, "pos", 0, max(d, 1))
    out = np.empty(np.size(f), np.int64)
    _C["pose_local"](*addresses[:2], out.size, *addresses[2:], out.ctypes.data)
    return out


def block_map(prow, pcol, position, front_of, fptr, rptr, rows):
    """(order, bptr, li, lj, transposed) (the map from N's blocks to their fronts)."""
    if np.shape(pcol) != np.shape(prow):
        raise ValueError("C kernels: prow and pcol must have one shape")
    ends = _i(prow=prow, pcol=pcol)
    where = _i(position=position, front_of=front_of)
    addresses = _i(fptr=fptr, rptr=rptr, rows=rows)
    nf, d = chk.fronts(fptr, rptr, rows)
    chk.need(np.size(position) == d and np.size(front_of) == d, f"position and front_of must have {d} entries")
    chk.ints(position, "position", 0, max(d, 1))
    chk.ints(front_of, "front_of", 0, max(nf, 1))
    chk.ints(prow, "prow", -1, d)
    chk.ints(pcol, "pcol", -1, d)
    bptr = np.empty(nf + 1, np.int64)
    n = _C["block_count"](*ends, prow.size, *where, nf, bptr.ctypes.data)
    order, li, lj = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    transposed, fill = np.empty(n, np.bool_), np.empty(max(nf, 1), np.int64)
    _C["block_fill"](*ends, prow.size, *where, *addresses, nf, bptr.ctypes.data,
                     fill.ctypes.data, order.ctypes.data, li.ctypes.data, lj.ctypes.data, transposed.ctypes.data)
    return order, bptr, li, lj, transposed


def _operator_args(A, B, t, h, v, name, d=0):
    m, q, b = _edges(A, B)
    if np.shape(t) != (m,) or np.shape(h) != (m,):
        raise ValueError(f"C kernels: tails and heads must be ({m},)")
    if np.ndim(v) != 3:
        raise ValueError(f"C kernels: {name} must be 3-D, not of shape {np.shape(v)}")
    d = np.shape(v)[0] if name == "x" else d
    chk.ints(t, "tails", -1, d)
    chk.ints(h, "heads", -1, d)
    return m, q, b, (_p(A, _F64, "A"), _p(B, _F64, "B"), m, q, b, *_i(t=t, h=h), _p(v, _F64, name), v.shape[2])


def edge_matvec(A, B, t, h, x):
    """M x (m, q, nr) for x (d, b, nr)."""
    m, q, b, args = _operator_args(A, B, t, h, x, "x")
    if x.shape[1] != b:
        raise ValueError(f"C kernels: x must be (d, {b}, nr), not {x.shape}")
    out = np.empty((m, q, x.shape[2]))
    _C["edge_matvec"](*args, out.ctypes.data)
    return out


def edge_rmatvec(A, B, t, h, r, d):
    """Mᵀ r (d, b, nr) for r (m, q, nr)."""
    m, q, b, args = _operator_args(A, B, t, h, r, "r", int(d))
    if r.shape[:2] != (m, q):
        raise ValueError(f"C kernels: r must be ({m}, {q}, nr), not {r.shape}")
    out = np.zeros((int(d), b, r.shape[2]))
    _C["edge_rmatvec"](*args, out.ctypes.data)
    return out


def stack_peak(seq, nchild, sizes):
    """The most stack entries alive at once."""
    lev = np.empty(np.size(seq) + 1, np.int64)
    args = (_p(seq, _I64, "seq"), np.size(seq), *_i(nchild=nchild, sizes=sizes), lev.ctypes.data)
    chk.ints(seq, "seq", 0, np.size(nchild))
    chk.need(np.size(sizes) == np.size(nchild), "sizes must have one entry per front")
    return _C["stack_peak"](*args)


def subtrees(parent, work):
    """(total work, first front) of each subtree."""
    n = np.size(parent)
    if np.shape(work) != (n,):
        raise ValueError("C kernels: work must be one value per front")
    chk.forest(parent)
    total, first = np.empty(n), np.empty(n, np.int64)
    _C["subtrees"](_p(parent, _I64, "parent"), _p(work, _F64, "work"), n, total.ctypes.data, first.ctypes.data)
    return total, first


def relax(k, r, true_nnz, sparent, n0, n1, n2, z0, z1, z2):
    """``multifrontal.relax`` (``k``, ``true_nnz`` updated in place)."""
    top = np.empty(np.size(k), np.int64)
    if not (np.shape(r) == np.shape(true_nnz) == np.shape(sparent) == np.shape(k)):
        raise ValueError("C kernels: relax takes four arrays of one shape")
    chk.forest(sparent, "sparent")
    _C["relax"](_p(k, _I64, "k", True), _p(r, _I64, "r"), _p(true_nnz, _I64, "true_nnz", True),
                _p(sparent, _I64, "sparent"), top.size, int(n0), int(n1), int(n2), float(z0), float(z1), float(z2),
                top.ctypes.data)
    return top


def postorder(parent):
    """``multifrontal.postorder``."""
    n = np.size(parent)
    size, free, order = np.empty(n + 1, np.int64), np.empty(n + 1, np.int64), np.empty(n, np.int64)
    address = _p(parent, _I64, "parent")
    chk.forest(parent, postorder=True)
    _C["postorder"](address, n, size.ctypes.data, free.ctypes.data, order.ctypes.data)
    return order


def _addresses() -> np.ndarray:
    """(3,) int64: the addresses of SciPy's LAPACK ``dpotrf`` and BLAS ``dtrsm``, ``dsyrk`` — the capsules of
    ``cython_lapack``/``cython_blas``, opened by the C API."""
    from scipy.linalg import cython_blas, cython_lapack

    name = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object)(("PyCapsule_GetName", ctypes.pythonapi))
    pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_void_p)(
        ("PyCapsule_GetPointer", ctypes.pythonapi))
    out = []
    for module, fn in ((cython_lapack, "dpotrf"), (cython_blas, "dtrsm"), (cython_blas, "dsyrk")):
        capsule = module.__pyx_capi__[fn]
        out.append(pointer(capsule, name(capsule)))
    return np.array(out, np.int64)


#: The kernels by name, and ``fn`` the LAPACK/BLAS addresses.
KERNELS = dict(run=run, forward=forward, backward=backward, stack_peak=stack_peak, subtrees=subtrees,
               pose_local=pose_local, block_map=block_map, edge_matvec=edge_matvec, edge_rmatvec=edge_rmatvec,
               relax=relax, postorder=postorder, fn=_addresses())
