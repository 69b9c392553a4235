"""Tests of lago_cvx.io: g2o / TORO reading and writing, the TORO information convention, and
every class of bad input (each must give a one-line ParseError naming the file and the line)."""

from __future__ import annotations

import logging
import os
import pickle
import random
import time

import numpy as np
import pytest

from helpers import corrupt_tokens
from lago_cvx.datasets import DATASET_TABLE
from conftest import dataset_path

import lago_cvx.io as lio
from lago_cvx.io import ParseError, detect_format, read_graph, write_graph
from lago_cvx.metrics import chi2
from lago_cvx.posegraph import PoseGraph, rot2

TORO_FILES = {rel for rel, *_ in DATASET_TABLE if rel.endswith("_toro.graph")}
UNIT = "1 0 0 1 0 1"  # identity information, g2o order


def _write(tmp_path, text, name="g.g2o"):
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


def _chain(n=4, start=0, step=1, fmt="g2o"):
    """A small valid file: n vertices and the odometric chain between them."""
    v, e = ("VERTEX_SE2", "EDGE_SE2") if fmt == "g2o" else ("VERTEX2", "EDGE2")
    info = UNIT if fmt == "g2o" else "1 0 1 1 0 0"
    ids = [start + k * step for k in range(n)]
    lines = [f"{v} {i} {k}.0 0.5 0.1" for k, i in enumerate(ids)]
    lines += [f"{e} {a} {b} 1.0 0.0 0.0 {info}" for a, b in zip(ids, ids[1:])]
    return "\n".join(lines) + "\n"


# ============================================================================ real datasets
@pytest.mark.parametrize("row", DATASET_TABLE, ids=[r[0] for r in DATASET_TABLE])
def test_dataset_counts_and_round_trip(row, tmp_path):
    rel, n, m, n_odo, n_lc = row
    src = dataset_path(rel)
    g = read_graph(src)
    assert (g.n_poses, g.n_edges, g.n_odometric, g.n_loop_closures) == (n, m, n_odo, n_lc)
    assert g.name == src.name
    assert detect_format(src) == ("toro" if rel in TORO_FILES else "g2o")

    # read -> write g2o -> read is bit-identical. A TORO file written as g2o means the same cost: read back (in
    # g2o's cost), its information of eq. (3) is the TORO file's to rounding, and χ² is the same at any poses.
    out = write_graph(tmp_path / "out.g2o", g, wrap_angles=False)
    g2 = read_graph(out)
    if rel in TORO_FILES:
        assert (g.cost, g2.cost) == ("paper", "g2o")
        assert np.array_equal(g2.measurements, g.measurements) and np.array_equal(g2.initial, g.initial)
        scale = np.abs(g.information).max(axis=(1, 2))[:, None, None]
        assert (np.abs(g2.information - g.information) / scale).max() <= 1e-12
        assert chi2(g2, g.initial) == pytest.approx(chi2(g, g.initial), rel=1e-12)
        g = g2
    else:
        assert g.cost == "g2o"
        assert g.equals(g2, rtol=0.0, atol=0.0)
    assert g2.name == "out.g2o"

    # With the default angle wrapping only out-of-range vertex angles change, by multiples of 2π.
    g3 = read_graph(write_graph(tmp_path / "wrapped.g2o", g))
    if g.initial is None:
        assert g3.initial is None
    else:
        assert np.array_equal(g3.initial[:, :2], g.initial[:, :2])
        th = g3.initial[:, 2]
        assert np.all((th >= -np.pi) & (th < np.pi))
        k = (g.initial[:, 2] - th) / (2 * np.pi)
        assert np.allclose(k, np.round(k), atol=1e-9)
        assert np.array_equal(th[k == 0], g.initial[k == 0, 2])  # in-range angles kept bit for bit
    assert g.with_initial(g3.initial).equals(g3)

    if rel in TORO_FILES:  # TORO -> TORO: no conversion, bit for bit
        toro = read_graph(src)
        g4 = read_graph(write_graph(tmp_path / "out.graph", toro, format="toro", wrap_angles=False))
        assert detect_format(tmp_path / "out.graph") == "toro"
        assert g4.equals(toro, rtol=0.0, atol=0.0)


def _raw_toro_information(path):
    """TORO information matrices exactly as written in the file (no conversion), parsed here
    independently of lago_cvx.io: EDGE2 i j dx dy dθ Ixx Ixy Iyy Iθθ Ixθ Iyθ."""
    rows = [ln.split()[1:] for ln in path.read_text().splitlines() if ln.startswith("EDGE2")]
    a = np.array(rows, dtype=float)
    xx, xy, yy, tt, xt, yt = a[:, 5:].T
    info = np.stack([np.stack([xx, xy, xt], -1), np.stack([xy, yy, yt], -1),
                     np.stack([xt, yt, tt], -1)], -2)
    return a[:, 4], info


