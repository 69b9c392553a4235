"""``--robust-threshold`` and ``--robust-confidence`` (``solve`` and ``certify``, planar and 3-D): the c̄² they set
is the one the library runs with, alone and combined with the other options of ``--robust``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_dist

import lago_cvx as lc
from lago_cvx.cli.main import main
from lago_cvx.io import read_graph
from lago_cvx.variants import RobustSettings


def run(capsys, *argv):
    capsys.readouterr()  # what a fixture printed
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's own refusal of an option's value
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def planar(tmp_path_factory):
    f = tmp_path_factory.mktemp("planar") / "w.g2o"
    assert main(["generate", "--poses", "90", "--seed", "4", "--outliers", "0.1", "-o", str(f)]) == 0
    return f


@pytest.fixture(scope="module")
def space(tmp_path_factory):
    f = tmp_path_factory.mktemp("space") / "g.g2o"
    assert main(["generate", "--world", "grid3d", "--poses", "150", "--seed", "2", "--outliers", "0.1", "-o",
                 str(f)]) == 0
    return f


def solve_json(capsys, f, *options):
    code, out, err = run(capsys, "solve", f, *options, "--json")
    assert code == 0, err
    return json.loads(out)


@pytest.mark.parametrize("options, settings", [
    (["--robust-threshold", "6"], RobustSettings(threshold=6.0)),
    (["--robust-confidence", "0.999"], RobustSettings(confidence=0.999)),
    (["--robust-loss", "gm", "--robust-threshold", "8"], RobustSettings(loss="gm", threshold=8.0)),
    (["--robust", "--robust-confidence", "0.95", "--anchor", "3"], RobustSettings(confidence=0.95)),
    (["--robust-threshold", "3", "--robust-calibrate", "4.7"], RobustSettings(threshold=3.0, calibrate=4.7)),
    (["--robust-loss", "gm"], RobustSettings(loss="gm")), (["--robust"], RobustSettings()),
], ids=["threshold", "confidence", "gm+threshold", "confidence+anchor", "threshold+calibrate", "gm", "robust"])
@pytest.mark.parametrize("command", ["solve", "certify"])
def test_each_option_implies_robust_and_asks_for_its_settings(command, options, settings):
    """What the command line asks the library for (parsed only): each option implies --robust."""
    from lago_cvx.cli.main import build_parser
    from lago_cvx.cli.robust import robust_request

    if command == "certify" and "--robust-calibrate" in options:
        options = options[:2]
        settings = RobustSettings(threshold=3.0)
    args = build_parser().parse_args([command, "f.g2o", *options])
    assert robust_request(args, 2) == settings and args.robust == f"gnc-{settings.loss}"
    none = build_parser().parse_args([command, "f.g2o"])
    assert robust_request(none, 2) is None and none.robust is None


@pytest.mark.parametrize("which, options, settings", [
    ("planar", ["--robust-threshold", 6, "--anchor", 3], RobustSettings(threshold=6.0)),
    ("space", ["--robust-confidence", 0.999], RobustSettings(confidence=0.999)),
    ("space", ["--robust-loss", "gm", "--robust-threshold", 8], RobustSettings(loss="gm", threshold=8.0)),
], ids=["planar-threshold+anchor", "space-confidence", "space-gm+threshold"])
def test_the_options_run_the_settings_they_name(request, capsys, which, options, settings):
    """The rejected edges and c̄² of a whole run are those of ``lago(graph, robust=settings)``."""
    f = request.getfixturevalue(which)
    g = read_graph(f)
    d = solve_json(capsys, f, *options)
    res = lc.lago(g, robust=settings, anchor=3 if "--anchor" in options else None)
    assert d["robust"] == f"gnc-{settings.loss}" and d["rejected_edges"] == res.rejected_edges.tolist()
    assert d["robust_threshold"] == pytest.approx(settings.c2_for(g.dim), rel=1e-12)
    if settings.threshold is None:
        assert d["robust_threshold"] == pytest.approx(chi2_dist.ppf(settings.confidence, 3 if g.dim == 2 else 6))
    assert d["chi2"] == pytest.approx(res.chi2, rel=1e-10)


def test_a_smaller_threshold_rejects_more_and_the_text_names_it(planar, capsys):
    loose, tight = (solve_json(capsys, planar, "--robust-threshold", c2) for c2 in (30.0, 4.0))
    assert set(loose["rejected_edges"]) <= set(tight["rejected_edges"])
    assert len(tight["rejected_edges"]) > len(loose["rejected_edges"])
    code, out, _ = run(capsys, "solve", planar, "--robust-threshold", 30)
    assert code == 0 and "robust (gnc-tls, c̄² = 30)" in out


def test_threshold_with_check_refine_route_and_stdout(planar, capsys):
    d = solve_json(capsys, planar, "--robust-threshold", 8, "--check", "--refine")
    assert d["check_edges"] == "accepted" and max(d["max_rel_diff"].values()) < 1e-6
    assert d["robust_threshold"] == 8.0 and d["chi2_refined"] <= d["chi2"]
    code, out, err = run(capsys, "solve", planar, "--robust-threshold", 8, "--refine", "-o", "-")
    assert code == 0 and "rejected" in err and out.startswith("VERTEX_SE2")
    s = solve_json(capsys, planar, "--robust-threshold", 8, "--route", "seed")
    res = lc.lago(read_graph(planar), robust=RobustSettings(threshold=8.0), route="seed")
    assert s["route"] == "seed" and s["rejected_edges"] == res.rejected_edges.tolist()


def test_calibration_under_a_given_threshold(tmp_path, capsys, c2=9.0):
    """--robust-calibrate K with --robust-threshold C2: the calibrated c̄² is min(C2, K · the largest odometric r²);
    "calibrated" only when the run returned used it. The world's information is loose for its noise (σ 0.02 m
    written as 0.1 m: r² × 0.04), so K · the largest r² falls below 9."""
    f = tmp_path / "loose.g2o"
    assert main(["generate", "--poses", "80", "--seed", "5", "--sigma-xy", "0.02", "--info-sigma-xy", "0.1",
                 "--outliers", "0.1", "-o", str(f)]) == 0
    d = solve_json(capsys, f, "--robust-threshold", c2, "--robust-calibrate", 4.7)
    res = lc.lago(read_graph(f), robust=RobustSettings(threshold=c2, calibrate=4.7))
    assert d["robust_threshold"] == pytest.approx(res.settings.c2_for(2)) and d["robust_threshold"] <= c2
    assert d["robust_calibrated"] == (res.settings.threshold != c2) == (d["robust_threshold"] < c2)
    assert d["rejected_edges"] == res.rejected_edges.tolist() and d["robust_calibrated"]


@pytest.mark.parametrize("command", ["solve", "certify"])
def test_bad_values_and_combinations_are_refused(planar, space, capsys, command):
    code, _, err = run(capsys, command, planar, "--robust-threshold", 2, "--robust-confidence", 0.9)
    assert code == 2 and err.strip().splitlines() == [err.strip()] and "give one" in err
    for option, value in [("--robust-threshold", 0), ("--robust-threshold", "nan"), ("--robust-threshold", "inf"),
                          ("--robust-threshold", "x"), ("--robust-confidence", 1), ("--robust-confidence", 0),
                          ("--robust-confidence", "-0.5"), ("--robust-confidence", "nan")]:
        code, _, err = run(capsys, command, planar, option, value)
        assert code == 2 and f"argument {option}:" in err.strip().splitlines()[-1], (option, value, err)
    if command == "solve":
        code, _, err = run(capsys, command, space, "--robust-threshold", 2, "--robust-calibrate", 4.7)
        assert code == 2 and "planar graphs only" in err and "--robust-threshold sets it" in err


@pytest.mark.parametrize("which", ["planar", "space"])
def test_certify_runs_the_same_robust_settings(request, capsys, which):
    f = request.getfixturevalue(which)
    s = solve_json(capsys, f, "--robust-confidence", 0.999)
    code, out, err = run(capsys, "certify", f, "--robust-confidence", 0.999, "--json")
    c = json.loads(out)
    assert code == c["exit_status"] and c["certified_edges"] == "accepted", err
    assert c["rejected_edges"] == s["rejected_edges"] and c["robust_threshold"] == pytest.approx(s["robust_threshold"])
    assert c["n_edges"] == c["n_edges_input"] - len(np.asarray(c["rejected_edges"]))
