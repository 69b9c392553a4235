"""3-D pose graphs: the SO(3)/SE(3) functions, ``PoseGraph3D``, and g2o ``VERTEX_SE3:QUAT`` / ``EDGE_SE3:QUAT`` files
(reading, writing, every malformed input named with file:line, the dispatch of ``read_graph``)."""

from __future__ import annotations

import logging
import pickle

import numpy as np
import pytest

from conftest import dataset_path
from lago_cvx.errors import GraphError, ParseError
from lago_cvx.io import detect_format, read_graph, write_graph
from lago_cvx.posegraph import PoseGraph
from lago_cvx.posegraph3d import PoseGraph3D, chi2_3d, edge_errors3d
from lago_cvx.so3 import (exp_so3, log_se3, log_so3, project_so3, quat_to_rot, right_jacobian_inverse,
                          rot_to_quat)

INFO21 = " ".join(["100 0 0 0 0 0", "100 0 0 0 0", "100 0 0 0", "400 0 0", "400 0", "400"])
V0 = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1"
V1 = "VERTEX_SE3:QUAT 1 1 0 0 0 0 0 1"
E01 = f"EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {INFO21}"


def _write(tmp_path, text: str, name="g.g2o"):
    p = tmp_path / name
    p.write_text(text)
    return p


# ------------------------------------------------------------------ SO(3), SE(3)
def test_exp_log_quaternion_round_trips():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(200, 3))
    w *= (rng.uniform(0, np.pi - 1e-6, 200) / np.linalg.norm(w, axis=1))[:, None]
    w[:3] = [[0, 0, 0], [1e-9, 0, 0], [0, 0, np.pi - 1e-9]]
    R = exp_so3(w)
    assert np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max() < 1e-14
    assert np.abs(log_so3(R) - w).max() < 1e-8
    assert np.abs(quat_to_rot(rot_to_quat(R)) - R).max() < 1e-14


def test_projection_onto_so3():
    rng = np.random.default_rng(1)
    M = rng.normal(size=(100, 3, 3))
    P = project_so3(M)
    assert np.abs(np.swapaxes(P, 1, 2) @ P - np.eye(3)).max() < 1e-13
    assert (np.linalg.det(P) > 0).all()  # never a reflection, also where det M < 0
    R = exp_so3(rng.normal(size=(100, 3)))
    assert np.abs(project_so3(R) - R).max() < 1e-14  # a rotation is its own projection
    assert np.abs(project_so3(3.0 * R) - R).max() < 1e-14  # scale is lost
    # nearest: no sampled rotation is closer to M than its projection
    for k in range(5):
        others = exp_so3(rng.normal(size=(500, 3)) * 0.3) @ P[k]
        assert (np.linalg.norm(others - M[k], axis=(1, 2)) >= np.linalg.norm(P[k] - M[k]) - 1e-12).all()


def _svd_projection(M):
    """The projection as the issue states it, by LAPACK's SVD: U diag(1, 1, det(UVᵀ)) Vᵀ."""
    U, _, Vt = np.linalg.svd(M)
    U[..., :, 2] *= np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)[..., None]
    return U @ Vt


@pytest.mark.parametrize("family", ["near", "gaussian", "ill-conditioned", "rank two", "scaled", "reflected"])
def test_projection_is_the_svd_projection(family):
    """``project_so3`` computes the polar factor by Newton's iteration where det M > 0, the SVD elsewhere: both give
    the SVD's matrix to rounding, on every kind of input, never a reflection."""
    rng = np.random.default_rng(3)
    R = exp_so3(rng.normal(size=(400, 3)))
    M = {"near": R + 0.05 * rng.normal(size=R.shape), "gaussian": rng.normal(size=R.shape),
         "ill-conditioned": R @ np.diag([1.0, 1e-3, 1e-12]) @ exp_so3(rng.normal(size=(400, 3))),
         "rank two": R @ np.diag([2.0, 1.0, 0.0]), "scaled": 1e6 * R, "reflected": -R}[family]
    P = project_so3(M)
    assert np.abs(P - _svd_projection(M)).max() < 1e-12
    assert np.abs(np.swapaxes(P, 1, 2) @ P - np.eye(3)).max() < 1e-14 * 10
    assert (np.linalg.det(P) > 0).all()
    assert project_so3(M[0]).shape == (3, 3) and project_so3(M[:6].reshape(2, 3, 3, 3)).shape == (2, 3, 3, 3)


