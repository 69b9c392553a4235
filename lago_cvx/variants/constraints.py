r"""Named convex constraints on the poses (V9), for the cvxpy route of every variant.

``constrained_lago`` solves phases 1 and 3 as cvxpy problems to which a user function adds named
convex constraints through ``PoseVariables`` (affine expressions of every pose's x, y, θ):
``box_constraint``, ``polygon_constraint`` (convex polygon as half-planes nᵢᵀp ≤ cᵢ),
``orientation_bounds`` (lower ≤ θ_v − center_v ≤ upper). The same function is called in every phase and
by ``refine(constraints=...)`` with x, y, θ of length n (pose index order); phase 1 has θ only, so a
constraint on positions applies from phase 3 on (``collect_constraints``). Bare cvxpy constraints are
accepted; anything else is an ``OptionError`` naming it. An infeasible problem raises
``InfeasibleConstraintsError`` naming the constraints (``diagnose``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import GraphError, InfeasibleConstraintsError, OptionError
from ..posegraph import PoseGraph
from ..rounding import TWO_PI, branch
from ..solvers import INFEASIBLE_STATUSES

__all__ = ["NamedConstraint", "PoseVariables", "halfplane_constraint", "box_constraint", "polygon_constraint",
           "orientation_bounds", "diagnose", "collect_constraints"]

log = logging.getLogger("lago_cvx.variants")


@dataclass
class NamedConstraint:
    """A named group of cvxpy constraints (``constraints`` may be empty when the helper does not
    apply to the phase at hand, e.g. a position box in phase 1)."""

    name: str
    constraints: list = field(default_factory=list)


@dataclass(eq=False)
class PoseVariables:
    """Affine cvxpy expressions of every pose's coordinates, the same in every phase and in ``refine``.

    ``x``, ``y``, ``theta`` (n,) are indexed by pose *index* in graph order over all n poses (the anchor's
    or a known coordinate's entries constant); ``index(ids)`` converts pose ids (as in the file) to indices.
    ``phase`` 1 (variable θ ∈ ℝⁿ), 3 (variable [p; θ] ∈ ℝ³ⁿ) or ``"refine"`` (a Gauss–Newton step, ``exprs``
    given). Phase 1 has no positions: its ``x``, ``y`` are placeholder variables, and a constraint on them
    is deferred to the first phase that has them (phase 3, and ``refine``). ``theta_tree`` (n,) the branch
    on which θ lives (the regularized tree orientations; in ``refine`` the estimate's θ), handy as
    ``orientation_bounds(center=...)``."""

    graph: PoseGraph
    phase: object
    variable: object  # the phase's cvxpy Variable
    theta_tree: np.ndarray
    exprs: tuple | None = None  # (x, y, θ) expressions, when not read from ``variable``'s layout
    _placeholders: tuple | None = None

    @property
    def n(self) -> int:
        return self.graph.n_poses

    @property
    def placeholders(self) -> tuple:
        """The phase-1 stand-ins for x and y (empty in other phases)."""
        if self.phase != 1:
            return ()
        if self._placeholders is None:
            import cvxpy as cp

            self._placeholders = (cp.Variable(self.n, name="x"), cp.Variable(self.n, name="y"))
        return self._placeholders

    @property
    def x(self):
        if self.exprs is not None:
            return self.exprs[0]
        return self.placeholders[0] if self.phase == 1 else self.variable[0:2 * self.n:2]

    @property
    def y(self):
        if self.exprs is not None:
            return self.exprs[1]
        return self.placeholders[1] if self.phase == 1 else self.variable[1:2 * self.n:2]

    @property
    def theta(self):
        if self.exprs is not None:
            return self.exprs[2]
        return self.variable if self.phase == 1 else self.variable[2 * self.n:]

    def index(self, ids=None) -> np.ndarray:
        """Pose indices (k,) of the pose ``ids`` (all poses when None), vectorized."""
        if ids is None:
            return np.arange(self.n)
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        order = np.argsort(self.graph.ids)
        pos = np.searchsorted(self.graph.ids[order], ids)
        pos = np.minimum(pos, self.n - 1)
        idx = order[pos]
        bad = self.graph.ids[idx] != ids
        if bad.any():
            raise GraphError(f"no pose with id {int(ids[bad][0])}")
        return idx

    def position_selector(self, ids=None) -> sp.csr_matrix:
        """Sparse (2k × 3n) matrix G with G @ variable = [x_v1, y_v1, x_v2, …] (phase 3 only)."""
        idx = self.index(ids)
        k = idx.size
        cols = np.stack([2 * idx, 2 * idx + 1], 1).reshape(-1)
        return sp.csr_matrix((np.ones(2 * k), (np.arange(2 * k), cols)), shape=(2 * k, 3 * self.n))


def halfplane_constraint(pv: PoseVariables, normals, offsets, *, poses=None, name: str = "half-planes") -> NamedConstraint:
    """Every pose in ``poses`` (ids; all when None) satisfies nᵢᵀp ≤ cᵢ for every half-plane i:
    ``normals`` (h, 2), ``offsets`` (h,). One vectorized constraint of k·h rows (pose-major: row v·h + i is
    half-plane i at the v-th pose) on ``pv.x``, ``pv.y``: deferred from phase 1 to phase 3
    (``PoseVariables``), kept by ``refine``."""
    Nrm = np.atleast_2d(np.asarray(normals, dtype=float))
    c = np.atleast_1d(np.asarray(offsets, dtype=float))
    if Nrm.shape[1] != 2 or c.shape != (Nrm.shape[0],):
        raise OptionError(f"{name}: normals must be (h, 2) and offsets (h,)")
    import cvxpy as cp

    idx = pv.index(poses)
    k, h = idx.size, Nrm.shape[0]
    rows = np.arange(k * h)
    pose = np.repeat(np.arange(k), h)
    H = sp.csr_matrix((np.concatenate([np.tile(Nrm[:, 0], k), np.tile(Nrm[:, 1], k)]),
                       (np.concatenate([rows, rows]), np.concatenate([pose, k + pose]))), shape=(k * h, 2 * k))
    return NamedConstraint(name, [H @ cp.hstack([pv.x[idx], pv.y[idx]]) <= np.tile(c, k)])


def box_constraint(pv: PoseVariables, *, poses=None, xmin=-np.inf, xmax=np.inf, ymin=-np.inf, ymax=np.inf,
                   name: str = "box") -> NamedConstraint:
    """xmin ≤ x_v ≤ xmax and ymin ≤ y_v ≤ ymax for the poses ``poses`` (ids; all when None).
    Infinite bounds are omitted. On positions: from phase 3 on (``PoseVariables``)."""
    if not (xmin <= xmax and ymin <= ymax):
        log.info("%s: empty box (xmin > xmax or ymin > ymax)", name)
    normals, offsets = [], []
    for nrm, off in (((1, 0), xmax), ((-1, 0), -xmin), ((0, 1), ymax), ((0, -1), -ymin)):
        if np.isfinite(off):
            normals.append(nrm)
            offsets.append(off)
    if not normals:
        return NamedConstraint(name)
    return halfplane_constraint(pv, normals, offsets, poses=poses, name=name)


def polygon_constraint(pv: PoseVariables, vertices, *, poses=None, name: str = "polygon") -> NamedConstraint:
    """The poses ``poses`` (ids; all when None) stay in the convex polygon ``vertices`` (h, 2), given in
    either orientation: one half-plane nᵢᵀp ≤ nᵢᵀvᵢ per side, nᵢ the outward normal of side vᵢ → vᵢ₊₁.
    Raises ``ValueError`` if the polygon is not convex (or degenerate). On positions: from phase 3 on."""
    V = np.asarray(vertices, dtype=float)
    if V.ndim != 2 or V.shape[1] != 2 or V.shape[0] < 3:
        raise OptionError(f"{name}: a polygon needs (h ≥ 3, 2) vertices")
    E = np.roll(V, -1, axis=0) - V
    cross = E[:, 0] * np.roll(E, -1, axis=0)[:, 1] - E[:, 1] * np.roll(E, -1, axis=0)[:, 0]
    if not (np.all(cross > 0) or np.all(cross < 0)):
        raise OptionError(f"{name}: the polygon is not strictly convex")
    sign = 1.0 if cross[0] > 0 else -1.0  # counter-clockwise: outward normal is (e_y, −e_x)
    normals = sign * np.column_stack([E[:, 1], -E[:, 0]])
    return halfplane_constraint(pv, normals, np.einsum("ha,ha->h", normals, V), poses=poses, name=name)


def orientation_bounds(pv: PoseVariables, *, poses=None, lower=-np.inf, upper=np.inf, center=None,
                       name: str = "orientation bounds") -> NamedConstraint:
    """lower ≤ θ_v − center_v ≤ upper for the poses ``poses`` (ids; all when None). ``center`` (k,) or
    scalar: the nominal orientations (e.g. a compass heading), moved by 2πk onto the branch of
    ``pv.theta_tree`` like an orientation anchor (V4) — θ is unwrapped, and a center one turn away
    would silently force an extra winding; default None: bounds on θ itself, on the unwrapped branch — a
    warning is logged, since θ_tree may be several turns away from the bounds. Applies in phases 1 and 3
    and in ``refine``."""
    idx = pv.index(poses)
    if center is None and pv.phase in (1, "refine"):
        log.warning("%s: bounds on the unwrapped θ without center= (θ lives on the branch of the tree, "
                    "θ_tree in [%.3g, %.3g]); give center= (e.g. 0.0) to bound θ − center modulo 2π", name,
                    float(np.min(pv.theta_tree[idx])), float(np.max(pv.theta_tree[idx])))
    c = np.zeros(idx.size) if center is None else np.broadcast_to(np.asarray(center, dtype=float), idx.shape)
    if center is not None:  # bring the centers onto the branch of θ (as anchors are, V4)
        c = c + TWO_PI * branch(c, pv.theta_tree[idx])
    th = pv.theta[idx] - c
    out = []
    lo = np.broadcast_to(np.asarray(lower, dtype=float), idx.shape)
    hi = np.broadcast_to(np.asarray(upper, dtype=float), idx.shape)
    if np.isfinite(lo).any():
        f = np.isfinite(lo)
        out.append(th[np.flatnonzero(f)] >= lo[f]) if not f.all() else out.append(th >= lo)
    if np.isfinite(hi).any():
        f = np.isfinite(hi)
        out.append(th[np.flatnonzero(f)] <= hi[f]) if not f.all() else out.append(th <= hi)
    return NamedConstraint(name, out)


def _flatten(out, where: str, found: list) -> None:
    import cvxpy as cp

    if out is None:
        return
    if isinstance(out, NamedConstraint):
        found.append(out)
    elif isinstance(out, cp.constraints.constraint.Constraint):
        found.append(NamedConstraint(f"constraint {len(found)}", [out]))
    elif isinstance(out, (list, tuple)):
        for item in out:
            _flatten(item, where, found)
    else:
        raise OptionError(f"{where}: the constraint function returned {type(out).__name__} {out!r:.60}; expected "
                          "cvxpy constraints or NamedConstraint (a bool: compare cvxpy expressions, not numbers)")


def collect_constraints(fn, pv: PoseVariables, where: str) -> list:
    """The ``NamedConstraint``s of ``fn(pv)`` (or of ``fn`` itself when it is a list, a ``NamedConstraint`` or a
    cvxpy constraint) for the phase of ``pv``: bare cvxpy constraints are named ``"constraint i"``; in phase 1
    a constraint on the positions (the placeholders of ``PoseVariables``) is deferred to phase 3 (logged).
    ``OptionError`` naming the constraint when it is not a constraint, not convex (DCP), or constant."""
    found: list = []
    _flatten(fn(pv) if callable(fn) else fn, where, found)
    held = {v.id for v in pv.placeholders} if pv is not None else set()
    out = []
    for c in found:
        keep = []
        for k in c.constraints:
            if not k.is_dcp():
                raise OptionError(f"{where}: constraint {c.name!r} is not convex (not DCP): {k}")
            ids = {v.id for v in k.variables()}
            if not ids:
                raise OptionError(f"{where}: constraint {c.name!r} involves no pose variable: {k}")
            if ids & held:
                log.debug("%s: constraint %r is on positions; it applies from phase 3", where, c.name)
                continue
            keep.append(k)
        out.append(NamedConstraint(c.name, keep))
    return out


def _feasible(fixed: list, named: list, solve_fn) -> bool:
    import cvxpy as cp

    prob = cp.Problem(cp.Minimize(0), fixed + [k for c in named for k in c.constraints])
    return solve_fn(prob) not in INFEASIBLE_STATUSES


def diagnose(phase: str, fixed: list, named: list, solve_fn) -> None:
    """Name the constraints to blame and raise ``InfeasibleConstraintsError``: first those infeasible on
    their own (together with the anchor equalities ``fixed``), else an irreducible infeasible subset by a
    deletion filter (drop each constraint in turn, keep it only if the rest becomes feasible without
    it). ``solve_fn(problem)`` solves a cvxpy problem and returns its status."""
    alone = [c.name for c in named if not _feasible(fixed, [c], solve_fn)]
    if alone:
        which = ", ".join(repr(a) for a in alone)
        msg = (f"{phase}: constraint {which} is infeasible on its own (together with the anchors)" if len(alone) == 1
               else f"{phase}: constraints {which} are each infeasible on their own (together with the anchors)")
        raise InfeasibleConstraintsError(msg, alone, phase)
    keep = list(named)
    for c in list(named):  # deletion filter
        trial = [k for k in keep if k is not c]
        if not _feasible(fixed, trial, solve_fn):
            keep = trial
    names = [c.name for c in keep]
    raise InfeasibleConstraintsError(
        f"{phase}: constraints {', '.join(repr(n) for n in names)} are jointly infeasible (each is feasible "
        "alone; dropping any one of them makes the rest feasible)", names, phase)
