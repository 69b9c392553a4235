r"""The engine behind every variant: LAGO's three phases over all coordinates with a set of them known
(V1–V8), run as a sequence of small steps on one ``VariantOptions``.

Frame (gauge) decision. The reference pose (``anchor=`` if given, else the first full anchor, else
the first anchor with a known orientation, else the first anchor, else the first prior, else the
smallest id) roots the spanning tree. Orientation: fixed by the orientation anchors, else by the
priors; else, with ≥ 2 position anchors, a provisional LAGO in the reference's frame (θ_ref = 0) is
rotated onto the anchored positions (2-D Kabsch, equal weights) and θ_ref := that angle is held as a
*gauge* (not an anchor: never reported as strained); else θ_ref := ``anchor_pose[2]`` (default 0,
the usual LAGO frame). Position: fixed by the position anchors or the priors, else
p_ref := ``anchor_pose[:2]`` (default the origin). With ``anchors={}`` and no priors this is exactly
plain LAGO.

Phase 1 (V5) carries the priors' marginal θ part; phase 2 (V6) uses the anchored, prior-informed
phase-1 information; phase 3 (V7) the conditional (x, y, θ) part of each prior (V8: every prior is
counted once). With a robust loss (V10) every edge can be re-rounded against the robust phase-1
estimate (``reround``), and phase 2 uses the IRLS-weighted phase-1 information.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from ..errors import GraphError, OptionError, check_choice
from ..graph import spanning_tree
from ..metrics import alignment_angle, chi2
from ..phases import Phase1, Phase3
from ..posegraph import PoseGraph
from ..positions import Polish, Positions, polish
from ..regularization import regularize
from ..reports import short_repr
from ..result import LagoResult
from ..rounding import AMBIGUITY_MARGIN, TWO_PI
from ..sparse import marginal_blocks
from ..solvers import LEAST_SQUARES, ROBUST, ClarabelSettings, IntegerSearch, check_method
from ..uncertainty import INFORMATION_MODES, edge_uncertainty
from .anchors import (AnchorRegularization, anchor_regularization, choose_reference, normalize_anchors,
                      normalize_priors, prior_arrays, reround_edges)
from .constraints import PoseVariables
from .strain import STRAIN_LEVEL, strain_report
from .systems import (DEFAULT_THRESHOLD, LOSSES, SystemSolution, WeightedSystem, anchored_phase2, phase1_system,
                      phase3_system, position_system, solve_system, solve_system_cvxpy)

__all__ = ["VariantOptions", "VariantPhase1", "VariantPhase3", "VariantResult", "lago_variant", "run_variant"]

log = logging.getLogger("lago_cvx.variants")

#: Phase 3 moving an orientation further than this (rad) from phase 1 is logged as a warning.
THETA_MOVE_WARNING = 0.3


@dataclass(frozen=True)
class VariantOptions:
    """Everything a variant run is told (see ``lago_variant`` for each field)."""

    anchors: object = None
    priors: object = None
    constraints_fn: Callable | None = None
    loss: str = "l2"
    threshold: float = DEFAULT_THRESHOLD
    grouping: str = "edge"
    method: str = "closed_form"
    spanning_tree: object = "bfs"
    anchor: int | None = None
    anchor_pose: object = None
    margin: float = AMBIGUITY_MARGIN
    reround: bool = False
    reround_rounds: int = 5
    strain_level: float = STRAIN_LEVEL
    solver_settings: ClarabelSettings | None = None
    backend: str = "auto"
    regularization: str = "chordal"
    information: str = "full"
    positions: str = "phase3"
    route: str = "custom"
    integer_search: IntegerSearch | None = None
    progress: Callable | None = None

    @property
    def use_cvxpy(self) -> bool:
        return self.method == "cvxpy" or self.loss != "l2" or self.constraints_fn is not None

    @property
    def preset(self) -> ClarabelSettings:
        return LEAST_SQUARES if self.loss == "l2" else ROBUST


# =============================================================================== results
@dataclass(frozen=True, eq=False)
class VariantPhase1(Phase1):
    """Phase-1 result of a variant, a ``Phase1`` in the output frame: ``theta`` (n,); ``theta_free``
    (d_θ,); ``info`` (d_θ, d_θ) LᵀL; ``anchor_index`` the reference pose; ``factor``/``stats`` of the
    closed form; plus ``free`` (d_θ,) the poses of unknown orientation, ``system`` and ``solution``."""

    free: np.ndarray = None
    system: WeightedSystem = None
    solution: SystemSolution = None

    def variances(self) -> np.ndarray:
        """Marginal variances of θ̂ (n,), 0 at known orientations: diag(LᵀL)⁻¹ by selected inversion
        (``known_blocks``)."""
        known = np.ones(self.theta.size, bool)
        known[self.free] = False
        if not self.free.size:
            return np.zeros(self.theta.size)
        return known_blocks(self.info, known, np.arange(self.theta.size)[:, None])[:, 0, 0]


def known_blocks(info: sp.spmatrix, known: np.ndarray, coord: np.ndarray, *, progress=None) -> np.ndarray:
    r"""Diagonal blocks of N_U⁻¹ per pose, zeros at known coordinates, by selected inversion.

    ``info`` N_U = M_UᵀM_U (d_U, d_U) over the unknown coordinates (in order of ``~known``); ``known``
    (N,) bool over all coordinates; ``coord`` (n, b) the coordinates of each pose. With Π the embedding of
    the unknown coordinates into ℝᴺ and E_K that of the known ones,

        N̄ = Π N_U Πᵀ + E_K E_Kᵀ   (N × N),     N̄⁻¹ = Π N_U⁻¹ Πᵀ + E_K E_Kᵀ,

    since the two terms act on complementary coordinates. N̄ has the pose graph's pattern with b
    coordinates per pose, so the pose-level multifrontal factor and its selected inversion (eq. (T) of
    ``lago_cvx.sparse.multifrontal``, via ``sparse.marginal_blocks``) give its b×b diagonal blocks in
    one pass — as the unanchored ``Phase3.pose_covariances`` — instead of one column solve per
    coordinate. Returns (n, b, b): the blocks of N_U⁻¹, with the rows and columns of known coordinates
    zeroed."""
    known = np.asarray(known, bool)
    N = known.size
    upos = np.flatnonzero(~known)
    kpos = np.flatnonzero(known)
    C = sp.coo_matrix(info)
    full = sp.csr_matrix((np.r_[C.data, np.ones(kpos.size)],
                          (np.r_[upos[C.row], kpos], np.r_[upos[C.col], kpos])), shape=(N, N))
    blocks = marginal_blocks(full, coord, progress=progress)
    free = ~known[coord]  # (n, b)
    return blocks * (free[:, :, None] & free[:, None, :])


@dataclass(frozen=True, eq=False)
class VariantPhase3(Phase3):
    """Phase-3 result of a variant, a ``Phase3``: ``x_star`` (d_U,) the unknown coordinates; ``poses``
    (n, 3) in the output frame; ``info`` (d_U, d_U); ``anchor_index``; ``factor``/``stats``; plus ``x``
    (3n,) all coordinates [p; θ], ``system`` and ``solution``."""

    x: np.ndarray = None
    system: WeightedSystem = None
    solution: SystemSolution = None

    def pose_covariances(self, *, progress=None) -> np.ndarray:
        """Marginal 3×3 covariance (n, 3, 3) of every pose (x, y, θ), zeros at known coordinates: the
        diagonal pose blocks of (M_UᵀM_U)⁻¹ by selected inversion (``known_blocks``), the unanchored
        route's method. ``progress`` an optional ``lago_cvx.progress.ProgressCallback``."""
        n = self.poses.shape[0]
        coord = np.stack([2 * np.arange(n), 2 * np.arange(n) + 1, 2 * n + np.arange(n)], 1)  # (n, 3)
        if n == 1 or self.system.known.all():
            return np.zeros((n, 3, 3))
        return known_blocks(self.info, self.system.known, coord, progress=progress)


