"""Axes-first plotting: every function takes a matplotlib ``Axes``, draws on it and returns it.

Nothing here calls ``plt.show()`` or writes files; scripts and the CLI decide where figures go.
"""

from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.patches import Ellipse

from .metrics import alignment
from .posegraph import PoseGraph, rot2

__all__ = ["plot_trajectory", "plot_edges", "plot_covariances", "plot_convergence", "plot_trajectory3d",
           "plot_edges3d", "plot_covariances3d", "aligned", "aligned3d", "edge_style", "set_title"]


def aligned(poses, reference) -> np.ndarray:
    """``poses`` (n, 3) moved by the rigid motion that best fits them to ``reference`` (n, 3), so the two
    can be drawn in one frame: with (φ, t) of ``metrics.alignment`` (least squares over all positions, no
    scale), p ↦ R(φ)p + t and θ ↦ θ + φ. A file's initial guess and an estimate anchored at the origin
    are then drawn where they overlap best, not in two frames."""
    poses = np.asarray(poses, dtype=float)
    phi, t = alignment(poses, reference)
    out = poses.copy()
    out[:, :2] = poses[:, :2] @ rot2(phi).T + t
    out[:, 2] = poses[:, 2] + phi
    return out


def edge_style(n_edges: int) -> dict:
    """``linewidth`` and ``alpha`` that keep ``n_edges`` segments visible on top of a trajectory without
    hiding it: 1.5 pt for a few hundred, 1.2 pt beyond (with round caps a loop closure between two poses
    at the same place — most of them, once the estimate is good — still shows as a dot), α from 0.9 down
    to 0.35 for tens of thousands (α = (1000/n)^0.3 clipped to [0.35, 0.9]; overlapping faint marks add
    up)."""
    n = max(int(n_edges), 1)
    linewidth = 1.5 if n <= 300 else 1.2
    return {"linewidth": linewidth, "alpha": float(np.clip((1000.0 / n) ** 0.3, 0.35, 0.9))}


def set_title(ax: Axes, title: str, *, fontsize: float = 10.0) -> Axes:
    """Set ``title`` wrapped to the width of ``ax``'s figure (about 0.55 em per character), so a long one
    takes two or three lines instead of running off the figure."""
    width_pt = ax.figure.get_figwidth() * 72.0
    chars = max(int(0.92 * width_pt / (0.55 * fontsize)), 20)
    ax.set_title("\n".join(textwrap.wrap(title, chars)) or title, fontsize=fontsize)
    return ax


def plot_trajectory(ax: Axes, poses, *, label: str | None = None, color=None, linewidth: float = 1.0,
                    style: str = "-", **kwargs) -> Axes:
    """Draw the trajectory through ``poses`` (n, 3) in id order (x–y plane, equal aspect)."""
    poses = np.asarray(poses, dtype=float)
    ax.plot(poses[:, 0], poses[:, 1], style, color=color, linewidth=linewidth, label=label, **kwargs)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return ax


def plot_edges(ax: Axes, graph: PoseGraph, poses, *, which: str = "loop_closures", color="tab:red",
               linewidth: float | None = None, alpha: float | None = None, label: str | None = None,
               zorder: float = 3.0) -> Axes:
    """Draw edges as segments between the endpoints' positions in ``poses`` (n, 3).

    ``which``: ``"loop_closures"`` (non-consecutive ids, the seed's Figure 1), ``"odometric"`` or ``"all"``.
    ``linewidth``/``alpha`` default to ``edge_style`` of the number drawn (round caps: a segment shorter
    than its width still shows as a dot); ``zorder`` 3 draws them above a trajectory (``plot_trajectory``'s
    lines are at 2), where loop closures between nearby poses would otherwise be hidden under it."""
    xy = np.asarray(poses, dtype=float)[:, :2]
    return _segments(ax, graph, xy, which, color, linewidth, alpha, label, zorder)


def _segments(ax: Axes, graph, xy: np.ndarray, which: str, color, linewidth, alpha, label, zorder) -> Axes:
    """The edges ``which`` of ``graph`` as segments between the plotted positions ``xy`` (n, 2) of their
    endpoints (``plot_edges``, ``plot_edges3d``)."""
    odo = graph.is_odometric
    sel = {"loop_closures": ~odo, "odometric": odo, "all": np.ones_like(odo)}[which]
    style = edge_style(int(np.count_nonzero(sel)))
    seg = np.stack([xy[graph.tails[sel]], xy[graph.heads[sel]]], axis=1)
    ax.add_collection(LineCollection(seg, colors=color, label=label, zorder=zorder, capstyle="round",
                                     linewidths=style["linewidth"] if linewidth is None else linewidth,
                                     alpha=style["alpha"] if alpha is None else alpha))
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    return ax


def plot_covariances(ax: Axes, poses, covariances, *, every: int = 1, n_sigma: float = 3.0,
                     color="tab:blue", alpha: float = 0.3, zorder: float = 4.0) -> Axes:
    """Draw the ``n_sigma`` position-uncertainty ellipse of every ``every``-th pose (above trajectory and
    edges: ``zorder`` 4).

    ``covariances`` (n, 3, 3) (only the x–y block is used) or (n, 2, 2)."""
    poses = np.asarray(poses, dtype=float)
    cov = np.asarray(covariances, dtype=float)[:, :2, :2]
    for i in range(0, poses.shape[0], every):
        _ellipse(ax, poses[i, :2], cov[i], n_sigma, color=color, alpha=alpha, zorder=zorder)
    ax.autoscale_view()
    return ax