def _max_rel_diff(a, b):
    """Largest entry-wise difference, relative to each matrix's largest entry."""
    scale = np.maximum(np.abs(a).max(axis=(1, 2)), np.abs(b).max(axis=(1, 2)))[:, None, None]
    return float((np.abs(a - b) / scale).max())


@pytest.mark.parametrize("g2o_rel, toro_rel", [("se-sync/manhattan.g2o", "carlone/M3500_P_toro.graph"),
                                               ("se-sync/CSAIL.g2o", "carlone/CSAIL_P_toro.graph")])
def test_toro_twins_are_one_graph_each_in_its_own_cost(g2o_rel, toro_rel):
    g2o_path, toro_path = dataset_path(g2o_rel), dataset_path(toro_rel)
    a, b = read_graph(g2o_path), read_graph(toro_path)
    assert (a.cost, b.cost) == ("g2o", "paper")  # each file's own cost
    assert a.initial is None and b.initial is not None  # the SE-Sync twins are edge-only
    assert np.array_equal(a.ids, b.ids)
    assert np.array_equal(a.tails, b.tails) and np.array_equal(a.heads, b.heads)
    assert np.array_equal(a.measurements, b.measurements)
    # g2o's matrices taken into eq. (3)'s frame (T Ω Tᵀ, T = blkdiag(R(dθ), 1)) are TORO's as written, to the 6
    # printed digits: the same cost at every pose.
    assert _max_rel_diff(a.information, b.information) < 1e-4
    assert chi2(a, b.initial) == pytest.approx(chi2(b, b.initial), rel=1e-4)

    # The convention is proved, not assumed: the raw TORO matrices (correct slot order, no rotation) are not
    # g2o's as written, g2o's rotated by hand here are, and the opposite rotation is not.
    dtheta, raw = _raw_toro_information(toro_path)
    assert np.array_equal(dtheta, a.delta)
    assert np.array_equal(raw, b.information)
    g2o_written = a.information_in("measurement")
    assert _max_rel_diff(g2o_written, raw) > 1e-2
    T = np.zeros_like(raw)
    T[:, :2, :2] = rot2(dtheta)
    T[:, 2, 2] = 1
    assert _max_rel_diff(T @ g2o_written @ np.swapaxes(T, 1, 2), raw) < 1e-4
    assert _max_rel_diff(np.swapaxes(T, 1, 2) @ g2o_written @ T, raw) > 1e-2


# ============================================================================ TORO conventions
def test_toro_information_order(tmp_path):
    # EDGE2 i j dx dy dθ Ixx Ixy Iyy Iθθ Ixθ Iyθ with dθ = 0: no rotation, only the slot order.
    p = _write(tmp_path, "EDGE2 0 1 1.5 -0.5 0 10 1 20 30 2 3\n", "t.graph")
    g = read_graph(p)
    expected = np.array([[10.0, 1.0, 2.0], [1.0, 20.0, 3.0], [2.0, 3.0, 30.0]])
    assert np.array_equal(g.information[0], expected)
    assert np.array_equal(g.delta_l[0], [1.5, -0.5]) and g.delta[0] == 0.0
    # The same numbers read as g2o (I11 I12 I13 I22 I23 I33) land elsewhere.
    q = _write(tmp_path, "EDGE_SE2 0 1 1.5 -0.5 0 10 1 2 20 3 30\n")
    assert np.array_equal(read_graph(q).information[0], expected)


def test_information_frame_of_each_cost(tmp_path):
    # TORO's matrices are eq. (3)'s as written. A g2o EDGE_SE2 with dθ = π/2 and translational information
    # diag(1, 4) in the measurement's frame is diag(4, 1) in the tail's frame; the x-θ / y-θ cross terms rotate
    # with it: [Ixθ, Iyθ] -> R(dθ) [Ixθ, Iyθ].
    p = _write(tmp_path, f"EDGE2 0 1 1 0 {np.pi / 2!r} 1 0 4 9 0.5 0.25\n", "t.graph")
    toro = read_graph(p)
    assert toro.cost == "paper" and toro.given_information is None
    assert np.array_equal(toro.information[0], [[1, 0, 0.5], [0, 4, 0.25], [0.5, 0.25, 9]])
    q = _write(tmp_path, f"EDGE_SE2 0 1 1 0 {np.pi / 2!r} 1 0 0.5 4 0.25 9\n")
    g = read_graph(q)
    info = g.information[0]
    assert g.cost == "g2o"
    assert np.allclose(info[:2, :2], np.diag([4.0, 1.0]), atol=1e-14)
    assert np.allclose(info[:2, 2], [-0.25, 0.5], atol=1e-14)
    assert info[2, 2] == 9.0 and np.array_equal(info, info.T)
    assert np.array_equal(g.given_information[0], toro.information[0])  # kept as written, for writing back
    # cost="paper" reads the g2o file's matrices as eq. (3)'s; cost="g2o" reads TORO's as g2o's.
    assert np.array_equal(read_graph(q, cost="paper").information, toro.information)
    assert np.array_equal(read_graph(p, cost="g2o").information, g.information)
    assert read_graph(q, cost="gtsam").equals(g.with_cost("gtsam")) and g.with_cost("paper").equals(
        read_graph(q, cost="paper"))