@dataclass(eq=False)
class VariantResult(LagoResult):
    """A ``LagoResult`` of a constrained variant: every attribute of a plain result works; everything is
    in the output frame (``phase1.theta`` and ``poses`` directly, ``anchor_pose`` = the reference's pose).
    Extra fields: ``anchors`` (list of ``Anchor``), ``priors`` (list of ``Prior``), ``loss``, ``frame``
    (how orientation/position were fixed), ``anchor_regularization``, ``strain`` (list of
    ``AnchorStrain``; None for robust or inequality-constrained runs, where the least-squares test does
    not apply), ``constraint_names``, ``robust`` (dict: ``edge_weights`` (m,) the smaller of the two
    phases' IRLS weights, ``rounds`` re-rounding rounds, ``k_changed``)."""

    anchors: list = field(default_factory=list)
    priors: list = field(default_factory=list)
    loss: str = "l2"
    frame: dict = field(default_factory=dict)
    anchor_regularization: AnchorRegularization | None = None
    strain: list | None = None
    constraint_names: list = field(default_factory=list)
    robust: dict | None = None

    @property
    def orientations(self) -> np.ndarray:
        return self.phase1.theta

    def __repr__(self) -> str:
        head, lines = self._describe()
        strained = self.strained
        shown = ", ".join(str(i) for i in strained[:5]) + (f", … ({len(strained)} in all)" if len(strained) > 5 else "")
        lines.insert(2, f"{len(self.anchors)} anchors, {len(self.priors)} priors, loss {self.loss}; strained "
                        f"anchors: {shown or 'none'}")
        return short_repr(type(self).__name__, head, lines)

    def pose_covariances(self, *, progress=None) -> np.ndarray:
        return self.phase3.pose_covariances(progress=progress)

    @property
    def strained(self) -> list:
        """Ids of the strained anchors."""
        return [s.id for s in (self.strain or []) if s.strained]

    def prior_chi2(self) -> np.ndarray:
        """eᵀΛe per prior at the final poses (e = pose − mean, θ on the rounded branch), shape (q,)."""
        out = []
        for p in self.priors:
            e = np.where(p.known, self.poses[p.index] - p.mean, 0.0)
            e[2] = (e[2] + np.pi) % TWO_PI - np.pi
            out.append(float(e @ p.information @ e))
        return np.array(out)