def test_entries_arithmetic_is_numpys():
    """``so3.entries`` and the products on them give NumPy's (N, 3, 3) results."""
    from lago_cvx.so3 import apply, cross, entries, matrices, product, transposed

    rng = np.random.default_rng(4)
    A, B, v = rng.normal(size=(50, 3, 3)), rng.normal(size=(50, 3, 3)), rng.normal(size=(50, 3))
    EA, EB = entries(A), entries(B)
    assert np.abs(matrices(product(EA, EB)) - A @ B).max() < 1e-14
    assert np.array_equal(matrices(transposed(EA)), np.swapaxes(A, 1, 2))
    assert np.abs(np.array(apply(EA, list(v.T))).T - np.einsum("kij,kj->ki", A, v)).max() < 1e-14
    assert np.abs(np.array(cross(list(v.T), list(v[::-1].T))).T - np.cross(v, v[::-1])).max() < 1e-14
    idx = np.array([3, 0, 3])
    assert np.array_equal(matrices(entries(A, idx)), A[idx])
    assert np.array_equal(matrices(entries(np.ascontiguousarray(A.reshape(-1, 9).T))), A)


def test_right_jacobian_inverse_is_barfoots_formula():
    """The entry-wise evaluation (outer products for the products of skew matrices) against Barfoot's formula with
    the 3×3 products taken as written, on both sides of the Taylor switch at θ = 0.1 and up to θ near π."""
    from lago_cvx.so3 import hat

    rng = np.random.default_rng(5)
    xi = rng.normal(size=(300, 6))
    xi[:, 3:] *= (np.geomspace(1e-9, 3.1, 300) / np.linalg.norm(xi[:, 3:], axis=1))[:, None]
    th = np.linalg.norm(xi[:, 3:], axis=1)
    co = np.stack([(th - np.sin(th)) / th ** 3, (th * th + 2 * np.cos(th) - 2) / (2 * th ** 4),
                   (2 * th - 3 * np.sin(th) + th * np.cos(th)) / (2 * th ** 5),
                   1 / th ** 2 - (1 + np.cos(th)) / (2 * th * np.sin(th))])
    big = th > 0.1  # where the closed forms are exact enough to be the reference
    a, b, c, c1 = (x[big][:, None, None] for x in co)
    F, P = hat(-xi[big, 3:]), hat(-xi[big, :3])
    Q = 0.5 * P + a * (F @ P + P @ F + F @ P @ F) + b * (F @ F @ P + P @ F @ F - 3 * F @ P @ F) \
        + c * (F @ P @ F @ F + F @ F @ P @ F)
    Jinv = np.eye(3) - 0.5 * F + c1 * (F @ F)
    got = right_jacobian_inverse(xi)
    assert np.abs(got[big, :3, :3] - Jinv).max() < 1e-13 and np.abs(got[big, 3:, 3:] - Jinv).max() < 1e-13
    assert np.abs(got[big, :3, 3:] + Jinv @ Q @ Jinv).max() < 1e-12 * np.abs(xi).max()
    assert np.array_equal(got[:, 3:, :3], np.zeros((300, 3, 3)))
    # the Taylor side meets the closed form: continuity across θ = 0.1
    x0 = np.array([0.3, -0.2, 0.5, 0.0, 0.0, 0.1])
    lo, hi = right_jacobian_inverse(x0 * (1 - 1e-9)), right_jacobian_inverse(x0 * (1 + 1e-9))
    assert np.abs(lo - hi).max() < 1e-8


def test_right_jacobian_inverse_against_finite_differences():
    rng = np.random.default_rng(2)
    xi = np.concatenate([rng.normal(size=3), 0.5 * rng.normal(size=3)])

    def exp_se3(x):  # T = Exp(x) through V: t = V(φ) v, with V = inverse of v_inverse
        from lago_cvx.so3 import v_inverse
        return exp_so3(x[3:]), np.linalg.solve(v_inverse(x[3:]), x[:3])

    R, t = exp_se3(xi)
    J = np.empty((6, 6))
    h = 1e-6
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        out = []
        for s in (1, -1):
            Rd, td = exp_se3(s * d)
            out.append(log_se3(R @ Rd, R @ td + t))
        J[:, k] = (out[0] - out[1]) / (2 * h)
    assert np.abs(J - right_jacobian_inverse(xi)).max() < 1e-6