def test_toro_write_format(tmp_path):
    g = read_graph(_write(tmp_path, "EDGE2 0 1 1.5 -0.5 0 10 1 20 30 2 3\n", "t.graph"))
    out = write_graph(tmp_path / "o.graph", g, format="toro")
    assert out.read_text() == "EDGE2 0 1 1.5 -0.5 0.0 10.0 1.0 20.0 30.0 2.0 3.0\n"
    out = write_graph(tmp_path / "o.g2o", g)
    assert out.read_text() == "EDGE_SE2 0 1 1.5 -0.5 0.0 10.0 1.0 2.0 20.0 3.0 30.0\n"


def test_format_argument(tmp_path):
    p = _write(tmp_path, _chain(fmt="toro"), "t.graph")
    assert read_graph(p, format="toro").equals(read_graph(p))
    with pytest.raises(ParseError) as ei:
        read_graph(p, format="g2o")
    assert ei.value.line == 1 and "TORO tag 'VERTEX2' in a file read as g2o" in str(ei.value)
    with pytest.raises(ValueError):
        read_graph(p, format="xml")


def test_detect_format(tmp_path):
    assert detect_format(_write(tmp_path, "# c\n\nFIX 0\n" + _chain())) == "g2o"
    assert detect_format(_write(tmp_path, "  # c\r\n" + _chain(fmt="toro"))) == "toro"
    with pytest.raises(ParseError) as ei:
        detect_format(_write(tmp_path, "# only\n\n"))
    assert ei.value.line is None
    with pytest.raises(ParseError) as ei:
        detect_format(_write(tmp_path, "\nBAR 1 2\n"))
    assert ei.value.line == 2 and "unknown tag 'BAR'" in ei.value.problem


# ============================================================================ bad inputs
V = "VERTEX_SE2 {} 0 0 0"
E = "EDGE_SE2 {} {} 1 0 0 " + UNIT
GOOD_HEAD = [V.format(0), V.format(1), V.format(2), E.format(0, 1), E.format(1, 2)]  # lines 1-5