# =============================================================================== the steps
@dataclass
class _State:
    """What the steps hand on: the known values and everything computed so far."""

    graph: PoseGraph
    opts: VariantOptions
    anchors: list
    priors: list
    ref: int
    gauge_pose: np.ndarray
    frame: dict
    timings: dict
    theta_gauge: float | None = None
    pos_gauge: bool = False


def _frame(st: _State) -> None:
    """Decide how the orientation and the position are fixed (module docstring, frame decision)."""
    g, anc, pri = st.graph, st.anchors, st.priors
    th_anc = [a for a in anc if a.theta is not None]
    pos_anc = [a for a in anc if a.position is not None]
    th_pri = [p for p in pri if p.has_theta]
    pos_pri = [p for p in pri if p.has_position]  # position (GPS) priors fix the frame as position anchors do
    ref_id = int(g.ids[st.ref])
    st.frame["reference"] = ref_id
    if not th_anc and not th_pri and len(pos_anc) + len(pos_pri) >= 2:
        prov = run_variant(g, replace(st.opts, anchors={ref_id: (0.0, 0.0, 0.0)}, priors=None, constraints_fn=None,
                                      anchor=None))
        idx = np.array([a.index for a in pos_anc] + [p.index for p in pos_pri])
        target = np.array([a.position for a in pos_anc] + [p.mean[:2] for p in pos_pri]).reshape(-1, 2)
        st.theta_gauge = alignment_angle(prov.poses[idx, :2], target)
        st.frame["orientation"] = (f"procrustes: provisional LAGO rotated by {st.theta_gauge:.6g} rad onto "
                                   f"{len(idx)} known positions")
    elif not th_anc and not th_pri:
        st.theta_gauge = float(st.gauge_pose[2])
        st.frame["orientation"] = f"gauge: θ of pose {ref_id} := {st.theta_gauge:.6g}"
    else:
        st.frame["orientation"] = "anchors" if th_anc else "priors"
    st.pos_gauge = not pos_anc and not pos_pri
    st.frame["position"] = (f"gauge: position of pose {ref_id} := ({st.gauge_pose[0]:.6g}, {st.gauge_pose[1]:.6g})"
                            if st.pos_gauge else ("anchors" if pos_anc else "priors"))


