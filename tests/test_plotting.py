"""Issue 30 — plots: the file's own guess is drawn rigidly aligned to the estimate's frame, loop closures
are drawn above the trajectory with a width and alpha that stay visible at 10 000 loop closures, and
titles wrap to the figure's width."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

import lago_cvx.plotting as plotting
from lago_cvx.cli import main
from lago_cvx.io import read_graph
from lago_cvx.pipeline import lago
from lago_cvx.posegraph import rot2
from lago_cvx.synthetic import manhattan_world


def test_aligned_undoes_a_rigid_motion():
    rng = np.random.default_rng(3)
    p = np.c_[rng.normal(0, 10, (50, 2)), rng.uniform(-3, 3, 50)]
    phi, t = 0.9, np.array([30.0, -7.0])
    moved = np.c_[p[:, :2] @ rot2(phi).T + t, p[:, 2] + phi]
    back = plotting.aligned(moved, p)
    np.testing.assert_allclose(back, p, atol=1e-9)


def test_plot_draws_the_files_guess_in_the_estimates_frame(capsys, tmp_path, monkeypatch):
    world = tmp_path / "w.g2o"
    assert main(["generate", "--poses", "300", "--seed", "4", "-o", str(world)]) == 0
    g = read_graph(world)
    # the file's guess in another frame: rotated by 1 rad and moved 100 m
    shifted = tmp_path / "shifted.g2o"
    text = world.read_text().splitlines()
    out = []
    for line in text:
        f = line.split()
        if f and f[0] == "VERTEX_SE2":
            x, y, th = map(float, f[2:5])
            c, s = np.cos(1.0), np.sin(1.0)
            f[2:5] = [repr(float(v)) for v in (c * x - s * y + 100.0, s * x + c * y - 50.0, th + 1.0)]
        out.append(" ".join(f))
    shifted.write_text("\n".join(out) + "\n")
    drawn = []
    real = plotting.plot_trajectory
    monkeypatch.setattr(plotting, "plot_trajectory", lambda ax, poses, **kw: (drawn.append((kw.get("label"), poses)),
                                                                             real(ax, poses, **kw))[1])
    capsys.readouterr()
    assert main(["plot", str(shifted), "-o", str(tmp_path / "f.png"), "--dpi", "30", "--size", "3"]) == 0
    guess = next(p for label, p in drawn if "initial guess" in label)
    est = next(p for label, p in drawn if label.startswith("LAGO"))
    np.testing.assert_allclose(est, lago(read_graph(shifted)).poses, atol=1e-9)
    # aligned: where the same guess in the original frame, aligned, is drawn; far from the file's raw frame
    np.testing.assert_allclose(guess, plotting.aligned(g.initial, est), atol=1e-6)
    rms = lambda a, b: float(np.sqrt(np.mean(np.sum((a[:, :2] - b[:, :2]) ** 2, 1))))  # noqa: E731
    assert rms(guess, est) < 0.1 * rms(read_graph(shifted).initial, est)


def _title_extent(fig, ax):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return ax.title.get_window_extent(canvas.get_renderer()), fig.bbox


@pytest.mark.parametrize("size", [3.0, 5.0, 8.0])
def test_long_titles_wrap_inside_the_figure(size):
    title = ("kitti_like_long_name_w10000.g2o: 10000 poses, 16819 edges; 3σ ellipses of LAGO's covariance, "
             "every 50 poses")
    fig = Figure(figsize=(size, size), layout="constrained")  # as lago-cvx plot draws
    ax = fig.subplots()
    plotting.set_title(ax, title)
    box, page = _title_extent(fig, ax)
    assert box.x0 >= page.x0 and box.x1 <= page.x1 and box.y1 <= page.y1
    assert " ".join(ax.get_title().split()) == title  # wrapped, not cut
    fig2 = Figure(figsize=(size, size), layout="constrained")
    ax2 = fig2.subplots()
    ax2.set_title(title, fontsize=10)  # what the plot did before: runs off a small figure
    box2, _ = _title_extent(fig2, ax2)
    if size <= 5.0:
        assert box2.x0 < page.x0 or box2.x1 > page.x1


def test_loop_closures_drawn_above_the_trajectory_and_visible_at_scale():
    w = manhattan_world(400, seed=1)
    fig = Figure()
    ax = fig.subplots()
    plotting.plot_trajectory(ax, w.truth)
    plotting.plot_edges(ax, w.graph, w.truth)
    (line,), (coll,) = ax.get_lines(), ax.collections
    assert coll.get_zorder() > line.get_zorder()
    assert len(coll.get_segments()) == w.graph.n_loop_closures
    for n in (100, 7000, 10688, 100000):
        st = plotting.edge_style(n)
        assert st["linewidth"] >= 1.0 and 0.35 <= st["alpha"] <= 0.9  # a zero-length segment still shows
    assert plotting.edge_style(100)["alpha"] > plotting.edge_style(10000)["alpha"]


# ------------------------------------------------------------------------------------------- 3-D
def _random_rotations(rng, n):
    from lago_cvx.so3 import exp_so3

    return exp_so3(rng.normal(0, 1.0, (n, 3)))


def test_aligned3d_undoes_a_rigid_motion():
    rng = np.random.default_rng(5)
    t, R = rng.normal(0, 10, (40, 3)), _random_rotations(rng, 40)
    G = _random_rotations(rng, 1)[0]
    c = np.array([30.0, -7.0, 4.0])
    back_t, back_R = plotting.aligned3d(t @ G.T + c, np.einsum("ab,kbc->kac", G, R), t)
    np.testing.assert_allclose(back_t, t, atol=1e-9)
    np.testing.assert_allclose(back_R, R, atol=1e-9)
    mirrored = t * np.array([1.0, 1.0, -1.0])  # the best fit is a rotation, never a reflection
    assert np.linalg.det(plotting.aligned3d(t, R, mirrored)[1][0] @ R[0].T) == pytest.approx(1.0)


def test_plot_covariances3d_draws_the_ellipsoids_shadow_on_each_plane():
    """The ellipse drawn on a plane is the shadow of the ellipsoid {u : uᵀΣ⁻¹u ≤ k²}, Σ = R Σ_pose Rᵀ: its extent
    along any in-plane direction w equals the ellipsoid's, k·√(wᵀΣw) (the support function)."""
    rng = np.random.default_rng(2)
    A = rng.normal(size=(3, 3))
    cov_pose = A @ A.T + 0.1 * np.eye(3)
    R = _random_rotations(rng, 1)
    cov6 = np.zeros((1, 6, 6))
    cov6[0, :3, :3] = cov_pose
    cov6[0, 3:, 3:] = np.eye(3)
    sigma_world = R[0] @ cov_pose @ R[0].T
    for plane, (a, b) in {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}.items():
        ax = Figure().subplots()
        plotting.plot_covariances3d(ax, np.zeros((1, 3)), cov6, R=R, plane=plane, n_sigma=2.0)
        (patch,) = ax.patches  # semi-axes width/2 along angle, height/2 across: its support function is √(wᵀMw)
        phi = np.radians(patch.angle)
        Q = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        M = Q @ np.diag([(patch.width / 2) ** 2, (patch.height / 2) ** 2]) @ Q.T
        for angle in np.linspace(0, np.pi, 7):
            w2 = np.array([np.cos(angle), np.sin(angle)])
            w3 = np.zeros(3)
            w3[[a, b]] = w2
            assert np.sqrt(w2 @ M @ w2) == pytest.approx(2.0 * np.sqrt(w3 @ sigma_world @ w3), rel=1e-9)


