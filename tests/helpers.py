"""Small helpers shared by the tests (not fixtures)."""

from __future__ import annotations

import numpy as np

from lago_cvx.graph import cycle_basis, spanning_tree
from lago_cvx.posegraph import PoseGraph, between, wrap_angle
from lago_cvx.synthetic import circle_world


def pose_error(a, b) -> float:
    """Largest difference between two (n, 3) pose arrays, angles compared modulo 2π."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return float(max(np.abs(a[:, :2] - b[:, :2]).max(), np.abs(wrap_angle(a[:, 2] - b[:, 2])).max()))


def graph_from_truth(truth, tails, heads, info=None) -> PoseGraph:
    """Noiseless graph with δ wrapped, as a sensor reports it."""
    truth = np.asarray(truth, dtype=float)
    tails = np.asarray(tails)
    heads = np.asarray(heads)
    meas = between(truth[tails], truth[heads])
    meas[:, 2] = wrap_angle(meas[:, 2])
    if info is None:
        info = np.broadcast_to(np.diag([100.0, 100.0, 400.0]), (tails.size, 3, 3))
    return PoseGraph(truth.shape[0], tails, heads, meas[:, :2], meas[:, 2], info)


def winding_world(n: int, laps: int, seed: int, kind: str):
    """A noiseless multi-lap ``circle_world`` (its δ wrap around ±π), the spanning tree of ``kind`` and the
    cycle basis C on it: returns (world, graph, tree, C)."""
    w = circle_world(n, laps=laps, seed=seed, sigma_xy=0.0, sigma_theta=0.0)
    t = spanning_tree(w.graph, kind)
    return w, w.graph, t, cycle_basis(w.graph, t)


def corrupt_tokens(rnd, base_lines, nasty):
    """One or two random token corruptions of a file given as lines: a token (never the tag) replaced by
    one of ``nasty`` (80 %), deleted (10 %) or one of ``nasty`` inserted before it (10 %). ``rnd`` a
    ``random.Random``; returns the corrupted text."""
    lines = [ln.split() for ln in base_lines]
    for _ in range(rnd.randint(1, 2)):
        r = rnd.randrange(len(lines))
        if len(lines[r]) < 2:
            continue
        c = rnd.randrange(1, len(lines[r]))
        op = rnd.random()
        if op < 0.8:
            lines[r][c] = rnd.choice(nasty)
        elif op < 0.9:
            del lines[r][c]
        else:
            lines[r].insert(c, rnd.choice(nasty))
    return "\n".join(" ".join(t) for t in lines) + "\n"