def _regularize(st: _State):
    """Tree, 2kπ regularization of the edges, and of the anchored / prior orientations (V4).
    Returns (tree, reg, areg, th_known (n,), th_vals (n,), prior arrays)."""
    g, o = st.graph, st.opts
    t = time.perf_counter()
    tree = _resolve_tree(g, o.spanning_tree, st.ref)
    st.timings["tree"] = time.perf_counter() - t
    t = time.perf_counter()
    reg = regularize(g, tree, regularization=o.regularization, margin=o.margin, method=o.method, backend=o.backend,
                     settings=o.solver_settings, search=o.integer_search, progress=o.progress)
    tt0 = reg.reference  # 0 at the root: θ_tree (tree rounding) or the chordal φ̃, the branch δ_reg follows
    th_anc = sorted((a for a in st.anchors if a.theta is not None), key=lambda a: a.index != st.ref)
    pri = sorted((p for p in st.priors if p.has_theta), key=lambda p: p.index != st.ref)  # reference's first
    if th_anc:
        offset, offset_from = th_anc[0].theta - tt0[th_anc[0].index], f"anchor {th_anc[0].id}"
    elif pri:
        offset, offset_from = pri[0].mean[2] - tt0[pri[0].index], f"prior {pri[0].id}"
    else:
        offset, offset_from = st.theta_gauge, st.frame["orientation"].split(":")[0]
    th_anc = [a for a in st.anchors if a.theta is not None]  # given order again
    a_idx = np.array([a.index for a in th_anc] + [p.index for p in st.priors], np.int64)
    a_src = np.array(["anchor"] * len(th_anc) + ["prior"] * len(st.priors))
    # a prior without θ keeps its (unused, weight 0) mean on the tree's branch
    a_val = np.array([a.theta for a in th_anc] + [p.mean[2] if p.has_theta else tt0[p.index] + offset
                                                   for p in st.priors], float)
    areg = anchor_regularization(g, tt0, a_idx, a_src, a_val, offset, offset_from, o.margin)
    reg = replace(reg, theta_tree=areg.theta_tree)
    nt = len(th_anc)
    th_known, th_vals = np.zeros(g.n_poses, bool), np.zeros(g.n_poses)
    th_known[a_idx[:nt]] = True
    th_vals[a_idx[:nt]] = areg.corrected[:nt]
    if not th_anc and not any(p.has_theta for p in st.priors):
        th_known[st.ref], th_vals[st.ref] = True, st.theta_gauge
    st.timings["regularization"] = time.perf_counter() - t
    return tree, reg, areg, th_known, th_vals, prior_arrays(st.priors, areg.corrected[nt:])


def _solve(st: _State, system: WeightedSystem, level: int, theta_tree: np.ndarray) -> SystemSolution:
    """One phase's system: closed form, or cvxpy with the loss and the user's named constraints."""
    o = st.opts
    if not o.use_cvxpy:
        return solve_system(system, backend=o.backend)
    return solve_system_cvxpy(system, loss=o.loss, threshold=o.threshold, grouping=o.grouping,
                              constraints=o.constraints_fn,
                              pose_variables=lambda x: PoseVariables(st.graph, level, x, theta_tree),
                              settings=o.solver_settings, preset=o.preset)