# (case id, lines after GOOD_HEAD or full bytes, expected line, expected text in the problem)
BAD = [
    ("unknown_tag", ["FOO 1 2 3"], 6, "unknown tag 'FOO' (expected VERTEX_SE2/EDGE_SE2 or VERTEX2/EDGE2)"),
    ("arity_edge", ["EDGE_SE2 0 2 1 0 0 1 0 0 1"], 6, "EDGE_SE2 expects 11 numbers after the tag, got 9"),
    ("arity_vertex", ["VERTEX_SE2 3 0 0 0 0"], 6, "VERTEX_SE2 expects 4 numbers after the tag, got 5"),
    ("non_numeric", ["EDGE_SE2 0 2 abc 0 0 " + UNIT], 6, "non-numeric value 'abc' for dx"),
    ("non_numeric_tail", ["EDGE_SE2 0 2 1 0 0 1 0 0 1 0 1x"], 6, "non-numeric value '1x' for I33"),
    ("non_ascii_digit", ["VERTEX_SE2 3 \u0663 0 0"], 6, "non-numeric value '\u0663' for x"),
    ("fullwidth_digit", ["VERTEX_SE2 3 0 \uff11 0"], 6, "non-numeric value '\uff11' for y"),
    ("underscore", ["VERTEX_SE2 3 1_000 0 0"], 6, "non-numeric value '1_000' for x"),
    ("nan", ["EDGE_SE2 0 2 1 0 0 1 0 0 nan 0 1"], 6, "non-finite value 'nan' for I22"),
    ("inf", ["EDGE_SE2 0 2 1 0 -inf " + UNIT], 6, "non-finite value '-inf' for dtheta"),
    ("overflow", ["VERTEX_SE2 3 0 1e999 0"], 6, "non-finite value '1e999' for y"),
    ("two_numbers_in_token", ["VERTEX_SE2 3 1-2 0 0"], 6, "non-numeric value '1-2' for x"),
    ("not_pd", ["EDGE_SE2 0 2 1 0 0 1 2 0 1 0 1"], 6, "information matrix is not positive definite (eigenvalues -1,"),
    ("zero_info", ["EDGE_SE2 0 2 1 0 0 0 0 0 0 0 0"], 6, "information matrix is not positive definite"),
    ("duplicate_vertex", ["VERTEX_SE2 1 5 5 5"], 6, "duplicate vertex id 1 (first defined on line 2)"),
    ("unknown_vertex", ["EDGE_SE2 2 12 1 0 0 " + UNIT], 6, "edge refers to vertex 12, which no VERTEX line defines"),
    ("self_loop", ["EDGE_SE2 2 2 1 0 0 " + UNIT], 6, "self-loop edge 2 -> 2"),
    ("undecodable", b"EDGE_SE2 0 2 1 0 \xff\xfe 1 0 0 1 0 1", 6, "undecodable bytes b'\\xff\\xfe' in dtheta"),
    ("undecodable_tag", b"\xffEDGE_SE2 0 2 1 0 0 1 0 0 1 0 1", 6, "undecodable bytes b'\\xffEDGE_SE2' in the tag"),
    ("latin1_word", "VERTEX_SE2 3 caf\u00e9 0 0".encode("latin-1"), 6, "undecodable bytes b'caf\\xe9' in x"),
    ("mixed", ["EDGE2 0 2 1 0 0 1 0 1 1 0 0"], 6,
     "mixes g2o and TORO tags (TORO tag 'EDGE2' here, g2o tag seen on line 1)"),
    ("float_id", ["VERTEX_SE2 3.0 0 0 0"], 6, "vertex id must be an integer, got '3.0' for id"),
    ("exp_id", ["EDGE_SE2 0 1e2 1 0 0 " + UNIT], 6, "vertex id must be an integer, got '1e2' for j"),
    ("huge_id", ["VERTEX_SE2 99999999999999999999 0 0 0"], 6, "out of range"),
    ("fix_float", ["FIX 0.5"], 6, "vertex id must be an integer, got '0.5' for id"),
    ("fix_empty", ["FIX"], 6, "FIX expects at least one vertex id"),
    ("nbsp", ["VERTEX_SE2 3\u00a00 0 0"], 6, "non-ASCII whitespace U+00A0"),
    ("tag_case", ["edge_se2 0 2 1 0 0 " + UNIT], 6, "unknown tag 'edge_se2'"),
]


def _bad_file(tmp_path, extra, name="bad.g2o", pad=0):
    """GOOD_HEAD (+ ``pad`` more good vertex and edge lines, ids from 100 on, so that the bulk
    conversion has real work to do before it fails) + the bad line(s)."""
    head = (GOOD_HEAD[:3] + [V.format(k) for k in range(100, 100 + pad)] + GOOD_HEAD[3:]
            + [E.format(k, k + 1) for k in range(100, 99 + pad)])
    text = ("\n".join(head) + "\n").encode()
    text += extra if isinstance(extra, bytes) else ("\n".join(extra) + "\n").encode()
    return _write(tmp_path, text, name), len(head)


def _check(err: ParseError, path, line, text):
    msg = str(err)
    assert isinstance(err, ValueError)
    assert "\n" not in msg
    assert err.path == str(path)
    assert err.line == line
    assert text in err.problem, err.problem
    if line is None:
        assert msg == f"{path}: {err.problem}"
    else:
        assert msg == f"{path}:{line}: {err.problem}"
        assert f"{path.name}:{line}:" in msg


@pytest.mark.parametrize("pad", [0, 2000], ids=["small", "bulk"])
@pytest.mark.parametrize("case, extra, line, text", BAD, ids=[b[0] for b in BAD])
def test_bad_input(tmp_path, case, extra, line, text, pad):
    p, n_head = _bad_file(tmp_path, extra, pad=pad)
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    _check(ei.value, p, line - 5 + n_head, text)


def test_bad_toro_fields(tmp_path):
    p = _write(tmp_path, "VERTEX2 0 0 0 0\nVERTEX2 1 0 0 0\nEDGE2 0 1 1 0 0 1 0 x 1 0 0\n", "t.graph")
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    _check(ei.value, p, 3, "non-numeric value 'x' for Iyy")


@pytest.mark.parametrize("content", [b"", b"\n\n  \r\n\t\n", b"# a comment\n  # another\n\n", b"FIX 0\n"],
                         ids=["empty", "blank", "comments_only", "fix_only"])
