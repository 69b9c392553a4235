r"""The compiled kernels of ``lago_cvx.sparse.compiled`` in C (``_ckernels.c``, built at install as an optional
extension module), called through ctypes: ``KERNELS`` has the keys, call signatures and results of
``compiled_kernels.KERNELS`` (Numba), and gives the same bits (the same loops in the same order; the C file is
compiled without fused multiply-add). It loads in a few milliseconds where Numba's import and cached kernels cost
about half a second per process (``compiled``'s docstring); Numba remains the engine's kernels when the C library
was not built (no compiler at install). Importing this module raises ImportError then; it never imports Numba.

Each wrapper checks the indices the C code reads (``kernel_checks``: the plan once, O(n), then each call in O(1))
and what else it relies on — the dtype (float64, int64, bool) and C order of every array, the
arrays written in place writable, the shapes of the edge blocks — and raises TypeError or ValueError otherwise;
nothing is copied. Arrays that a Numba kernel allocates (its results, its scratch) are allocated here, so the C
functions keep no state: threads may call them at once on different data (ctypes releases the GIL during a call).
LAPACK's ``dpotrf`` and BLAS's ``dtrsm``, ``dsyrk`` are SciPy's (``cython_lapack``/``cython_blas``), by address.
"""

from __future__ import annotations

import ctypes
import importlib.util

import numpy as np

from .kernel_checks import checked

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


def _fronts_args(b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B):
    m, q, _ = _edges(A, B, b)
    return (int(b), *_i(fptr=fptr, rptr=rptr, rel=rel, nchild=nchild, bptr=bptr, border=border, bli=bli, blj=blj),
            _p(btr, _BOOL, "transposed"), _p(A, _F64, "A"), _p(B, _F64, "B"), m, q)


def _stack(stack, st_front, st_off, state):
    """The addresses of a stack of updates: its entries, fronts, offsets and (1,) top."""
    return (_p(stack, _F64, "stack", True), _p(st_front, _I64, "st_front", True),
            _p(st_off, _I64, "st_off", True), _p(state, _I64, "state", True))


#: Each C function's result then its arguments, one letter each (i int64, d double, p pointer, - no result);
#: tests hold this table to the prototypes of _ckernels.c.
SIGNATURES = dict(assemble="iiipppppppppppiippppp", finish="-iippppppppp", run="iiipippppppppppppiippppppip",
                  one="iiippip", forward="-piipiippppppp", backward="-piipiippppppp", pose_local="-ppipppp",
                  block_count="ippippip", block_fill="-ppipppppipppppp", edge_matvec="-ppiiipppip",
                  edge_rmatvec="-ppiiipppip", stack_peak="ipippp", subtrees="-ppipp", push="ipiipipppi",
                  relax="-ppppiiiidddp", heights="-pip",
                  postorder="-pippp")
_C = {name: _c(name, sig) for name, sig in SIGNATURES.items()}


def assemble(f, b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, F, stack, st_front, st_off, state):
    """Front f's matrix in F (``compiled_kernels.assemble``). Returns D."""
    return _C["assemble"](int(f), *_fronts_args(b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B),
                          _p(F, _F64, "F", True), *_stack(stack, st_front, st_off, state))


def finish(f, b, fptr, rptr, Lptr, L, F, stack, st_front, st_off, state):
    """Keep front f's block column in L, push its update (``compiled_kernels.finish``)."""
    _C["finish"](int(f), int(b), *_i(fptr=fptr, rptr=rptr, Lptr=Lptr), _p(L, _F64, "L", True), _p(F, _F64, "F"),
                 *_stack(stack, st_front, st_off, state))


def run(f0, f1, big, b, fptr, rptr, rel, nchild, Lptr, bptr, border, bli, blj, btr, A, B, L, F, stack,
        st_front, st_off, state, small_work, fn):
    """Fronts f0 … f1 − 1 up to the first ``big`` one (``compiled_kernels.run``)."""
    args = _fronts_args(b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B)
    return _C["run"](int(f0), int(f1), _p(big, _BOOL, "big"), *args[:5], _p(Lptr, _I64, "Lptr"), *args[5:],
                     _p(L, _F64, "L", True), _p(F, _F64, "F", True), *_stack(stack, st_front, st_off, state),
                     int(small_work), _p(fn, _I64, "fn"))