def _phase1(st: _State, reg, unc, th_known, th_vals, pr, theta_tree):
    """Phase 1 (V5), and with ``reround`` the re-rounding of every edge against its estimate (V10).
    Returns (system, solution, reg (with the final δ_reg), rounds, k_changed)."""
    g, o = st.graph, st.opts
    delta_reg = reg.delta_reg
    sys1 = phase1_system(g, delta_reg, unc, th_known, th_vals, pr)
    sol1 = _solve(st, sys1, 1, theta_tree)
    rounds = k_changed = 0
    if o.reround:
        for rounds in range(1, o.reround_rounds + 1):
            new_dreg, _ = reround_edges(g, sol1.x)
            changed = int(np.count_nonzero(np.rint((new_dreg - delta_reg) / TWO_PI)))
            if changed == 0:
                rounds -= 1
                break
            k_changed += changed
            log.info("re-rounding against the phase-1 estimate: %d edge(s) changed k (round %d)", changed, rounds)
            delta_reg = new_dreg
            sys1 = phase1_system(g, delta_reg, unc, th_known, th_vals, pr)
            sol1 = _solve(st, sys1, 1, theta_tree)
        reg = replace(reg, delta_reg=delta_reg, k=np.rint((delta_reg - g.delta) / TWO_PI).astype(np.int64))
    return sys1, sol1, reg, rounds, k_changed


def _phase3_known(st: _State, th_known, th_vals) -> tuple[np.ndarray, np.ndarray]:
    """The known coordinates (3n,) of phase 3 (positions of anchors or the gauge, known orientations)."""
    n = st.graph.n_poses
    known3, vals3 = np.zeros(3 * n, bool), np.zeros(3 * n)
    for a in st.anchors:  # loop over anchors (few), not edges
        if a.position is not None:
            known3[2 * a.index:2 * a.index + 2] = True
            vals3[2 * a.index:2 * a.index + 2] = a.position
    if st.pos_gauge:
        known3[2 * st.ref:2 * st.ref + 2] = True
        vals3[2 * st.ref:2 * st.ref + 2] = st.gauge_pose[:2]
    known3[2 * n:], vals3[2 * n:] = th_known, th_vals
    return known3, vals3


def _robust_summary(st: _State, systems, rounds: int, k_changed: int) -> dict | None:
    """IRLS edge weights of a robust run (the smaller of the two phases'), None for least squares."""
    if st.opts.loss == "l2":
        return None
    w = np.ones(st.graph.n_edges)
    for s, sol in systems:
        g = s.groups >= 0
        np.minimum.at(w, s.groups[g], sol.weights[g])
    return {"edge_weights": w, "rounds": rounds, "k_changed": k_changed, "threshold": st.opts.threshold,
            "grouping": st.opts.grouping}


def _polish(st: _State, theta_hat, theta_star, unc, known_p, vals_p, pr, problems) -> Polish:
    """The position polish of a least-squares variant: positions re-solved for the orientations with the
    known positions held and the priors' conditional parts (``systems.position_system``), guarded by
    phase 1's orientations (``lago_cvx.positions.polish``, objective χ² plus the priors' eᵀΛe)."""
    g, o = st.graph, st.opts
    n = g.n_poses

    def objective(poses):
        e_th = poses[pr.index, 2] - pr.mean[:, 2]
        e_p = poses[pr.index, :2] - pr.mean[:, :2] + pr.h * e_th[:, None]
        return chi2(g, poses) + float(np.sum(np.einsum("qab,qb->qa", pr.C, e_p) ** 2) +
                                      np.sum((e_th / pr.sigma_theta) ** 2))

    def solve_positions(theta):
        sys_ = position_system(g, theta, unc, known_p, vals_p, pr)
        if o.method == "cvxpy":
            sol = solve_system_cvxpy(sys_, settings=o.solver_settings)
            problems["positions"] = sol.problem
        else:
            sol = solve_system(sys_, backend=o.backend)
        poses = np.column_stack([sol.x[0:2 * n:2], sol.x[1:2 * n:2], theta])
        return Positions(poses, sol.info, st.ref, sol.factor, sol.stats)

    return polish(g, theta_hat, theta_star, unc, solve_positions=solve_positions, objective=objective)