def test_no_data(tmp_path, content):
    p = _write(tmp_path, content)
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    _check(ei.value, p, None, "file contains no vertices and no edges")


def test_missing_file(tmp_path):
    p = tmp_path / "nope.g2o"
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    _check(ei.value, p, None, "cannot read file")
    assert "nope.g2o" in str(ei.value)
    with pytest.raises(ParseError):
        detect_format(p)
    with pytest.raises(ParseError) as ei:
        read_graph(tmp_path)  # a directory
    assert ei.value.line is None


def test_first_problem_wins(tmp_path):
    # A lexical problem on line 4 is reported before the structural one on line 6 ...
    p = _write(tmp_path, "\n".join([V.format(0), V.format(1), V.format(2), "VERTEX_SE2 3 x 0 0",
                                    E.format(0, 1), "FOO"]) + "\n")
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    assert ei.value.line == 4
    # ... and among semantic problems the earliest line wins (duplicate on 3, self-loop on 4,
    # non-PD information on 5).
    p = _write(tmp_path, "\n".join([V.format(0), V.format(1), V.format(0), E.format(1, 1),
                                    "EDGE_SE2 0 1 1 0 0 -1 0 0 1 0 1"]) + "\n")
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    assert ei.value.line == 3 and "duplicate vertex id 0 (first defined on line 1)" in ei.value.problem


def test_parse_error_object():
    e = ParseError("data/x.g2o", 17, "EDGE_SE2 expects 11 numbers after the tag, got 9")
    assert str(e) == "data/x.g2o:17: EDGE_SE2 expects 11 numbers after the tag, got 9"
    assert (e.path, e.line, e.problem) == ("data/x.g2o", 17, "EDGE_SE2 expects 11 numbers after the tag, got 9")
    e2 = pickle.loads(pickle.dumps(e))
    assert str(e2) == str(e) and e2.line == 17
    assert str(ParseError("x.g2o", None, "file contains no vertices and no edges")) == \
        "x.g2o: file contains no vertices and no edges"


# ============================================================================ accepted oddities
def test_comments_blank_lines_crlf_tabs(tmp_path):
    plain = read_graph(_write(tmp_path, _chain(), "plain.g2o"))
    odd = ("# header comment\r\n\r\n"
           "VERTEX_SE2\t0  0.0\t0.5 0.1\r\n"
           "   # indented comment with ünïcödé\r\n"
           "\tVERTEX_SE2 1 1.0 0.5 0.1   \r\n"
           "VERTEX_SE2 2 2.0 0.5 0.1\r\n\r\n"
           "VERTEX_SE2 3 3.0 0.5 0.1\r\n"
           "EDGE_SE2 0 1 1.0 0.0 0.0 1 0 0 1 0 1\r\n"
           "EDGE_SE2\t1\t2\t1.0\t0.0\t0.0\t1\t0\t0\t1\t0\t1\r\n"
           "EDGE_SE2 2 3 1.0 0.0 0.0 1 0 0 1 0 1")  # no final newline
    g = read_graph(_write(tmp_path, odd, "odd.g2o"))
    assert g.equals(plain)


def test_classic_mac_line_endings_are_lines(tmp_path):
    """A file whose lines end in CR alone (classic Mac OS) reads as its LF twin, planar, TORO and 3-D; a CR inside
    a file of LF lines is left to the parser as before."""
    from lago_cvx.io import write_graph
    from lago_cvx.synthetic.space import sphere_world

    three = tmp_path / "three.g2o"
    write_graph(three, sphere_world(3, 4, seed=0).graph)
    for lf in (_write(tmp_path, _chain(), "lf.g2o"), _write(tmp_path, _chain(fmt="toro"), "lf.graph"), three):
        cr = tmp_path / f"cr{lf.suffix}"
        cr.write_bytes(lf.read_bytes().replace(b"\n", b"\r"))
        assert b"\n" not in cr.read_bytes() and read_graph(cr).equals(read_graph(lf))
        assert detect_format(cr) == detect_format(lf)


def test_comment_with_undecodable_bytes_is_ignored(tmp_path):
    p = _write(tmp_path, b"# caf\xe9 (latin-1 comment)\n" + _chain().encode())
    assert read_graph(p).n_poses == 4


def test_utf8_bom(tmp_path):
    p = _write(tmp_path, b"\xef\xbb\xbf" + _chain().encode())
    assert read_graph(p).n_edges == 3