def one(f, b, fptr, rptr, Lptr, L, F, D, fn):
    """A front assembled in F, by LAPACK/BLAS (``compiled_kernels.one``). Returns LAPACK's info."""
    return _C["one"](int(f), int(b), _p(fptr, _I64, "fptr"), _p(F, _F64, "F", True), int(D), _p(fn, _I64, "fn"))


def _sweep(kernel, Y, seq, b, fptr, rptr, rows, Lptr, L, rmax):
    if np.ndim(Y) != 2:
        raise ValueError(f"C kernels: Y must be (right-hand sides, slots), not of shape {np.shape(Y)}")
    y = _p(Y, _F64, "Y", True)
    n = max(int(rmax), 1)
    slot, t = np.empty(n, np.int64), np.empty(n)
    kernel(y, Y.shape[0], Y.shape[1], _p(seq, _I64, "seq"), seq.size, int(b),
           *_i(fptr=fptr, rptr=rptr, rows=rows, Lptr=Lptr), _p(L, _F64, "L"), slot.ctypes.data, t.ctypes.data)


def forward(Y, seq, b, fptr, rptr, rows, Lptr, L, rmax):
    """L z = y in place for Y (nrhs, slots) (``compiled_kernels.forward``)."""
    _sweep(_C["forward"], Y, seq, b, fptr, rptr, rows, Lptr, L, rmax)


def backward(Y, seq, b, fptr, rptr, rows, Lptr, L, rmax):
    """Lᵀ x = z in place for Y (nrhs, slots) (``compiled_kernels.backward``)."""
    _sweep(_C["backward"], Y, seq, b, fptr, rptr, rows, Lptr, L, rmax)


def pose_local(f, pos, fptr, rptr, rows):
    """Local pose index of position pos[t] in front f[t] (``compiled_kernels.pose_local``)."""
    if np.shape(pos) != np.shape(f):
        raise ValueError("C kernels: f and pos must have one shape")
    out = np.empty(np.size(f), np.int64)
    _C["pose_local"](*_i(f=f, pos=pos), out.size, *_i(fptr=fptr, rptr=rptr, rows=rows), out.ctypes.data)
    return out


def block_map(prow, pcol, position, front_of, fptr, rptr, rows):
    """(order, bptr, li, lj, transposed): ``compiled_kernels.block_map``."""
    if np.shape(pcol) != np.shape(prow):
        raise ValueError("C kernels: prow and pcol must have one shape")
    ends = _i(prow=prow, pcol=pcol)
    where = _i(position=position, front_of=front_of)
    nf = np.size(fptr) - 1
    bptr = np.empty(nf + 1, np.int64)
    n = _C["block_count"](*ends, prow.size, *where, nf, bptr.ctypes.data)
    order, li, lj = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    transposed, fill = np.empty(n, np.bool_), np.empty(max(nf, 1), np.int64)
    _C["block_fill"](*ends, prow.size, *where, *_i(fptr=fptr, rptr=rptr, rows=rows), nf, bptr.ctypes.data,
                     fill.ctypes.data, order.ctypes.data, li.ctypes.data, lj.ctypes.data, transposed.ctypes.data)
    return order, bptr, li, lj, transposed


def _operator_args(A, B, t, h, v, name):
    m, q, b = _edges(A, B)
    if np.shape(t) != (m,) or np.shape(h) != (m,):
        raise ValueError(f"C kernels: tails and heads must be ({m},)")
    if np.ndim(v) != 3:
        raise ValueError(f"C kernels: {name} must be 3-D, not of shape {np.shape(v)}")
    return m, q, b, (_p(A, _F64, "A"), _p(B, _F64, "B"), m, q, b, *_i(t=t, h=h), _p(v, _F64, name), v.shape[2])


def edge_matvec(A, B, t, h, x):
    """M x (m, q, nr) for x (d, b, nr) (``compiled_kernels.edge_matvec``)."""
    m, q, b, args = _operator_args(A, B, t, h, x, "x")
    if x.shape[1] != b:
        raise ValueError(f"C kernels: x must be (d, {b}, nr), not {x.shape}")
    out = np.empty((m, q, x.shape[2]))
    _C["edge_matvec"](*args, out.ctypes.data)
    return out


def edge_rmatvec(A, B, t, h, r, d):
    """Mᵀ r (d, b, nr) for r (m, q, nr) (``compiled_kernels.edge_rmatvec``)."""
    m, q, b, args = _operator_args(A, B, t, h, r, "r")
    if r.shape[:2] != (m, q):
        raise ValueError(f"C kernels: r must be ({m}, {q}, nr), not {r.shape}")
    out = np.zeros((int(d), b, r.shape[2]))
    _C["edge_rmatvec"](*args, out.ctypes.data)
    return out