def _resolve_tree(graph: PoseGraph, kind, ref: int):
    """The spanning tree rooted at index ``ref``; ``"auto"``: odometric if the chain is complete, else BFS."""
    ref_id = int(graph.ids[ref])
    if isinstance(kind, str) and kind == "auto":
        try:
            return spanning_tree(graph, "odometry", anchor=ref_id)
        except GraphError as exc:
            log.warning("robust LAGO: no complete odometric chain (%s); using the BFS tree — the re-rounding "
                        "against the robust phase-1 estimate must then undo false loop closures in the tree", exc)
            return spanning_tree(graph, "bfs", anchor=ref_id)
    return spanning_tree(graph, kind, anchor=ref_id)


def run_variant(graph: PoseGraph, opts: VariantOptions) -> VariantResult:
    """Run the variant described by ``opts`` (steps above); see ``lago_variant``."""
    check_method(opts.method)
    if opts.loss not in LOSSES:
        raise OptionError(f"unknown loss {opts.loss!r}; expected one of {LOSSES}")
    check_choice("information", opts.information, INFORMATION_MODES)
    check_choice("positions", opts.positions, ("phase3", "resolve"))
    if opts.positions == "resolve" and (opts.loss != "l2" or opts.constraints_fn is not None):
        raise OptionError("the position polish (positions='resolve') is an unconstrained least-squares step: use "
                          "positions='phase3' with robust losses or convex constraints")
    if graph.n_edges == 0 and graph.n_poses > 1:
        raise GraphError(f"the graph has {graph.n_poses} poses and no edges: nothing links them")
    t_all = time.perf_counter()
    anc, pri = normalize_anchors(graph, opts.anchors), normalize_priors(graph, opts.priors)
    gauge = np.zeros(3) if opts.anchor_pose is None else np.asarray(opts.anchor_pose, dtype=float).reshape(3)
    st = _State(graph, opts, anc, pri, choose_reference(graph, anc, pri, opts.anchor), gauge, {}, {})
    _frame(st)
    tree, reg, areg, th_known, th_vals, pr = _regularize(st)
    unc = edge_uncertainty(graph)
    t = time.perf_counter()
    sys1, sol1, reg, rounds, k_changed = _phase1(st, reg, unc, th_known, th_vals, pr, areg.theta_tree)
    free_th = np.flatnonzero(~th_known)
    st.timings["phase1"] = time.perf_counter() - t
    t = time.perf_counter()
    w1 = sol1.weights if sol1.weights is not None else np.ones(sys1.W.shape[0])
    L = (sp.diags(np.sqrt(w1)) @ sys1.design())[:, free_th]
    ph2 = anchored_phase2(graph, sol1.x, unc, free_th, L, sys1.groups, st.ref, information=opts.information,
                          delta_reg=reg.delta_reg)
    st.timings["phase2"] = time.perf_counter() - t
    t = time.perf_counter()
    known3, vals3 = _phase3_known(st, th_known, th_vals)
    sys3 = phase3_system(graph, ph2, known3, vals3, pr)
    sol3 = _solve(st, sys3, 3, areg.theta_tree)
    x = sol3.x
    n = graph.n_poses
    poses = np.column_stack([x[0:2 * n:2], x[1:2 * n:2], x[2 * n:]])
    st.timings["phase3"] = time.perf_counter() - t
    moved = float(np.max(np.abs(poses[:, 2] - sol1.x), initial=0.0))
    if moved > THETA_MOVE_WARNING:  # phase 3 corrects θ by O(noise); a large move means a fight
        log.warning("phase 3 moved θ by up to %.3g rad from phase 1 (pose %d): the phases disagree — constraints "
                    "or priors far from the data (e.g. a wall on the wrong side) or, with a robust loss, outliers "
                    "pull against the measurements; check them", moved,
                    int(graph.ids[int(np.argmax(np.abs(poses[:, 2] - sol1.x)))]))
    t = time.perf_counter()
    problems, pol = {}, None
    if opts.positions == "resolve":
        pol = _polish(st, sol1.x, poses[:, 2], unc, known3[:2 * n], vals3[:2 * n], pr, problems)
        poses = pol.poses
    st.timings["positions"] = time.perf_counter() - t
    ph1 = VariantPhase1(sol1.x, sol1.x[free_th], sol1.info, st.ref, sol1.factor, sol1.stats, free_th, sys1, sol1)
    ph3 = VariantPhase3(x[~known3], poses, sol3.info, st.ref, sol3.factor, sol3.stats, x, sys3, sol3)
    strain = None
    if opts.loss == "l2" and opts.constraints_fn is None and anc:  # the least-squares test (V3)
        strain = strain_report(graph, anc, sys1, sol1, sys3, sol3, opts.strain_level)
    problems.update({name: s.problem for name, s in (("phase1", sol1), ("phase3", sol3)) if s.problem is not None})
    st.timings["total"] = time.perf_counter() - t_all
    method = "cvxpy" if opts.use_cvxpy else opts.method
    log.info("LAGO variant (%s, loss %s, %s tree): %d anchors, %d priors, %.3f s", method, opts.loss, tree.kind,
             len(anc), len(pri), st.timings["total"])
    return VariantResult(graph=graph, poses=poses, anchor=int(graph.ids[st.ref]), anchor_index=st.ref,
                         anchor_pose=poses[st.ref].copy(), method=method, tree=tree, regularization=reg,
                         uncertainty=unc, phase1=ph1, phase2=ph2, phase3=ph3, timings=st.timings, problems=problems,
                         route=opts.route, information=opts.information, positions=opts.positions, polish=pol,
                         anchors=anc, priors=pri, loss=opts.loss, frame=st.frame, anchor_regularization=areg,
                         strain=strain,
                         constraint_names=sorted(set(sol1.constraint_names) | set(sol3.constraint_names)),
                         robust=_robust_summary(st, ((sys1, sol1), (sys3, sol3)), rounds, k_changed))