def test_edge_only_file(tmp_path):
    text = "EDGE_SE2 0 1 1 0 0 " + UNIT + "\nEDGE_SE2 1 2 1 0 0 " + UNIT + "\n"
    g = read_graph(_write(tmp_path, text))
    assert g.n_poses == 3 and g.initial is None
    assert np.array_equal(g.ids, [0, 1, 2])
    out = write_graph(tmp_path / "o.g2o", g)
    assert "VERTEX" not in out.read_text()
    assert read_graph(out).equals(g)
    # Edge-only ids need not be contiguous: the pose set is the ids that appear.
    g = read_graph(_write(tmp_path, "EDGE_SE2 7 3 1 0 0 " + UNIT + "\n"))
    assert np.array_equal(g.ids, [3, 7]) and g.tails[0] == 1 and g.heads[0] == 0


def test_vertices_without_edges(tmp_path):
    g = read_graph(_write(tmp_path, "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"))
    assert g.n_poses == 2 and g.n_edges == 0 and g.initial.shape == (2, 3)
    assert read_graph(write_graph(tmp_path / "o.g2o", g)).equals(g)


def test_backward_and_parallel_edges(tmp_path):
    text = _chain() + "EDGE_SE2 3 0 -3 0 0 " + UNIT + "\n" + "EDGE_SE2 3 0 -3 0.1 0 " + UNIT + "\n" \
        + "EDGE_SE2 0 1 1.0 0.0 0.0 " + UNIT + "\n"
    g = read_graph(_write(tmp_path, text))
    assert g.n_edges == 6
    assert g.tails.tolist() == [0, 1, 2, 3, 3, 0] and g.heads.tolist() == [1, 2, 3, 0, 0, 1]
    assert g.delta_l[4, 1] == 0.1
    assert read_graph(write_graph(tmp_path / "o.g2o", g)).equals(g)


def test_non_contiguous_ids_round_trip(tmp_path):
    text = ("VERTEX_SE2 30 2 0 0\nVERTEX_SE2 10 0 0 0\nVERTEX_SE2 20 1 0 0\n"
            "EDGE_SE2 10 20 1 0 0 " + UNIT + "\nEDGE_SE2 20 30 1 0 0 " + UNIT + "\n"
            "EDGE_SE2 30 10 -2 0 0 " + UNIT + "\n")
    g = read_graph(_write(tmp_path, text))
    assert g.ids.tolist() == [10, 20, 30]
    assert g.tails.tolist() == [0, 1, 2] and g.heads.tolist() == [1, 2, 0]
    assert g.initial[:, 0].tolist() == [0, 1, 2]  # vertex poses sorted by id
    assert g.n_odometric == 0  # |id_i - id_j| = 10, not 1
    out = write_graph(tmp_path / "o.g2o", g)
    assert "VERTEX_SE2 10 " in out.read_text() and "EDGE_SE2 30 10 " in out.read_text()
    assert read_graph(out).equals(g)
    g_neg = read_graph(_write(tmp_path, _chain(start=-5, step=3), "neg.g2o"))
    assert g_neg.ids.tolist() == [-5, -2, 1, 4]
    assert read_graph(write_graph(tmp_path / "neg_out.g2o", g_neg)).equals(g_neg)


def test_large_ids(tmp_path):
    big = 2 ** 62 + 1  # beyond double precision: exercises the token-by-token path
    text = f"VERTEX_SE2 {big} 0 0 0\nVERTEX_SE2 {big + 1} 1 0 0\nEDGE_SE2 {big} {big + 1} 1 0 0 {UNIT}\n"
    g = read_graph(_write(tmp_path, text))
    assert g.ids.tolist() == [big, big + 1] and g.n_odometric == 1
    assert read_graph(write_graph(tmp_path / "o.g2o", g)).equals(g)


def test_fix_lines_are_ignored_with_one_warning(tmp_path, caplog):
    p = _write(tmp_path, "FIX 0\n" + _chain() + "FIX 1 2\n")
    with caplog.at_level(logging.INFO, logger="lago_cvx.io"):
        g = read_graph(p)
    assert g.equals(read_graph(_write(tmp_path, _chain(), "plain.g2o")))
    msgs = [r for r in caplog.records if r.name == "lago_cvx.io" and "FIX" in r.getMessage()]
    assert len(msgs) == 1 and msgs[0].levelno == logging.WARNING
    assert ": ignoring 2 FIX line(s) (the first on line 1: FIX 0)" in msgs[0].getMessage()


def test_number_syntax_accepted(tmp_path):
    text = "VERTEX_SE2 +0 .5 5. -1.5E+2\nVERTEX_SE2 001 1e-3 -0 +2.25e1\nEDGE_SE2 0 1 1 0 0 " + UNIT + "\n"
    g = read_graph(_write(tmp_path, text))
    assert g.ids.tolist() == [0, 1]
    assert g.initial.tolist() == [[0.5, 5.0, -150.0], [0.001, 0.0, 22.5]]


