"""The ``lago-cvx`` command line: JSON keys, counts on every dataset, bad input → exit 2, one line."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from lago_cvx.cli import main

from lago_cvx.datasets import DATASET_TABLE, REFERENCE_CHI2
from conftest import dataset_path


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("row", DATASET_TABLE, ids=[r[0] for r in DATASET_TABLE])
def test_info_json_counts_match_datasets_readme(capsys, row):
    rel, n, m, odo, lc = row
    code, out, _ = run(capsys, "info", str(dataset_path(rel)), "--json")
    assert code == 0
    info = json.loads(out)
    assert (info["n_poses"], info["n_edges"], info["n_odometric"], info["n_loop_closures"]) == (n, m, odo, lc)
    assert info["n_components"] == 1
    assert info["cyclomatic_number"] == m - n + 1
    assert isinstance(info["n_regularized"], int)


def test_info_intel_odometric_tree_reports_table1(capsys):
    code, out, _ = run(capsys, "info", str(dataset_path("carlone/INTEL_P_toro.graph")), "--json",
                       "--spanning-tree", "odometry")
    info = json.loads(out)
    assert code == 0 and info["n_regularized"] == 198 and info["n_loop_closures"] == 278


def test_generate_then_info_and_solve(capsys, tmp_path):
    out = tmp_path / "world.g2o"
    code, text, _ = run(capsys, "generate", "--poses", "300", "--seed", "4", "-o", str(out))
    assert code == 0 and out.exists() and (tmp_path / "world.truth.g2o").exists()
    code, text, _ = run(capsys, "info", str(out))
    assert code == 0 and "poses             300" in text
    est = tmp_path / "est.g2o"
    code, text, _ = run(capsys, "solve", str(out), "--json", "--check", "-o", str(est))
    assert code == 0
    res = json.loads(text)
    for key in ("n_poses", "n_edges", "n_regularized", "chi2", "timings", "max_rel_diff"):
        assert key in res
    assert set(res["timings"]) == {"regularization", "phase1", "phase2", "phase3", "positions", "total"}
    assert set(res["max_rel_diff"]) == {"phase1", "phase3", "positions", "chordal"}
    assert max(res["max_rel_diff"].values()) < 1e-6
    assert est.exists()


def test_solve_cvxpy_method_and_text_output(capsys, tmp_path):
    out = tmp_path / "c.g2o"
    run(capsys, "generate", "--world", "circle", "--laps", "3", "--poses", "90", "-o", str(out))
    code, text, _ = run(capsys, "solve", str(out), "--method", "cvxpy", "--route", "seed")
    assert code == 0 and "chi2 =" in text
    assert "LAGO (cvxpy, seed route: odometry spanning tree, tree regularization, marginal information, phase3 " \
           "positions)" in text
    code, text, _ = run(capsys, "solve", str(out), "--method", "cvxpy", "--spanning-tree", "odometry",
                        "--positions", "phase3")
    assert code == 0 and "custom route: odometry spanning tree, chordal regularization, full information, phase3" \
                         in text


def test_solve_refuses_to_overwrite_input(capsys, tmp_path):
    out = tmp_path / "w.g2o"
    run(capsys, "generate", "--poses", "50", "-o", str(out))
    before = out.read_bytes()
    code, _, err = run(capsys, "solve", str(out), "-o", str(out))
    assert code == 2 and "refusing to overwrite the input file" in err
    assert out.read_bytes() == before
    code, _, _ = run(capsys, "solve", str(out), "-o", str(out), "--overwrite-input")
    assert code == 0 and out.read_bytes() != before


@pytest.mark.parametrize("content, fragment", [
    ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", ":1:"),                       # arity
    ("VERTEX_SE2 0 0 0 0\nBOGUS 1 2\n", ":2:"),                       # unknown tag
    ("", "no vertices and no edges"),                                 # empty
])
def test_bad_input_exit_2_one_line(capsys, tmp_path, content, fragment):
    f = tmp_path / "bad.g2o"
    f.write_text(content)
    for cmd in ("info", "solve"):
        code, out, err = run(capsys, cmd, str(f))
        assert code == 2
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("lago-cvx: error: ") and fragment in lines[0]
        assert "Traceback" not in err


def test_disconnected_graph_exit_2(capsys, tmp_path):
    f = tmp_path / "disc.g2o"
    f.write_text("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\nEDGE_SE2 3 4 1 0 0 1 0 0 1 0 1\n")
    code, _, err = run(capsys, "solve", str(f))
    assert code == 2 and "not connected: 2 components of sizes 3 poses" in err
    code, out, _ = run(capsys, "info", str(f), "--json")
    assert code == 0 and json.loads(out)["n_components"] == 2


def test_broken_odometric_chain_named(capsys, tmp_path):
    f = tmp_path / "chain.g2o"
    f.write_text("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 3 1 0 0 1 0 0 1 0 1\nEDGE_SE2 3 2 1 0 0 1 0 0 1 0 1\n")
    code, _, err = run(capsys, "solve", str(f), "--spanning-tree", "odometry")
    assert code == 2 and "no edge between poses 1 and 2" in err


def test_missing_file_exit_2(capsys, tmp_path):
    code, _, err = run(capsys, "info", str(tmp_path / "nope.g2o"))
    assert code == 2 and "nope.g2o" in err


def test_demo_writes_figure(capsys, tmp_path):
    code, out, _ = run(capsys, "demo", "--poses", "200", "--out-dir", str(tmp_path), "--json")
    assert code == 0
    res = json.loads(out)
    assert Path(res["figure"]).exists()
    assert res["ate"]["lago"] < res["ate"]["odometry"]
    assert res["chi2"]["lago"] <= res["chi2"]["truth"]  # LAGO minimises (approximately) the same cost
    assert max(res["max_rel_diff"].values()) < 1e-6


def test_module_entry_point_and_bad_option():
    r = subprocess.run([sys.executable, "-m", "lago_cvx", "solve", "x.g2o", "--method", "magic"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "unknown method" in r.stderr


def test_solve_refine_reports_refined_chi2(capsys):
    code, out, _ = run(capsys, "solve", str(dataset_path("se-sync/MIT.g2o")), "--refine", "--json")
    res = json.loads(out)
    assert code == 0
    assert res["chi2_refined"] == pytest.approx(REFERENCE_CHI2["se-sync/MIT.g2o"], rel=1e-5) and res["chi2_refined"] < res["chi2"]
    assert 1 <= res["refine_iterations"] <= 8


def test_solve_with_anchors_and_strain(capsys, tmp_path):
    out = tmp_path / "w.g2o"
    run(capsys, "generate", "--poses", "200", "--seed", "1", "-o", str(out))
    code, text, _ = run(capsys, "solve", str(out), "--anchor", "0:0,0,0", "--anchor", "150:,,0.3", "--json")
    res = json.loads(text)
    assert code == 0 and set(res["anchors"]) == {"0", "150"} and isinstance(res["strained_anchors"], list)
    code, _, err = run(capsys, "solve", str(out), "--anchor", "3:1,,", "--json")
    assert code == 2 and "give both X and Y" in err
    code, text, _ = run(capsys, "solve", str(out), "--anchor", "5", "--json")
    assert code == 0


@pytest.mark.parametrize("command", ["info", "solve", "certify"])
def test_edge2_order_option_reads_what_the_hint_names(capsys, tmp_path, command):
    """An EDGE2 file that stores its information in g2o order: without ``--edge2-order`` exit 2 with a
    message naming the option (which exists); with ``--edge2-order g2o`` the file is read."""
    f = tmp_path / "g2o_order.graph"
    lines = ["VERTEX2 0 0 0 0", "VERTEX2 1 1 0 0", "VERTEX2 2 1 1 1.5"]
    # I11 I12 I13 I22 I23 I33 = 1 0 0 1 0 1 is fine in g2o order; read as TORO it is (1 0 0 / 0 1 1 / 0 1 0): indefinite
    lines += [f"EDGE2 {a} {b} 1 0 0.5 1 0 0 1 0 1" for a, b in ((0, 1), (1, 2), (0, 2))]
    f.write_text("\n".join(lines) + "\n")
    code, out, err = run(capsys, command, str(f))
    assert code == 2 and "--edge2-order g2o" in err and "Traceback" not in err, err
    code, out, err = run(capsys, command, str(f), "--edge2-order", "g2o")
    assert code in (0, 3), err        # certify may exit 3 (not certified) on a 3-pose graph; it has read the file
    assert "error" not in err.lower()


def test_verbose_is_accepted_before_and_after_the_command(capsys, tmp_path):
    f = tmp_path / "g.g2o"
    f.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n")
    for argv in (["-v", "solve", str(f)], ["solve", str(f), "-v"], ["solve", str(f), "-vv"]):
        code, out, err = run(capsys, *argv)
        assert code == 0 and "INFO" in err, (argv, err)
    code, out, err = run(capsys, "solve", str(f))
    assert code == 0 and "INFO" not in err