def _ellipse(ax: Axes, center, cov2, n_sigma: float, **style) -> None:
    """The ``n_sigma`` ellipse {c + u : uᵀ Σ⁻¹ u ≤ n_sigma²} of the 2×2 ``cov2`` (nothing when it is zero)."""
    w, v = np.linalg.eigh(cov2)
    w = np.clip(w, 0.0, None)
    if w.max() <= 0:
        return
    angle = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
    ax.add_patch(Ellipse(center, 2 * n_sigma * np.sqrt(w[1]), 2 * n_sigma * np.sqrt(w[0]), angle=angle,
                         facecolor=style["color"], edgecolor=style["color"], alpha=style["alpha"],
                         zorder=style["zorder"]))


def plot_convergence(ax: Axes, values, *, label: str | None = None, reference: float | None = None,
                     reference_label: str | None = None, logy: bool = True, **kwargs) -> Axes:
    """Cost per iteration (the seed's Figure 3), optionally with a horizontal reference level."""
    values = np.asarray(values, dtype=float)
    ax.plot(np.arange(values.size), values, marker="o", markersize=3, label=label, **kwargs)
    if reference is not None:
        ax.axhline(reference, linestyle="--", color="k", linewidth=1.0, label=reference_label)
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("χ² (Σ eᵀΩe)")
    return ax


_AXES3 = {"x": 0, "y": 1, "z": 2}


def plot_trajectory3d(ax: Axes, t, *, plane: str = "xy", label: str | None = None, color=None,
                      linewidth: float = 1.0, style: str = "-", **kwargs) -> Axes:
    """Draw the projection on ``plane`` ("xy", "xz" or "yz") of the 3-D trajectory through the positions ``t``
    (n, 3), in id order (equal aspect)."""
    t = np.asarray(t, dtype=float)
    a, b = _plane(plane)
    ax.plot(t[:, a], t[:, b], style, color=color, linewidth=linewidth, label=label, **kwargs)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"{plane[0]} [m]")
    ax.set_ylabel(f"{plane[1]} [m]")
    return ax


def _plane(plane: str) -> tuple[int, int]:
    if len(plane) != 2 or plane[0] not in _AXES3 or plane[1] not in _AXES3 or plane[0] == plane[1]:
        raise ValueError(f"plane must be two of x, y, z (e.g. 'xy', 'xz', 'yz'), got {plane!r}")
    return _AXES3[plane[0]], _AXES3[plane[1]]


def aligned3d(t, R, reference) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``t`` (n, 3) and rotations ``R`` (n, 3, 3) moved by the rigid motion (G, c) ∈ SE(3) that best fits
    the positions to ``reference`` (n, 3) in least squares, no scale (Kabsch/Umeyama: H = Σ (t_i − t̄)(r_i − r̄)ᵀ =
    U S Vᵀ, G = V diag(1, 1, det(V Uᵀ)) Uᵀ, c = r̄ − G t̄): t_i ↦ G t_i + c, R_i ↦ G R_i. The 3-D ``aligned``: a
    file's guess is then drawn where it overlaps the estimate best, not in its own frame. ``R`` may be None."""
    t = np.asarray(t, dtype=float)
    ref = np.asarray(reference, dtype=float)
    tc, rc = t.mean(axis=0), ref.mean(axis=0)
    U, _, Vt = np.linalg.svd((t - tc).T @ (ref - rc))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    G = Vt.T @ D @ U.T
    moved = (t - tc) @ G.T + rc
    return moved, None if R is None else np.einsum("ab,kbc->kac", G, np.asarray(R, dtype=float))


def plot_edges3d(ax: Axes, graph, t, *, plane: str = "xy", which: str = "loop_closures", color="tab:red",
                 linewidth: float | None = None, alpha: float | None = None, label: str | None = None,
                 zorder: float = 3.0) -> Axes:
    """``plot_edges`` for a 3-D graph: segments between the endpoints' positions ``t`` (n, 3), projected on
    ``plane``; ``which`` ``"loop_closures"`` (non-consecutive ids), ``"odometric"`` or ``"all"``."""
    a, b = _plane(plane)
    return _segments(ax, graph, np.asarray(t, dtype=float)[:, [a, b]], which, color, linewidth, alpha, label, zorder)


def plot_covariances3d(ax: Axes, t, covariances, *, R=None, plane: str = "xy", every: int = 1,
                       n_sigma: float = 3.0, color="tab:blue", alpha: float = 0.3, zorder: float = 4.0) -> Axes:
    """The projections on ``plane`` of the ``n_sigma`` position-uncertainty ellipsoids of every ``every``-th pose.

    ``covariances`` (n, 6, 6) translation first (``space.covariance.pose_covariances3d``) or (n, 3, 3): of the
    position in the pose's own frame when ``R`` (n, 3, 3) is given (then Σ_world = R_i Σ R_iᵀ), else in the world
    frame. The shadow of the ellipsoid {u : uᵀ Σ⁻¹ u ≤ k²} on a coordinate plane is the ellipse of the marginal
    2×2 block of Σ on that plane's axes, which is what is drawn, centred on t_i."""
    t = np.asarray(t, dtype=float)
    cov = np.asarray(covariances, dtype=float)[:, :3, :3]
    if R is not None:
        R = np.asarray(R, dtype=float)
        cov = R @ cov @ np.swapaxes(R, 1, 2)
    a, b = _plane(plane)
    for i in range(0, t.shape[0], every):
        _ellipse(ax, t[i, [a, b]], cov[i][np.ix_([a, b], [a, b])], n_sigma, color=color, alpha=alpha, zorder=zorder)
    ax.autoscale_view()
    return ax
