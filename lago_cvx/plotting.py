"""Axes-first plotting: every function takes a matplotlib ``Axes``, draws on it and returns it.

Nothing here calls ``plt.show()`` or writes files; scripts and the CLI decide where figures go.
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.patches import Ellipse

from .posegraph import PoseGraph

__all__ = ["plot_trajectory", "plot_edges", "plot_covariances", "plot_convergence", "plot_trajectory3d"]


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
               linewidth: float = 0.4, alpha: float = 0.6, label: str | None = None) -> Axes:
    """Draw edges as segments between the endpoints' positions in ``poses`` (n, 3).

    ``which``: ``"loop_closures"`` (non-consecutive ids, the seed's Figure 1), ``"odometric"`` or ``"all"``."""
    poses = np.asarray(poses, dtype=float)
    odo = graph.is_odometric
    sel = {"loop_closures": ~odo, "odometric": odo, "all": np.ones_like(odo)}[which]
    seg = np.stack([poses[graph.tails[sel], :2], poses[graph.heads[sel], :2]], axis=1)
    ax.add_collection(LineCollection(seg, colors=color, linewidths=linewidth, alpha=alpha, label=label))
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    return ax


def plot_covariances(ax: Axes, poses, covariances, *, every: int = 1, n_sigma: float = 3.0,
                     color="tab:blue", alpha: float = 0.3) -> Axes:
    """Draw the ``n_sigma`` position-uncertainty ellipse of every ``every``-th pose.

    ``covariances`` (n, 3, 3) (only the x–y block is used) or (n, 2, 2)."""
    poses = np.asarray(poses, dtype=float)
    cov = np.asarray(covariances, dtype=float)[:, :2, :2]
    for i in range(0, poses.shape[0], every):
        w, v = np.linalg.eigh(cov[i])
        w = np.clip(w, 0.0, None)
        if w.max() <= 0:
            continue
        angle = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
        ax.add_patch(Ellipse(poses[i, :2], 2 * n_sigma * np.sqrt(w[1]), 2 * n_sigma * np.sqrt(w[0]),
                             angle=angle, facecolor=color, edgecolor=color, alpha=alpha))
    ax.autoscale_view()
    return ax


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
    ax.set_ylabel("χ² (g2o convention)")
    return ax


_AXES3 = {"x": 0, "y": 1, "z": 2}


def plot_trajectory3d(ax: Axes, t, *, plane: str = "xy", label: str | None = None, color=None,
                      linewidth: float = 1.0, style: str = "-", **kwargs) -> Axes:
    """Draw the projection on ``plane`` ("xy", "xz" or "yz") of the 3-D trajectory through the positions ``t``
    (n, 3), in id order (equal aspect)."""
    t = np.asarray(t, dtype=float)
    a, b = _AXES3[plane[0]], _AXES3[plane[1]]
    ax.plot(t[:, a], t[:, b], style, color=color, linewidth=linewidth, label=label, **kwargs)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"{plane[0]} [m]")
    ax.set_ylabel(f"{plane[1]} [m]")
    return ax
