"""read_graph beyond the basics of test_io.py: the vectorized fast path against the careful line parser
(equal arrays, bit for bit, on every dataset and on fuzzed files), inline comments, FIX and EQUIV
lines (one warning each), landmark and 3-D records (a message saying what they are), files without
vertex lines, and the EDGE2 information order (the hint and the ``edge2_order`` option)."""

from __future__ import annotations

import importlib.util
import logging
import random
from pathlib import Path

import numpy as np
import pytest

from helpers import corrupt_tokens
from conftest import dataset_path
from fuzzing import mutate, synthetic_seeds

import lago_cvx.io.reader as reader
from lago_cvx.datasets import DATASET_FILES
from lago_cvx.errors import OptionError
from lago_cvx.io import ParseError, detect_format, read_graph
from lago_cvx.io.careful import decode, parse_careful
from lago_cvx.io.fastpath import parse_fast

UNIT = "1 0 0 1 0 1"  # identity information, g2o order
FIELDS = ("vid", "vval", "vlines", "eid", "evals", "elines")


def _gtsam_data(name: str) -> Path:
    """A file of GTSAM's example data (installed with the gtsam wheel), or skip."""
    spec = importlib.util.find_spec("gtsam")
    if spec is None or spec.origin is None:
        pytest.skip("gtsam is not installed (its Data folder holds the file)")
    path = Path(spec.origin).parent / "Data" / name
    if not path.is_file():
        pytest.skip(f"{name} not found in {path.parent}")
    return path


def _write(tmp_path, text, name="g.g2o") -> Path:
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


def _bits(a: np.ndarray) -> bytes:
    a = np.ascontiguousarray(a)
    return (a.view(np.int64) if a.dtype == float else a).tobytes()


def _same_parse(fast, careful) -> bool:
    return (all(_bits(getattr(fast, f)) == _bits(getattr(careful, f)) for f in FIELDS)
            and all(getattr(fast, f).shape == getattr(careful, f).shape for f in FIELDS)
            and (fast.fmt, fast.fix, fast.equiv) == (careful.fmt, careful.fix, careful.equiv))


def _graph_bits(g):
    arrays = [g.ids, g.tails, g.heads, g.delta_l, g.delta, g.information]
    return [_bits(a) for a in arrays] + ([_bits(g.initial)] if g.initial is not None else [None])


def _outcome(path, monkeypatch=None, careful=False):
    """("ok", bits of the graph) or ("error", message) of read_graph, optionally without the fast path."""
    if careful:
        monkeypatch.setattr(reader, "parse_fast", lambda data, fmt: None)
    try:
        return "ok", _graph_bits(read_graph(path))
    except ParseError as exc:
        return "error", str(exc)
    finally:
        if careful:
            monkeypatch.undo()


# ============================================================================ fast path = careful parser
@pytest.mark.parametrize("rel", DATASET_FILES)
def test_fast_path_equals_careful_on_datasets(rel):
    data = dataset_path(rel).read_bytes()
    fast = parse_fast(data, None)
    assert fast is not None, "the fast path must take ordinary files"
    assert _same_parse(fast, parse_careful(decode(data), None, rel))


@pytest.mark.parametrize("name", ["w100.graph", "w10000.graph", "w100_30.g2o", "w20000.txt", "pose2example.txt",
                                  "noisyToyGraph.txt"])
def test_fast_path_equals_careful_on_gtsam_files(name):
    data = _gtsam_data(name).read_bytes()
    fast = parse_fast(data, None)
    assert fast is not None
    assert _same_parse(fast, parse_careful(decode(data), None, name))