def lago_variant(graph: PoseGraph, **options) -> VariantResult:
    """The general engine behind ``anchored_lago`` and ``constrained_lago``, and of the convex robust losses (module
    docstrings of ``lago_cvx.variants``, V1–V10). All options keyword-only (``VariantOptions``):

      anchors — ``{id: (x, y, θ)}`` hard anchors, None components unknown (``normalize_anchors``).
      priors — ``{id: (mean (3,), information (3, 3))}`` soft absolute measurements.
      constraints_fn — ``f(pv: PoseVariables) -> list[NamedConstraint]``, called for phase 1
        (``pv.phase == 1``) and phase 3; forces the cvxpy route.
      loss — ``"l2"`` (LAGO), ``"huber"`` or ``"l1"`` (V10; cvxpy route); ``threshold`` M (whitened
        units); ``grouping`` ``"edge"`` or ``"component"``.
      method — ``"closed_form"`` or ``"cvxpy"`` for the least-squares variants (robust/constrained
        runs always use cvxpy).
      spanning_tree — as in ``lago`` plus ``"auto"`` (odometric if the chain is complete, else BFS);
        rooted at the reference pose.
      anchor — id of the reference pose (module docstring of ``engine``); anchor_pose — gauge values for
        what no anchor or prior fixes (default the origin).
      margin — ambiguity margin of the regularization (rad).
      regularization — ``"tree"``, ``"chordal"`` or ``"integer"`` (as in ``lago``; the chordal relaxation
        is anchored at the reference pose and ignores anchors and priors: it only chooses the integers;
        ``method`` picks its solver as in ``lago``). integer_search — an ``IntegerSearch`` for
        ``"integer"`` (as in ``lago``); progress — a ``ProgressCallback`` told about the integer search.
      information — ``"full"`` or ``"marginal"`` (as in ``lago``); positions — ``"phase3"`` or
        ``"resolve"`` (least squares without constraints only); route — the name recorded in the result.
      reround — re-round every edge against the phase-1 estimate and re-solve phase 1 until no k
        changes (at most ``reround_rounds`` rounds; V10).
      strain_level — significance of the anchor strain test (V3).
      solver_settings — a ``ClarabelSettings`` over the route's preset; backend — sparse solver of the
        closed form.
    Returns a ``VariantResult``. Raises ``GraphError`` (disconnected graph, unknown id),
    ``OptionError`` (bad option or anchor), ``InfeasibleConstraintsError``."""
    return run_variant(graph, VariantOptions(**options))