def test_read_write_read_bit_identical(tmp_path):
    rng = np.random.default_rng(3)
    n, m = 40, 90
    tails = np.concatenate([np.arange(n - 1), rng.integers(0, n, m - n + 1)])
    heads = np.concatenate([np.arange(1, n), rng.integers(0, n, m - n + 1)])
    heads = np.where(heads == tails, (heads + 1) % n, heads)
    A = rng.normal(size=(m, 3, 3))
    info = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)
    info = 0.5 * (info + np.swapaxes(info, 1, 2))
    init = rng.normal(size=(n, 3)) * [100, 1e-7, 1]
    init[:, 2] = np.clip(init[:, 2], -3, 3)
    g = PoseGraph(n, tails, heads, rng.normal(size=(m, 2)) * 1e5, rng.normal(size=m) * 7, info,
                  initial=init, ids=np.arange(n) * 7 + 100)
    # A graph built in Python holds eq. (3)'s information (cost "paper"): TORO keeps it bit for bit; g2o's frame
    # is a rotation away, so the g2o file read back is the same cost to rounding, and bit for bit from then on.
    g3 = read_graph(write_graph(tmp_path / "r.graph", g, format="toro"))
    assert g3.cost == "paper" and g.equals(g3)  # rtol = atol = 0 by default
    g2 = read_graph(write_graph(tmp_path / "r.g2o", g))
    assert g2.cost == "g2o" and g2.equals(g, rtol=1e-12) and not g2.equals(g)
    assert chi2(g2, init) == pytest.approx(chi2(g, init), rel=1e-12)
    assert read_graph(write_graph(tmp_path / "r2.g2o", g2)).equals(g2)


# ============================================================================ write_graph
def test_write_atomic_and_wrapped(tmp_path):
    g = read_graph(_write(tmp_path, _chain(), "in.g2o"))
    poses = np.array([[0, 0, 3.5], [1, 0, -4.0], [2, 0, 0.1], [3, 0, np.pi]])
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    target = out_dir / "w.g2o"
    assert write_graph(target, g, poses) == target
    assert sorted(os.listdir(out_dir)) == ["w.g2o"]  # no temporary file left behind
    th = read_graph(target).initial[:, 2]
    assert np.all((th >= -np.pi) & (th < np.pi))
    assert np.allclose(np.cos(th), np.cos(poses[:, 2])) and np.allclose(np.sin(th), np.sin(poses[:, 2]))
    assert th[2] == 0.1  # in-range angles are written bit for bit
    assert th[3] == -np.pi  # π itself maps to −π
    # Edge angles are written as stored; wrap_angles=False keeps vertex angles as given.
    raw = read_graph(write_graph(target, g, poses, wrap_angles=False))
    assert np.array_equal(raw.initial, poses)
    assert sorted(os.listdir(out_dir)) == ["w.g2o"]


def test_write_failure_leaves_old_file(tmp_path, monkeypatch):
    g = read_graph(_write(tmp_path, _chain(), "in.g2o"))
    target = tmp_path / "w.g2o"
    target.write_text("old\n")

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(lio.output.os, "replace", boom)
    with pytest.raises(OSError) as ei:  # an OutputError naming the target, never the temporary file
        write_graph(target, g)
    assert str(ei.value) == f"cannot write {target}: disk full"
    assert target.read_text() == "old\n"
    assert sorted(os.listdir(tmp_path)) == ["in.g2o", "w.g2o"]


def test_write_keeps_permissions_and_checks_poses(tmp_path):
    g = read_graph(_write(tmp_path, _chain(), "in.g2o"))
    target = tmp_path / "w.g2o"
    target.write_text("old\n")
    os.chmod(target, 0o640)
    write_graph(target, g)
    assert os.stat(target).st_mode & 0o777 == 0o640
    with pytest.raises(ValueError):
        write_graph(tmp_path / "x.g2o", g, np.zeros((3, 3)))
    with pytest.raises(ValueError):
        write_graph(tmp_path / "x.g2o", g, format="xml")
    assert not (tmp_path / "x.g2o").exists()


# ============================================================================ fast path vs careful path
NASTY = ["1-2", "1e", ".", "+-1", "1_0", "nan", "inf", "\u0663", "1e999", "0x1", "3.0", "-0", "1.",
         ".5", "+.5e-3", "EDGE_SE2", "1EDGE_SE2", "VERTEX_SE2", "EDGE2", "#", "e5", "1..2", "--1", "7",
         "12", "-3", "2e0", "99999999999999999999", "1E+2", "\x00", "\x0c", "\xa0"]