def stack_peak(seq, nchild, sizes):
    """The most stack entries alive at once (``compiled_kernels.stack_peak``)."""
    lev = np.empty(np.size(seq) + 1, np.int64)
    return _C["stack_peak"](_p(seq, _I64, "seq"), seq.size, *_i(nchild=nchild, sizes=sizes), lev.ctypes.data)


def subtrees(parent, work):
    """(total work, first front) of each subtree (``compiled_kernels.subtrees``)."""
    n = np.size(parent)
    if np.shape(work) != (n,):
        raise ValueError("C kernels: work must be one value per front")
    total, first = np.empty(n), np.empty(n, np.int64)
    _C["subtrees"](_p(parent, _I64, "parent"), _p(work, _F64, "work"), n, total.ctypes.data, first.ctypes.data)
    return total, first


def push(src, off, size, stack, st_front, st_off, state, f):
    """Push ``src[off:off + size]`` onto this stack as front f's update (``compiled_kernels.push``)."""
    off, size = int(off), int(size)
    if off < 0 or size < 0 or off + size > np.size(src):
        raise ValueError(f"C kernels: push of src[{off}:{off + size}] beyond its {np.size(src)} entries")
    if _C["push"](_p(src, _F64, "src"), off, size, _p(stack, _F64, "stack", True), stack.size,
                  *_stack(stack, st_front, st_off, state)[1:], int(f)) != 0:
        raise ValueError("C kernels: the update does not fit on the stack")


def relax(k, r, true_nnz, sparent, n0, n1, n2, z0, z1, z2):
    """``supernodes.relax`` (``k``, ``true_nnz`` updated in place)."""
    top = np.empty(np.size(k), np.int64)
    if not (np.shape(r) == np.shape(true_nnz) == np.shape(sparent) == np.shape(k)):
        raise ValueError("C kernels: relax takes four arrays of one shape")
    _C["relax"](_p(k, _I64, "k", True), _p(r, _I64, "r"), _p(true_nnz, _I64, "true_nnz", True),
                _p(sparent, _I64, "sparent"), top.size, int(n0), int(n1), int(n2), float(z0), float(z1), float(z2),
                top.ctypes.data)
    return top


def heights(parent):
    """``supernodes.heights``."""
    h = np.empty(np.size(parent), np.int64)
    _C["heights"](_p(parent, _I64, "parent"), h.size, h.ctypes.data)
    return h


def postorder(parent):
    """``supernodes.postorder``."""
    n = np.size(parent)
    size, free, order = np.empty(n + 1, np.int64), np.empty(n + 1, np.int64), np.empty(n, np.int64)
    _C["postorder"](_p(parent, _I64, "parent"), n, size.ctypes.data, free.ctypes.data, order.ctypes.data)
    return order


def _addresses() -> np.ndarray:
    """(3,) int64: the addresses of SciPy's LAPACK ``dpotrf`` and BLAS ``dtrsm``, ``dsyrk`` — the capsules of
    ``cython_lapack``/``cython_blas``, opened by the C API (what Numba's ``get_cython_function_address`` does)."""
    from scipy.linalg import cython_blas, cython_lapack

    name = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object)(("PyCapsule_GetName", ctypes.pythonapi))
    pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_void_p)(
        ("PyCapsule_GetPointer", ctypes.pythonapi))
    out = []
    for module, fn in ((cython_lapack, "dpotrf"), (cython_blas, "dtrsm"), (cython_blas, "dsyrk")):
        capsule = module.__pyx_capi__[fn]
        out.append(pointer(capsule, name(capsule)))
    return np.array(out, np.int64)


#: The kernels by name (the keys of ``compiled_kernels.KERNELS``), and ``fn`` the LAPACK/BLAS addresses; each checks
#: the indices it reads first (``kernel_checks``: a malformed plan raises PlanError, never reaches the C code), and
#: so do this module's functions of the same names.
KERNELS = checked(dict(assemble=assemble, finish=finish, run=run, forward=forward, backward=backward,
               stack_peak=stack_peak, one=one, subtrees=subtrees, push=push, pose_local=pose_local,
               block_map=block_map, edge_matvec=edge_matvec, edge_rmatvec=edge_rmatvec, relax=relax,
               heights=heights, postorder=postorder, fn=_addresses()))
globals().update({name: fn for name, fn in KERNELS.items() if name != "fn"})