# ------------------------------------------------------------------ the graph type
def test_planar_graph_has_dim_2_and_3d_graph_has_dim_3(tmp_path):
    g = PoseGraph(2, [0], [1], [[1, 0]], [0], [np.eye(3)])
    assert g.dim == 2
    h = read_graph(_write(tmp_path, "\n".join([V0, V1, E01]) + "\n"))
    assert isinstance(h, PoseGraph3D) and h.dim == 3 and h.n_poses == 2 and h.n_edges == 1
    assert chi2_3d(h, *h.initial) == 0.0
    assert pickle.loads(pickle.dumps(h)).equals(h)


def test_graph_type_rejects_bad_data():
    R = np.eye(3)[None]
    with pytest.raises(GraphError, match="not a rotation"):
        PoseGraph3D(2, [0], [1], [[1, 0, 0]], 2 * R, [np.eye(6)])
    with pytest.raises(GraphError, match="positive definite"):
        PoseGraph3D(2, [0], [1], [[1, 0, 0]], R, [-np.eye(6)])
    with pytest.raises(GraphError, match="self-loop"):
        PoseGraph3D(2, [1], [1], [[1, 0, 0]], R, [np.eye(6)])


def test_errors_match_gtsam_convention():
    gtsam = pytest.importorskip("gtsam")
    rng = np.random.default_rng(3)
    n, m = 4, 6
    t, R = rng.normal(size=(n, 3)), exp_so3(rng.normal(size=(n, 3)))
    tails, heads = np.array([0, 1, 2, 3, 0, 1]), np.array([1, 2, 3, 0, 2, 3])
    dR = exp_so3(rng.normal(size=(m, 3)))
    A = rng.normal(size=(m, 6, 6))
    info = A @ np.swapaxes(A, 1, 2) + 6 * np.eye(6)
    g = PoseGraph3D(n, tails, heads, rng.normal(size=(m, 3)), dR, info, cost="gtsam")
    fg, vals = gtsam.NonlinearFactorGraph(), gtsam.Values()
    perm = [3, 4, 5, 0, 1, 2]  # GTSAM orders the tangent (rotation, translation)
    for k in range(m):
        fg.add(gtsam.BetweenFactorPose3(int(tails[k]), int(heads[k]), gtsam.Pose3(gtsam.Rot3(dR[k]), g.delta_t[k]),
                                        gtsam.noiseModel.Gaussian.Information(info[k][np.ix_(perm, perm)])))
    for i in range(n):
        vals.insert(i, gtsam.Pose3(gtsam.Rot3(R[i]), t[i]))
    assert chi2_3d(g, t, R) == pytest.approx(2 * fg.error(vals), rel=1e-12)
    assert edge_errors3d(g, t, R).shape == (m, 6)
    # the default cost of a hand-built graph is g2o's; the gtsam cost stays reachable by name
    h = PoseGraph3D(n, tails, heads, g.delta_t, dR, info)
    assert h.cost == "g2o" and chi2_3d(h, t, R, cost="gtsam") == chi2_3d(g, t, R)
    assert chi2_3d(h, t, R) != pytest.approx(chi2_3d(g, t, R), rel=1e-3)


# ------------------------------------------------------------------ files
def test_round_trip_reproduces_the_graph(tmp_path):
    rng = np.random.default_rng(4)
    n = 6
    t, R = rng.normal(size=(n, 3)), exp_so3(rng.normal(size=(n, 3)))
    A = rng.normal(size=(n - 1, 6, 6))
    g = PoseGraph3D(n, np.arange(n - 1), np.arange(1, n), rng.normal(size=(n - 1, 3)),
                    exp_so3(rng.normal(size=(n - 1, 3))), A @ np.swapaxes(A, 1, 2) + np.eye(6), initial_t=t,
                    initial_R=R, ids=np.arange(n) * 3 + 7)
    p = write_graph(tmp_path / "w.g2o", g)
    h = read_graph(p)
    assert h.equals(g, rtol=1e-13, atol=1e-14) and h.ids.tolist() == g.ids.tolist()
    q = write_graph(tmp_path / "w2.g2o", h)
    assert read_graph(q).equals(h, rtol=1e-14, atol=1e-15)  # quaternion → R → quaternion: rounding only
    assert detect_format(p) == "g2o"