def test_plot_3d_draws_loop_closures_the_aligned_guess_and_covariances(tmp_path, capsys, monkeypatch):
    """plot on a 3-D file whose guess is in another frame: the guess is drawn aligned to the estimate (SE(3)), the
    loop closures are drawn in every projection, and --covariances draws one ellipse per poses drawn and plane."""
    from lago_cvx.space import lago3d

    world = tmp_path / "w.g2o"
    assert main(["generate", "--world", "sphere3d", "--poses", "80", "--seed", "2", "-o", str(world)]) == 0
    g = read_graph(world)
    G, c = _random_rotations(np.random.default_rng(0), 1)[0], np.array([100.0, -50.0, 20.0])
    moved = tmp_path / "moved.g2o"
    from lago_cvx.io import write_graph

    write_graph(moved, g, (g.initial_t @ G.T + c, np.einsum("ab,kbc->kac", G, g.initial_R)))
    drawn, edges, ellipses = [], [], []
    real_t, real_e, real_c = plotting.plot_trajectory3d, plotting.plot_edges3d, plotting.plot_covariances3d
    monkeypatch.setattr(plotting, "plot_trajectory3d", lambda ax, t, **kw: (drawn.append((kw["label"], t)),
                                                                           real_t(ax, t, **kw))[1])
    monkeypatch.setattr(plotting, "plot_edges3d", lambda ax, graph, t, **kw: (edges.append(kw["plane"]),
                                                                             real_e(ax, graph, t, **kw))[1])
    monkeypatch.setattr(plotting, "plot_covariances3d", lambda ax, t, cov, **kw: (ellipses.append(cov.shape),
                                                                                 real_c(ax, t, cov, **kw))[1])
    capsys.readouterr()
    assert main(["plot", str(moved), "-o", str(tmp_path / "f.png"), "--covariances", "--every", "10",
                 "--dpi", "30", "--size", "6"]) == 0
    assert "8 covariance ellipsoids" in capsys.readouterr().out
    est = next(t for label, t in drawn if label.startswith("LAGO"))
    guess = next(t for label, t in drawn if "initial guess" in label)
    np.testing.assert_allclose(est, lago3d(read_graph(moved)).t, atol=1e-9)
    np.testing.assert_allclose(guess, plotting.aligned3d(g.initial_t, None, est)[0], atol=1e-6)
    rms = lambda a, b: float(np.sqrt(np.mean(np.sum((a - b) ** 2, 1))))  # noqa: E731
    assert rms(guess, est) < 0.1 * rms(read_graph(moved).initial_t, est)
    assert sorted(edges) == ["xy", "xz", "yz"] and ellipses == [(g.n_poses, 6, 6)] * 3


def test_plot_functions_take_an_axes_and_return_it():
    from lago_cvx.synthetic.space import cube_grid_world

    w = cube_grid_world(3, seed=0)
    ax = Figure().subplots()
    assert plotting.plot_trajectory3d(ax, w.t, plane="xz") is ax
    assert plotting.plot_edges3d(ax, w.graph, w.t, plane="yz") is ax
    assert plotting.plot_covariances3d(ax, w.t, np.broadcast_to(np.eye(6), (27, 6, 6)), plane="xy") is ax
    with pytest.raises(ValueError, match="plane"):
        plotting.plot_trajectory3d(ax, w.t, plane="xx")