FAST_EDGE_CASES = {
    "signs_exponents": "VERTEX_SE2 -3 1e5 -2.5E-3 3e+2\nVERTEX_SE2 7 -1.5e-05 -0 -0.000\n",
    "crlf_tabs_bom": "\ufeff# c\r\nVERTEX_SE2\t0 0 0 0\r\n\r\n  \t\r\nVERTEX_SE2 1  1   0 0\r\nEDGE_SE2\t0 1 1 0 0 " + UNIT + "\r\n",
    "inline_comments": "VERTEX_SE2 0 0 0 0 # first\nVERTEX_SE2 1 1 0 0\t#\tsecond \u00e9\nEDGE_SE2 0 1 1 0 0 " + UNIT + " #\n",
    "fix_equiv": "FIX 0 # anchor\nVERTEX2 0 0 0 0\nEQUIV 0 1\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 1 0 0\nFIX 1\n",
    "interleaved": "".join(f"VERTEX_SE2 {k} {k}.5 0 0\nEDGE_SE2 {k} {k + 1} 1 0 0 {UNIT}\n" for k in range(50))
                   + "VERTEX_SE2 50 0 0 0\n",
    "no_final_newline": "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 " + UNIT,
}


@pytest.mark.parametrize("case", FAST_EDGE_CASES, ids=list(FAST_EDGE_CASES))
def test_fast_path_takes_and_agrees(case):
    data = FAST_EDGE_CASES[case].encode()
    fast = parse_fast(data, None)
    assert fast is not None
    assert _same_parse(fast, parse_careful(decode(data), None, case))


# Tokens the fast path must either read exactly like the careful parser or leave to it.
NASTY = ["1-2", "1e", ".", "+-1", "1_0", "nan", "inf", "\u0663", "1e999", "0x1", "3.0", "-0", "1.", ".5",
         "+.5e-3", "EDGE_SE2", "1EDGE_SE2", "VERTEX_SE2", "EDGE2", "#", "#x", "1#2", "e5", "1..2", "--1", "7",
         "12", "-3", "2e0", "99999999999999999999", "9007199254740993", "1E+2", "1.2.3", "1e5.3", "1e5e3",
         "1e-5.2", "-1e-5e2", "1.e5", "5e-", "1e+", "-", "+1", "1e-400", "4.9e-324", "1e308", "\x00", "\x0c",
         "\x1c", "\xa0", "\u2003", "\ufeff", "FIX", "EQUIV", "\t", "\r"]


def test_fast_path_on_token_corruptions(tmp_path, monkeypatch):
    """Random token corruptions of a valid file: read_graph with and without the fast path give the
    same graph (bit for bit) or the same message."""
    rnd = random.Random(11)
    base = ("".join(f"VERTEX_SE2 {k} {k * 0.5!r} -0.25 {k / 7!r}\n" for k in range(6))
            + "".join(f"EDGE_SE2 {k} {k + 1} 1.5 -0.0 0.1 44.72 0 0 44.72 0 1e2\n" for k in range(5))).splitlines()
    n_fast = n_ok = 0
    for trial in range(500):
        p = _write(tmp_path, corrupt_tokens(rnd, base, NASTY), f"f{trial}.g2o")
        n_fast += parse_fast(p.read_bytes(), None) is not None
        fast = _outcome(p)
        careful = _outcome(p, monkeypatch, careful=True)
        assert fast == careful, p.read_bytes()
        n_ok += fast[0] == "ok"
    assert 20 < n_ok < 480 and n_fast > 20  # both outcomes, and the fast path, were exercised


def test_fast_path_on_fuzzed_files(tmp_path, monkeypatch):
    """The fuzzer's mutants (tests/fuzzing.py): same outcome with and without the fast path."""
    seeds = synthetic_seeds(tmp_path / "seeds")
    seeds["inline.g2o"] = f"VERTEX_SE2 0 0 0 0 # a\nVERTEX_SE2 1 1.5 -0.25 3e-2\nFIX 0\nEDGE_SE2 0 1 1 0 0 {UNIT} #\n".encode()
    seeds["equiv.graph"] = b"VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 1 0 0\nEQUIV 0 1\n# c\n"
    rng = random.Random(5)
    names = sorted(seeds)
    n_fast = 0
    for i in range(400):
        data, mutations = mutate(seeds[names[i % len(names)]], rng)
        p = _write(tmp_path, data, "mutant.g2o")
        n_fast += parse_fast(data, None) is not None
        assert _outcome(p) == _outcome(p, monkeypatch, careful=True), (mutations, data[:300])
    assert n_fast > 50