def test_fast_path_matches_token_by_token(tmp_path, monkeypatch):
    """Random corruptions of a valid file: the vectorized fast path and the careful parser's bulk
    conversion must accept exactly what the token-by-token conversion accepts, with bit-identical
    results and identical errors."""
    rnd = random.Random(7)
    base = _chain(n=6).splitlines()

    def outcome(p):
        try:
            return ("ok", read_graph(p))
        except ParseError as e:
            return ("error", str(e))

    n_ok = 0
    for trial in range(400):
        p = _write(tmp_path, corrupt_tokens(rnd, base, NASTY), f"f{trial}.g2o")
        fast = outcome(p)
        with monkeypatch.context() as mp:
            mp.setattr(lio.reader, "parse_fast", lambda data, fmt: None)
            mp.setattr(lio.careful, "_convert_fast", lambda rec, spec: None)
            slow = outcome(p)
        assert fast[0] == slow[0], (p.read_text(), fast, slow)
        if fast[0] == "ok":
            n_ok += 1
            assert fast[1].equals(slow[1])
        else:
            assert fast[1] == slow[1]
    assert 10 < n_ok < 390  # both outcomes were exercised


# ============================================================================ speed
@pytest.mark.slow
def test_load_100k_edges_fast(tmp_path):
    rng = np.random.default_rng(0)
    n, m = 50_000, 100_000
    tails = np.concatenate([np.arange(n - 1), rng.integers(0, n, m - n + 1)])
    heads = np.concatenate([np.arange(1, n), rng.integers(0, n, m - n + 1)])
    heads = np.where(heads == tails, (heads + 1) % n, heads)
    meas = rng.normal(size=(m, 3))
    lines = [f"VERTEX_SE2 {i} {x:.6f} {y:.6f} {t:.6f}" for i, (x, y, t) in enumerate(rng.normal(size=(n, 3)).tolist())]
    lines += [f"EDGE_SE2 {i} {j} {a:.6f} {b:.6f} {c:.6f} 44.72 0 0 44.72 0 44.72"
              for i, j, (a, b, c) in zip(tails.tolist(), heads.tolist(), meas.tolist())]
    p = _write(tmp_path, "\n".join(lines) + "\n", "big.g2o")
    best = np.inf
    for _ in range(2):
        t0 = time.perf_counter()
        g = read_graph(p)
        best = min(best, time.perf_counter() - t0)
    assert g.n_edges == m and g.n_poses == n
    print(f"read_graph: {m} edges + {n} vertices in {best:.3f} s")
    assert best < 5.0  # generous: catches accidental per-token Python work on slow CI machines


def test_write_new_file_permissions_follow_umask(tmp_path):
    g = read_graph(_write(tmp_path, _chain(), "in.g2o"))
    old = os.umask(0o027)
    try:
        out = write_graph(tmp_path / "new.g2o", g)
    finally:
        os.umask(old)
    assert os.stat(out).st_mode & 0o777 == 0o640


def test_write_nothing_is_an_error(tmp_path):
    g = PoseGraph(2, np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3, 3)))
    with pytest.raises(ValueError):
        write_graph(tmp_path / "e.g2o", g)
    assert read_graph(write_graph(tmp_path / "e.g2o", g, np.zeros((2, 3)))).n_poses == 2


def test_threaded_writer_writes_the_same_bytes_in_order(tmp_path, monkeypatch):
    """Blocks formatted by two threads (``WRITE_THREADS``) land in file order: the file is byte for byte
    the one-thread file, over many small blocks of vertices and edges, and reads back to the same graph
    (vertex angles wrapped into [−π, π))."""
    import lago_cvx as lc
    from lago_cvx.io import writer

    g = lc.manhattan_world(700, seed=4).graph
    monkeypatch.setattr(writer, "BLOCK", 37)
    monkeypatch.setattr(writer, "WRITE_THREADS", 1)
    one = writer.write_graph(tmp_path / "one.g2o", g, g.initial).read_bytes()
    monkeypatch.setattr(writer, "WRITE_THREADS", 2)
    two = writer.write_graph(tmp_path / "two.g2o", g, g.initial).read_bytes()
    assert one == two
    back = read_graph(tmp_path / "two.g2o")
    assert np.array_equal(back.delta, g.delta) and np.array_equal(back.initial[:, :2], g.initial[:, :2])
    assert np.allclose(np.exp(1j * back.initial[:, 2]), np.exp(1j * g.initial[:, 2]), rtol=0, atol=1e-12)