@pytest.mark.parametrize("name", ["pose3example.txt", "pose3example-grid.txt", "pose3example-offdiagonal.txt"])
def test_gtsam_example_files(name):
    p = dataset_path(f"gtsam/{name}")
    g = read_graph(p)
    assert g.dim == 3 and g.initial is not None
    if name == "pose3example-offdiagonal.txt":  # its information has off-diagonal entries 1 … 5
        assert g.information[0, 0, 1] == 1.0 and g.information[0, 4, 5] == 5.0


def test_edge_only_3d_file(tmp_path):
    g = read_graph(_write(tmp_path, f"{E01}\n" + E01.replace(" 0 1 ", " 1 5 ", 1)))
    assert g.initial is None and g.ids.tolist() == [0, 1, 5]


BAD = [
    (f"{V0}\n{V1} 2\n", 2, "VERTEX_SE3:QUAT expects 8 numbers after the tag, got 9"),
    (f"{V0}\n{E01.replace(' 400', '', 1)}\n", 2, "EDGE_SE3:QUAT expects 30 numbers after the tag, got 29"),
    (f"{V0}\n{V1.replace(' 1 0 0 0', ' x 0 0 0', 1)}\n", 2, "non-numeric value 'x' for x"),
    (f"{V0}\n{V1}\n{E01.replace('EDGE_SE3:QUAT 0 1 1', 'EDGE_SE3:QUAT 0 1 nan', 1)}\n", 3,
     "non-finite value 'nan' for x"),
    (f"{V0}\nVERTEX_SE3:QUAT 1.5 0 0 0 0 0 0 1\n", 2, "vertex id must be an integer, got '1.5' for id"),
    (f"{V0}\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 0\n", 2, "quaternion (qx, qy, qz, qw) has zero norm: no rotation"),
    (f"{V0}\n{V1}\n{E01.replace(' 400 0 0', ' -400 0 0', 1)}\n", 3, "information matrix is not positive definite"),
    (f"{V0}\n{V0}\n", 2, "duplicate vertex id 0 (first defined on line 1)"),
    (f"{V0}\n{V1}\n{E01.replace(' 0 1 1', ' 0 7 1', 1)}\n", 3, "edge refers to vertex 7, which no VERTEX_SE3:QUAT"),
    (f"{V0}\n{V1}\n{E01.replace(' 0 1 1', ' 1 1 1', 1)}\n", 3, "self-loop edge 1 -> 1"),
    (f"{V0}\n{V1}\nVERTEX_SE2 2 0 0 0\n", 3, "mixes planar and 3-D records: planar tag 'VERTEX_SE2'"),
    (f"{V0}\nVERTEX_SE3:EXPMAP 1 0 0 0 0 0 0\n", 2, "'VERTEX_SE3:EXPMAP' is not supported"),
    (f"{V0}\nBOGUS 1\n", 2, "unknown tag 'BOGUS' (expected VERTEX_SE3:QUAT/EDGE_SE3:QUAT)"),
    ("# nothing\n", None, "file contains no vertices and no edges"),
]


@pytest.mark.parametrize("text, line, problem", BAD, ids=[b[2][:30] for b in BAD])
def test_malformed_3d_files_name_file_and_line(tmp_path, text, line, problem):
    p = _write(tmp_path, text)
    with pytest.raises(ParseError) as ei:
        read_graph(p) if line is not None else __import__("lago_cvx.io.space", fromlist=["x"]).read_graph3d(p)
    assert ei.value.line == line and ei.value.problem.startswith(problem), str(ei.value)
    assert str(ei.value).startswith(f"{p}:{line}: " if line else f"{p}: ")


def test_3d_record_in_a_planar_file_is_a_mix(tmp_path):
    p = _write(tmp_path, f"VERTEX_SE2 0 0 0 0\n{V1}\n")
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    assert ei.value.line == 2 and "cannot mix planar and 3-D records" in ei.value.problem