# ============================================================================ comments
def test_inline_comments(tmp_path):
    plain = read_graph(_write(tmp_path, f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 {UNIT}\n", "p.g2o"))
    text = f"VERTEX_SE2 0 0 0 0 # origin\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 {UNIT}   # odometry\n"
    assert read_graph(_write(tmp_path, text)).equals(plain)
    # A comment takes the rest of the line: what is left must still be a whole record ...
    with pytest.raises(ParseError) as ei:
        read_graph(_write(tmp_path, "VERTEX_SE2 0 0 0 #0\n"))
    assert str(ei.value).endswith(":1: VERTEX_SE2 expects 4 numbers after the tag, got 3")
    # ... and a '#' inside a token is not a comment but a bad number.
    with pytest.raises(ParseError) as ei:
        read_graph(_write(tmp_path, "VERTEX_SE2 0 0 0 1#2\n"))
    assert str(ei.value).endswith(":1: non-numeric value '1#2' for theta")


# ============================================================================ FIX and EQUIV
def test_fix_lines_warn_once(tmp_path, caplog):
    text = "FIX 3\n" + "".join(f"VERTEX_SE2 {k} {k} 0 0\n" for k in (3, 4, 5)) \
        + f"EDGE_SE2 3 4 1 0 0 {UNIT}\nFIX 4 5\nEDGE_SE2 4 5 1 0 0 {UNIT}\n"
    p = _write(tmp_path, text)
    with caplog.at_level(logging.WARNING):  # the default level
        g = read_graph(p)
    assert g.n_poses == 3 and g.n_edges == 2
    msgs = [r for r in caplog.records if r.name.startswith("lago_cvx.io")]
    assert len(msgs) == 1 and msgs[0].levelno == logging.WARNING
    assert msgs[0].getMessage() == (f"{p}: ignoring 2 FIX line(s) (the first on line 1: FIX 3): LAGO anchors the "
                                    "estimate at the smallest pose id, 3 (lago(graph, anchor=ID); CLI: --anchor ID)")


def test_equiv_lines_warn_once(tmp_path, caplog):
    text = ("VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nVERTEX2 2 2 0 0\nEDGE2 0 1 1 0 0 1 0 1 1 0 0\n"
            "EQUIV 2 0\nEDGE2 1 2 1 0 0 1 0 1 1 0 0\nEQUIV 1 0\n")
    p = _write(tmp_path, text, "g.graph")
    with caplog.at_level(logging.WARNING):
        g = read_graph(p)
    assert g.n_poses == 3 and g.n_edges == 2  # nothing collapsed
    msgs = [r.getMessage() for r in caplog.records if r.name.startswith("lago_cvx.io")]
    assert msgs == [f"{p}: ignoring 2 EQUIV line(s) (the first on line 5: EQUIV 2 0): TORO collapses such vertex "
                    "pairs only on request; lago_cvx keeps every vertex and edge as written"]


@pytest.mark.parametrize("line, problem", [
    ("EQUIV 1", "EQUIV expects 2 vertex ids after the tag, got 1"),
    ("EQUIV 1 2 3", "EQUIV expects 2 vertex ids after the tag, got 3"),
    ("EQUIV a 2", "vertex id must be an integer, got 'a' for id"),
    ("FIX 1.5", "vertex id must be an integer, got '1.5' for id"),
])
def test_bad_fix_and_equiv_lines(tmp_path, line, problem):
    p = _write(tmp_path, "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\n" + line + "\n", "g.graph")
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    assert str(ei.value) == f"{p}:3: {problem}"


def test_toro_file_with_equiv_lines_reads(caplog):
    path = _gtsam_data("w100.graph")
    with caplog.at_level(logging.WARNING):
        g = read_graph(path)
    assert (g.n_poses, g.n_edges) == (100, 300)
    assert [r.getMessage() for r in caplog.records if r.name.startswith("lago_cvx.io")] == [
        f"{path}: ignoring 40 EQUIV line(s) (the first on line 401: EQUIV 21 1): TORO collapses such vertex pairs "
        "only on request; lago_cvx keeps every vertex and edge as written"]


# ============================================================================ records of other kinds
PLANAR = "lago_cvx reads pose graphs (VERTEX_SE2/EDGE_SE2 or VERTEX2/EDGE2, planar; VERTEX_SE3:QUAT/EDGE_SE3:QUAT, 3-D)"
OTHER_3D = ("a 3-D record of a kind lago_cvx does not read (it reads 3-D graphs as VERTEX_SE3:QUAT/EDGE_SE3:QUAT, "
            "planar ones as VERTEX_SE2/EDGE_SE2 or VERTEX2/EDGE2)")
# VERTEX_SE3:QUAT / EDGE_SE3:QUAT are 3-D graphs (tests/test_space_io.py), and a mix with planar records there.


@pytest.mark.parametrize("line, problem", [
    ("LANDMARK2 5 11 -2.6 2.6 10 0 10", f"'LANDMARK2' is a landmark measurement, not a pose–pose constraint: {PLANAR}"),
    ("BR 0 144 0.18 9.1 0.0349 0.1", f"'BR' is a landmark measurement, not a pose–pose constraint: {PLANAR}"),
    ("EDGE_SE2_XY 0 7 1 2 10 0 10", f"'EDGE_SE2_XY' is a landmark measurement, not a pose–pose constraint: {PLANAR}"),
    ("VERTEX_XY 7 1 2", f"'VERTEX_XY' is a landmark position, not a pose: {PLANAR}"),
    ("POINT2 7 1 2", f"'POINT2' is a landmark position, not a pose: {PLANAR}"),
    ("VERTEX3 0 1 2 3 0 0 0", f"'VERTEX3' is {OTHER_3D}"),
    ("EDGE3 0 1 1 0 0 0 0 0", f"'EDGE3' is {OTHER_3D}"),
])
@pytest.mark.parametrize("where", ["first", "later"])
def test_non_pose_records(tmp_path, line, problem, where):
    head = "" if where == "first" else f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 {UNIT}\n"
    p = _write(tmp_path, head + line + "\n")
    lineno = 1 if where == "first" else 4
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    assert str(ei.value) == f"{p}:{lineno}: {problem}"
    with pytest.raises(ParseError) as ei:
        read_graph(p, format="toro")
    assert ei.value.problem == problem if where == "first" else ei.value.line == 1
    if where == "first":
        with pytest.raises(ParseError) as ei:
            detect_format(p)
        assert str(ei.value) == f"{p}:1: {problem}"


@pytest.mark.parametrize("name, line, tag", [("cityTrees_reduced_1k.g2o", 1000, "LANDMARK2"),
                                             ("example.graph", 190, "BR"),
                                             ("sphere2500.txt", 1, "EDGE3")])
def test_non_pose_records_in_gtsam_files(name, line, tag):
    path = _gtsam_data(name)
    with pytest.raises(ParseError) as ei:
        read_graph(path)
    assert ei.value.line == line and ei.value.problem.startswith(f"{tag!r} is a ")


# ============================================================================ files without vertex lines
def test_edge_only_file_infers_poses(tmp_path, caplog):
    p = _write(tmp_path, f"EDGE_SE2 10 11 1 0 0 {UNIT}\nEDGE_SE2 11 13 1 0 0 {UNIT}\nEDGE_SE2 13 10 1 0 0 {UNIT}\n")
    with caplog.at_level(logging.INFO, logger="lago_cvx.io"):
        g = read_graph(p)
    assert g.ids.tolist() == [10, 11, 13] and g.initial is None
    assert [r.getMessage() for r in caplog.records if r.levelno == logging.INFO] == [
        f"{p}: no VERTEX lines; 3 poses inferred from the ids of the 3 edges (no initial guess)"]
    # With some vertex lines, an edge to an undefined vertex stays an error.
    q = _write(tmp_path, f"VERTEX_SE2 10 0 0 0\nVERTEX_SE2 11 0 0 0\nEDGE_SE2 10 11 1 0 0 {UNIT}\n"
                         f"EDGE_SE2 11 13 1 0 0 {UNIT}\n", "q.g2o")
    with pytest.raises(ParseError) as ei:
        read_graph(q)
    assert str(ei.value) == f"{q}:4: edge refers to vertex 13, which no VERTEX line defines"


def test_gtsam_w20000_without_vertices():
    path = _gtsam_data("w20000.txt")
    g = read_graph(path, edge2_order="g2o")
    assert g.initial is None and g.n_edges == 26831 and g.n_poses == g.ids.size
    assert np.array_equal(g.ids, np.unique(np.concatenate([g.ids[g.tails], g.ids[g.heads]])))


# ============================================================================ EDGE2 information order
def _edge2_file(tmp_path, order: str, name="g.graph"):
    """A small EDGE2 file whose information is diag(4, 9, 25) plus x-y coupling 1, in ``order``."""
    six = {"toro": "4 1 9 25 0 0", "g2o": "4 1 0 9 0 25"}[order]
    lines = [f"VERTEX2 {k} {k} 0 0" for k in range(3)] + [f"EDGE2 {k} {k + 1} 1 0 0.3 {six}" for k in range(2)]
    return _write(tmp_path, "\n".join(lines) + "\n", name)


def test_edge2_order_hint_and_option(tmp_path):
    p = _edge2_file(tmp_path, "g2o")
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    assert str(ei.value) == (
        f"{p}:4: information matrix is not positive definite (eigenvalues -20.9254, 4.00774, 29.9177) in the TORO "
        "order (Ixx Ixy Iyy Itt Ixt Iyt); every EDGE2 line of this file is positive definite in the g2o order "
        "(I11 I12 I13 I22 I23 I33): if the file stores its information that way, read it with "
        "read_graph(path, edge2_order='g2o') (CLI: --edge2-order g2o)")
    g = read_graph(p, edge2_order="g2o")  # read exactly like EDGE_SE2
    same = _write(tmp_path, p.read_text().replace("VERTEX2", "VERTEX_SE2").replace("EDGE2", "EDGE_SE2"), "same.g2o")
    assert g.equals(read_graph(same))
    assert read_graph(p, edge2_order="G2O").equals(g) and read_graph(same, edge2_order="g2o").equals(g)
    # The other way round: a TORO-ordered file read with edge2_order="g2o".
    t = _edge2_file(tmp_path, "toro", "t.graph")
    assert read_graph(t, edge2_order="toro").equals(read_graph(t))
    with pytest.raises(ParseError) as ei:
        read_graph(t, edge2_order="g2o")
    assert ei.value.problem.endswith(
        "in the g2o order (I11 I12 I13 I22 I23 I33); every EDGE2 line of this file is positive definite in the "
        "TORO order (Ixx Ixy Iyy Itt Ixt Iyt): if the file stores its information that way, read it with "
        "read_graph(path, edge2_order='toro' (the default)) (CLI: --edge2-order toro)")
    with pytest.raises(OptionError):
        read_graph(p, edge2_order="xml")


def test_edge2_order_no_hint_when_neither_fits(tmp_path):
    p = _write(tmp_path, "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 0 1 -1 0 0\n", "g.graph")
    with pytest.raises(ParseError) as ei:
        read_graph(p)
    assert ei.value.problem == ("information matrix is not positive definite (eigenvalues -1, 1, 1); "
                                "read_graph(path, repair=True) (CLI: --repair-information) replaces such matrices by "
                                "the nearest positive-definite one")


@pytest.mark.parametrize("name, n_edges", [("w100_30.g2o", 59), ("w20000.txt", 26831)])
def test_gtsam_files_with_g2o_ordered_edge2(name, n_edges):
    path = _gtsam_data(name)
    with pytest.raises(ParseError) as ei:
        read_graph(path)
    assert "edge2_order='g2o'" in ei.value.problem and "--edge2-order g2o" in ei.value.problem
    assert read_graph(path, edge2_order="g2o").n_edges == n_edges
