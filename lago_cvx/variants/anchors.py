r"""Known poses: hard anchors (full or partial), soft priors, and how their orientations are put on
the branch of the regularized tree (V4). Notation as in ``lago_cvx.variants``.

Regularization with anchors (V4). The tree is rooted at the reference pose; θ_tree is the tree
integral offset so that the first pose of known orientation (the reference if it has one) matches
its value. Every other orientation anchor a acts like a chord from the root: its value is corrected
by 2πk_a, k_a = branch(θ_a, θ_tree[a]) (``lago_cvx.rounding``: residual in (−π, π]), reported like a
chord (``AnchorRegularization``, ambiguous within ``margin`` of ±π, logged). Prior means are rounded
the same way.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..errors import OptionError
from ..stacks import whitening_2x2
from ..posegraph import PoseGraph
from ..rounding import TWO_PI, branch, edge_integers

__all__ = ["Anchor", "Prior", "normalize_anchors", "normalize_priors", "PriorArrays", "prior_arrays",
           "AnchorRegularization", "anchor_regularization", "choose_reference", "reround_edges"]

log = logging.getLogger("lago_cvx.variants")


@dataclass(frozen=True)
class Anchor:
    """A hard anchor: pose ``id`` (index ``index``) with known ``position`` (2,) or None and known
    ``theta`` or None (at least one of them known). ``theta`` is the value as given; the value used
    is corrected by 2πk (``AnchorRegularization``)."""

    id: int
    index: int
    position: tuple | None
    theta: float | None

    @property
    def kind(self) -> str:
        return "full" if self.position is not None and self.theta is not None else (
            "position" if self.position is not None else "orientation")


@dataclass(frozen=True, eq=False)
class Prior:
    """A soft absolute measurement of pose ``id``: ``mean`` (3,) = (x, y, θ), ``information`` (3, 3)
    (order x, y, θ; GTSAM-style prior factor, its χ² term eᵀΛe with no ½ like every χ² here).
    ``known`` (3,) bool: the measured components — all three (Λ SPD), the position only (a GPS fix:
    Λ_pp SPD, the θ row and column zero, mean[2] = 0 unused) or θ only (Λ_θθ > 0, the rest zero)."""

    id: int
    index: int
    mean: np.ndarray
    information: np.ndarray
    known: np.ndarray = field(default_factory=lambda: np.ones(3, bool))

    @property
    def has_theta(self) -> bool:
        return bool(self.known[2])

    @property
    def has_position(self) -> bool:
        return bool(self.known[0])


def _items(spec) -> list:
    if spec is None:
        return []
    return list(spec.items()) if isinstance(spec, Mapping) else list(spec)


def _unknown(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _by_pose(graph: PoseGraph, spec, what: str):
    """(id, index, value) for every entry of ``spec`` ({id: value} or pairs), each pose at most once."""
    seen = set()
    for pid, val in _items(spec):
        idx = graph.index_of(pid)
        if idx in seen:
            raise OptionError(f"{what} {pid} given twice")
        seen.add(idx)
        yield pid, idx, val


def normalize_anchors(graph: PoseGraph, anchors) -> list[Anchor]:
    """``{id: (x, y, θ)}`` (or pairs ``(id, (x, y, θ))``; a component None or NaN is unknown) →
    list of ``Anchor`` in the given order. Raises ``OptionError`` / ``GraphError`` naming the anchor."""
    out = []
    for pid, idx, val in _by_pose(graph, anchors, "anchor"):
        val = tuple(val)
        if len(val) != 3:
            raise OptionError(f"anchor {pid}: expected (x, y, θ) with None for unknown parts, got {val!r}")
        x, y, th = (None if _unknown(v) else float(v) for v in val)
        if (x is None) != (y is None):
            raise OptionError(f"anchor {pid}: give both x and y, or neither")
        if x is None and th is None:
            raise OptionError(f"anchor {pid}: nothing is known (all components None)")
        if not all(math.isfinite(v) for v in (x, y, th) if v is not None):
            raise OptionError(f"anchor {pid}: values must be finite")
        out.append(Anchor(int(pid), idx, None if x is None else (x, y), th))
    return out


def normalize_priors(graph: PoseGraph, priors) -> list[Prior]:
    """``{id: (mean, information)}`` (or pairs) → list of ``Prior``. ``mean`` (x, y, θ) with None (or NaN)
    for an unmeasured part: all three known with ``information`` (3, 3); ``(x, y, None)`` with (2, 2) (a
    position / GPS prior); ``(None, None, θ)`` with a scalar or (1, 1). The information of the measured
    part must be symmetric positive definite. Raises ``OptionError`` naming the prior."""
    out = []
    for pid, idx, spec in _by_pose(graph, priors, "prior on pose"):
        try:
            mean, info = spec
        except (TypeError, ValueError):
            raise OptionError(f"prior {pid}: expected (mean, information), got {spec!r}") from None
        mean = [None if _unknown(v) else float(v) for v in np.asarray(mean, dtype=object).reshape(-1)]
        known = np.array([v is not None for v in mean], bool)
        if len(mean) != 3 or not (known.all() or known.tolist() in ([True, True, False], [False, False, True])):
            raise OptionError(f"prior {pid}: mean must be (x, y, θ), (x, y, None) or (None, None, θ), got {mean!r}")
        k = int(known.sum())
        info = np.asarray(info, dtype=float)
        info = info.reshape(1, 1) if k == 1 and info.size == 1 else info
        if info.shape != (k, k):
            raise OptionError(f"prior {pid}: the information of a prior on {k} component(s) must be ({k}, {k}), "
                              f"got {info.shape}")
        if not (all(math.isfinite(v) for v in mean if v is not None) and np.isfinite(info).all()):
            raise OptionError(f"prior {pid}: values must be finite")
        if not np.allclose(info, info.T, rtol=1e-9, atol=0.0):
            raise OptionError(f"prior {pid}: information matrix is not symmetric")
        try:
            np.linalg.cholesky(info)
        except np.linalg.LinAlgError:
            hint = ("; for a position-only (GPS) prior give ((x, y, None), Λ 2×2), for θ only ((None, None, θ), λ)"
                    if k == 3 else "")
            raise OptionError(f"prior {pid}: information matrix is not positive definite{hint}") from None
        full = np.zeros((3, 3))
        full[np.ix_(known, known)] = 0.5 * (info + info.T)
        out.append(Prior(int(pid), idx, np.array([0.0 if v is None else v for v in mean]), full, known))
    return out


@dataclass(frozen=True, eq=False)
class PriorArrays:
    """Vectorized priors, q of them (Λ a prior's 3×3 information)."""

    #: (q,) the poses' indices.
    index: np.ndarray
    #: (q, 3) the means, θ rounded to the tree.
    mean: np.ndarray
    #: (q,) the marginal standard deviation of θ.
    sigma_theta: np.ndarray
    #: (q, 2, 2) C with CᵀC = Λ_pp.
    C: np.ndarray
    #: (q, 2) h = Λ_pp⁻¹Λ_pθ.
    h: np.ndarray

    @property
    def q(self) -> int:
        """The number of priors."""
        return int(self.index.size)


def prior_arrays(priors: list[Prior], mean_theta: np.ndarray) -> PriorArrays:
    """``PriorArrays`` of ``priors`` with their θ means replaced by ``mean_theta`` (q,) (rounded, V4)."""
    q = len(priors)
    if q == 0:
        z = np.zeros(0)
        return PriorArrays(np.zeros(0, np.int64), np.zeros((0, 3)), z, np.zeros((0, 2, 2)), np.zeros((0, 2)))
    info = np.stack([p.information for p in priors])
    mean = np.stack([p.mean for p in priors])
    mean[:, 2] = mean_theta
    has_p = np.array([p.has_position for p in priors])
    has_t = np.array([p.has_theta for p in priors])
    var_theta = np.full(q, np.inf)  # a position-only prior says nothing about θ (weight 1/σ = 0)
    both = has_p & has_t
    var_theta[both] = np.linalg.inv(info[both])[:, 2, 2]
    var_theta[has_t & ~has_p] = 1.0 / info[has_t & ~has_p, 2, 2]
    C, h = np.zeros((q, 2, 2)), np.zeros((q, 2))  # a θ-only prior has no conditional position part
    if has_p.any():
        Lpp = info[has_p, :2, :2]
        h[has_p] = np.linalg.solve(Lpp, info[has_p, :2, 2][..., None])[..., 0]
        C[has_p] = whitening_2x2(Lpp)
    return PriorArrays(np.array([p.index for p in priors], np.int64), mean, np.sqrt(var_theta), C, h)


@dataclass(frozen=True, eq=False)
class AnchorRegularization:
    """2kπ correction of the anchored orientations and prior means against the tree (V4).

    ``index`` (a,) pose indices; ``source`` (a,) "anchor" / "prior"; ``value`` (a,) as given;
    ``k`` (a,) the integer corrections; ``residual_before`` (a,) value − θ_tree; ``residual`` (a,) after
    correction, in (−π, π]; ``ambiguous`` (a,) bool (|residual| > π − margin); ``theta_tree`` (n,) the
    tree orientations in the output frame; ``offset`` the tree's orientation offset and
    ``offset_from`` what fixed it ("anchor <id>", "prior <id>", "gauge", "procrustes")."""

    index: np.ndarray
    source: np.ndarray
    value: np.ndarray
    k: np.ndarray
    residual_before: np.ndarray
    residual: np.ndarray
    ambiguous: np.ndarray
    theta_tree: np.ndarray
    offset: float
    offset_from: str

    @property
    def corrected(self) -> np.ndarray:
        return self.value + TWO_PI * self.k

    @property
    def n_regularized(self) -> int:
        return int(np.count_nonzero(self.k))


def anchor_regularization(graph: PoseGraph, theta_tree0: np.ndarray, idx: np.ndarray, source: np.ndarray,
                          value: np.ndarray, offset: float, offset_from: str, margin: float) -> AnchorRegularization:
    """Round the known orientations ``value`` (a,) of poses ``idx`` onto θ_tree = ``theta_tree0`` + offset (V4)."""
    theta_tree = theta_tree0 + offset
    before = value - theta_tree[idx]
    k = branch(value, theta_tree[idx])
    res = before + TWO_PI * k
    amb = np.abs(res) > np.pi - margin
    if amb.any():
        ids = graph.ids[idx[amb]]
        log.warning("regularization: anchored/prior orientation(s) of pose(s) %s are within %.3g rad of ±π "
                    "from the tree's orientation, so their 2kπ correction is ambiguous",
                    ", ".join(str(i) for i in ids[:10]), margin)
    return AnchorRegularization(idx, source, value, k, before, res, amb, theta_tree, float(offset), offset_from)


def choose_reference(graph: PoseGraph, anchors: list[Anchor], priors: list[Prior], anchor) -> int:
    """Index of the reference pose: ``anchor`` (an id) if given, else the first full anchor, else the first
    anchor with a known orientation, else the first anchor, else the first prior, else the smallest id."""
    if anchor is not None:
        return graph.index_of(anchor)
    for pick in (lambda a: a.kind == "full", lambda a: a.theta is not None, lambda a: True):
        for a in anchors:
            if pick(a):
                return a.index
    if priors:
        return priors[0].index
    return graph.anchor_index(None)


def reround_edges(graph: PoseGraph, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Round every edge against an orientation estimate θ (n,): k_e = branch(δ_e, θ_j − θ_i),
    δ_reg = δ + 2πk (residual in (−π, π]). Returns (delta_reg (m,), k (m,))."""
    k = edge_integers(graph, theta)
    return graph.delta + TWO_PI * k, k