def test_quaternion_far_from_unit_norm_warns_once(tmp_path, caplog):
    text = "\n".join([V0, "VERTEX_SE3:QUAT 1 1 0 0 0 0 0 2", "VERTEX_SE3:QUAT 2 1 0 0 0 0 0 3",
                      E01, E01.replace(" 0 1 1 0 0 0 0 0 1", " 1 2 1 0 0 0 0 0 0.5", 1)])
    with caplog.at_level(logging.WARNING, logger="lago_cvx.io"):
        g = read_graph(_write(tmp_path, text))
    msgs = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(msgs) == 1 and "3 quaternion(s)" in msgs[0] and "first on line 2" in msgs[0], msgs
    assert np.abs(g.initial_R - np.eye(3)).max() < 1e-15


def test_gtsam_toy_example_reads_as_3d():
    import importlib.util
    from pathlib import Path
    spec = importlib.util.find_spec("gtsam")
    if spec is None or spec.origin is None or not (Path(spec.origin).parent / "Data" / "toyExample.g2o").is_file():
        pytest.skip("gtsam's Data/toyExample.g2o not installed")
    g = read_graph(Path(spec.origin).parent / "Data" / "toyExample.g2o")
    assert g.dim == 3 and g.n_poses > 1


# ------------------------------------------------------------------ the vectorized reader
def _careful(monkeypatch, path):
    """The graph read line by line (the vectorized path switched off)."""
    import lago_cvx.io.space as space

    with monkeypatch.context() as m:
        m.setattr(space, "parse_fast", lambda *a, **k: None)
        return space.read_graph3d(path)


@pytest.mark.parametrize("variant", ["plain", "crlf+comments+fix", "edges only"])
def test_vectorized_reader_equals_the_careful_one(tmp_path, monkeypatch, variant):
    """3-D files are read by the planar files' vectorized path (``fastpath.parse_fast`` with the 3-D record types);
    whatever it returns is bit for bit what the line-by-line reader gives, and it does read ordinary files."""
    import lago_cvx.io.space as space
    from lago_cvx.synthetic import space as space3d

    p = write_graph(tmp_path / "w.g2o", space3d.sphere_world(10, 20, seed=5).graph)
    lines = p.read_text().splitlines()
    if variant == "crlf+comments+fix":
        lines = ["# a comment", "FIX 0"] + [ln + ("   # note" if k % 7 == 0 else "") for k, ln in enumerate(lines)]
        p.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    elif variant == "edges only":
        p.write_text("\n".join(ln for ln in lines if ln.startswith("EDGE")) + "\n")
    fast_calls = []
    real_fast = space.parse_fast
    monkeypatch.setattr(space, "parse_fast", lambda *a, **k: fast_calls.append(real_fast(*a, **k)) or fast_calls[-1])
    fast = space.read_graph3d(p)
    assert fast_calls and fast_calls[0] is not None, "the vectorized path gave up on an ordinary file"
    slow = _careful(monkeypatch, p)
    for name in ("tails", "heads", "delta_t", "delta_R", "information", "ids"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert (fast.initial is None) == (slow.initial is None) == (variant == "edges only")


def test_positive_definiteness_test_agrees_with_eigenvalues():
    from lago_cvx.posegraph3d import is_spd6, ldl_pivots

    rng = np.random.default_rng(7)
    B = rng.normal(size=(3000, 6, 6))
    S = B @ np.swapaxes(B, 1, 2) - rng.uniform(0, 0.3, size=(3000, 1, 1)) * np.eye(6)  # some indefinite
    S[0, 2, 3] += 1e-3                                                             # not symmetric
    S[1, 4, 4] = np.nan
    S[2] = 0.0
    ev = np.linalg.eigvalsh(np.nan_to_num(S))
    expected = ev[:, 0] > 0
    expected[:3] = False
    clear = np.abs(ev[:, 0]) > 1e-6 * np.abs(ev).max(axis=1)  # far from singular: no rounding decides the answer
    clear[:3] = True
    before = S.copy()
    got = is_spd6(S)
    assert np.array_equal(got[clear], expected[clear]) and clear.mean() > 0.99 and 0.1 < got.mean() < 0.9
    assert np.array_equal(S, before, equal_nan=True), "is_spd6 changed its argument"
    k = 3 + int(np.flatnonzero(clear[3:])[0])
    assert is_spd6(S[k:k + 1])[0] == expected[k] and np.array_equal(S, before, equal_nan=True)
    d = ldl_pivots(S[3:50])
    assert np.allclose(d.prod(axis=1), np.linalg.det(S[3:50]), rtol=1e-9)
