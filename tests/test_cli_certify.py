"""``lago-cvx certify``: exit 0 and the verdict when certified, exit 3 when not, JSON fields, SE-Sync's
published optimum on CSAIL, bad input → exit 2 with one line; and ``--regularization integer`` in
``info`` / ``solve``. Real-data tests are skipped when ../shared/datasets is absent."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lago_cvx.regularization
from lago_cvx import read_graph
from lago_cvx.datasets import REFERENCE_CHI2
from lago_cvx.certification import CERTIFY_TOL, sesync_cost
from lago_cvx.cli import EXIT_NOT_CERTIFIED, main
from lago_cvx.posegraph import between
from lago_cvx.regularization import REGULARIZATIONS

from conftest import dataset_path

#: SE-Sync's certified optimum of CSAIL (IJRR 2019, Table 1; datasets README 4.1), more digits from
#: the local solver (tests/test_certify.py).
CSAIL_F_STAR = 31.70371588

CERTIFICATE_KEYS = {"certified", "verdict", "f", "f_input", "lambda_min", "eigenvalues", "eta", "norm_M",
                    "n_negative", "residual_rel", "lower_bound", "suboptimality_bound",
                    "relative_suboptimality_bound"}


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _world(capsys, tmp_path, *options, name="world.g2o"):
    """A synthetic Manhattan world written by ``lago-cvx generate``."""
    path = tmp_path / name
    code, _, _ = run(capsys, "generate", *options, "-o", str(path))
    assert code == 0
    return path


def _one_error_line(err: str) -> str:
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lago-cvx: error: "), err
    return lines[0]


# ------------------------------------------------------------------------------- certified → 0
def test_certify_synthetic_world_exit_0_writes_certified_poses(capsys, tmp_path):
    world = _world(capsys, tmp_path, "--poses", "150", "--seed", "3")
    out = tmp_path / "certified.g2o"
    code, text, err = run(capsys, "certify", str(world), "-o", str(out))
    assert code == 0, err
    assert "certificate of the SE-Sync-refined estimate: CERTIFIED globally optimal" in text
    assert "verdict: globally optimal (certified)" in text
    assert "comparison certificate of the raw LAGO estimate: not run (--compare-lago" in text  # opt-in
    assert "not the χ²" in text  # the cost convention is stated
    # the written poses are the certified point: their f is the reported one
    f_text = float(text.split("SE-Sync-refined estimate, translations re-optimised      f = ")[1].split()[0])
    g = read_graph(out)
    assert sesync_cost(g, g.initial) == pytest.approx(f_text, rel=1e-9)
    assert f"certified estimate written to {out}" in text


def test_certify_json_fields(capsys, tmp_path):
    world = _world(capsys, tmp_path, "--poses", "150", "--seed", "3")
    code, text, _ = run(capsys, "certify", str(world), "--json", "--regularization", "chordal", "--compare-lago")
    assert code == 0
    res = json.loads(text)
    assert res["compare_lago"] is True and "certify_lago" in res["timings"]
    assert {"f_lago", "f_chi2_refined", "f", "f_input", "lago_certificate.f"} <= set(res["cost_labels"])
    for key in ("file", "n_poses", "n_edges", "spanning_tree", "regularization", "tol", "cost_convention",
                "chi2_lago", "chi2_refined", "f_lago", "f_chi2_refined", "sesync_iterations", "sesync_converged",
                "lago_certificate", "timings", "exit_status"):
        assert key in res, key
    assert CERTIFICATE_KEYS <= set(res) and CERTIFICATE_KEYS <= set(res["lago_certificate"])
    assert (res["n_poses"], res["regularization"], res["tol"], res["exit_status"]) == (150, "chordal", CERTIFY_TOL, 0)
    assert res["certified"] is True and res["n_negative"] == 0
    assert res["lambda_min"] >= -res["eta"] and res["eta"] == pytest.approx(1e-12 * res["norm_M"])
    assert res["lower_bound"] <= res["f"] <= res["f_chi2_refined"]
    assert res["relative_suboptimality_bound"] < 1e-5
    assert res["chi2_refined"] <= res["chi2_lago"]
    lago_cert = res["lago_certificate"]
    assert lago_cert["certified"] is False and lago_cert["f_input"] == pytest.approx(res["f_lago"])
    assert lago_cert["lower_bound"] <= res["f"] * (1 + 1e-9)  # both bounds are valid lower bounds on f*


def test_certify_csail_reaches_sesync_optimum(capsys):
    code, text, _ = run(capsys, "certify", str(dataset_path("se-sync/CSAIL.g2o")), "--json", "--compare-lago")
    res = json.loads(text)
    assert code == 0 and res["certified"] is True, res["verdict"]
    assert res["f"] == pytest.approx(CSAIL_F_STAR, rel=1e-6)
    assert res["lower_bound"] <= CSAIL_F_STAR <= res["f"] + 1e-9
    assert res["relative_suboptimality_bound"] < 1e-5
    assert res["chi2_refined"] == pytest.approx(REFERENCE_CHI2["se-sync/CSAIL.g2o"], rel=1e-4)  # g2o's χ²: f's differs
    assert res["lago_certificate"]["certified"] is False
    # two points under two labels: LAGO's own translations vs re-optimised ones (measured: 53.5 vs 32.5)
    assert res["lago_certificate"]["f_input"] == pytest.approx(res["f_lago"], rel=1e-12)
    assert res["lago_certificate"]["f"] < 0.65 * res["f_lago"]


# --------------------------------------------------------------------------- not certified → 3
def test_certify_local_minimum_exit_3(capsys, tmp_path):
    # σ_θ = 0.3 rad: LAGO → χ² GN → SE-Sync Newton ends at a critical point of f (‖SYᵀ‖ ≈ 0) whose
    # certificate matrix has clearly negative eigenvalues (λ_min ≈ −0.68 ≫ η ≈ 3e-9): not certified.
    world = _world(capsys, tmp_path, "--poses", "100", "--seed", "0", "--sigma-theta", "0.3")
    out = tmp_path / "est.g2o"
    code, text, _ = run(capsys, "certify", str(world), "--json", "-o", str(out))
    assert code == EXIT_NOT_CERTIFIED == 3
    res = json.loads(text)
    assert res["certified"] is False and res["exit_status"] == 3 and res["verdict"].startswith("NOT certified")
    assert res["n_negative"] >= 1 and res["lambda_min"] < -1e6 * res["eta"]  # not a rounding artefact
    assert res["residual_rel"] < 1e-6  # a critical point, yet not certified
    assert res["lower_bound"] <= res["f"]
    assert out.exists()  # the estimate is still written (scripts decide on the exit status)
    code, text, _ = run(capsys, "certify", str(world))
    assert code == 3 and "certificate of the SE-Sync-refined estimate: NOT certified" in text
    assert "exit status 3" in text


def test_certify_tol_is_a_relative_bound_not_a_psd_threshold(capsys, tmp_path):
    # the local minimum stays uncertified at the loosest tolerance: its proven relative bound is large
    world = _world(capsys, tmp_path, "--poses", "100", "--seed", "0", "--sigma-theta", "0.3")
    code, text, _ = run(capsys, "certify", str(world), "--json", "--tol", "1e-3")
    res = json.loads(text)
    assert code == 3 and res["certified"] is False and res["relative_suboptimality_bound"] > 1e-3
    assert res["tol"] == 1e-3 and res["eta"] < -res["lambda_min"]  # a genuine negative direction, not rounding


# ------------------------------------------------------------------------------- bad input → 2
@pytest.mark.parametrize("content, fragment", [
    ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 a b c\n", "bad.g2o:2:"),                  # arity
    ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 a b c 1 0 0 1 0 1\n", "bad.g2o:2:"),      # non-numeric value
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n", "no edges: nothing to certify"),
    ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\n", "not connected"),
    ("", "no vertices and no edges"),
])
def test_certify_bad_input_exit_2_one_line(capsys, tmp_path, content, fragment):
    f = tmp_path / "bad.g2o"
    f.write_text(content)
    code, out, err = run(capsys, "certify", str(f))
    assert code == 2 and out == ""
    assert fragment in _one_error_line(err)


def test_certify_missing_file_and_bad_tol(capsys, tmp_path):
    code, _, err = run(capsys, "certify", str(tmp_path / "nope.g2o"))
    assert code == 2 and "nope.g2o" in _one_error_line(err)
    for tol in ("0", "-1", "nan", "x", "1e-2"):  # above 1e-3 the word "certified" would mean too little
        with pytest.raises(SystemExit) as exc:
            main(["certify", "w.g2o", "--tol", tol])
        assert exc.value.code == 2
        assert "--tol must be" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["certify", "w.g2o", "--max-iterations", "-1"])
    assert exc.value.code == 2 and "--max-iterations: the value must be >= 0" in capsys.readouterr().err


def test_certify_refuses_to_overwrite_input(capsys, tmp_path):
    world = _world(capsys, tmp_path, "--poses", "40")
    before = world.read_bytes()
    code, _, err = run(capsys, "certify", str(world), "-o", str(world))
    assert code == 2 and "refusing to overwrite the input file" in _one_error_line(err)
    assert world.read_bytes() == before


def test_certify_entry_points_and_documented_exit_status():
    exe = Path(sys.executable).parent / "lago-cvx"
    commands = [[sys.executable, "-m", "lago_cvx"]] + ([[str(exe)]] if exe.exists() else [])
    for cmd in commands:
        r = subprocess.run(cmd + ["certify", "--help"], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        assert "exit status: 0 certified globally optimal; 3 NOT certified" in r.stdout
        assert "not the χ²" in r.stdout


# ------------------------------------------------------------------ --regularization choices
def test_regularization_choices_follow_the_library(capsys, tmp_path):
    assert "integer" in REGULARIZATIONS
    world = _world(capsys, tmp_path, "--poses", "120", "--seed", "2")
    code, out, _ = run(capsys, "info", str(world), "--regularization", "integer", "--json")
    assert code == 0 and json.loads(out)["regularization"] == "integer"
    assert isinstance(json.loads(out)["n_regularized"], int)
    code, out, _ = run(capsys, "solve", str(world), "--regularization", "integer", "--json")
    assert code == 0 and json.loads(out)["regularization"] == "integer"
    code, out, _ = run(capsys, "certify", str(world), "--regularization", "integer", "--json")
    assert code == 0 and json.loads(out)["regularization"] == "integer" and json.loads(out)["certified"]
    with pytest.raises(SystemExit):
        main(["solve", str(world), "--regularization", "magic"])
    assert "invalid choice" in capsys.readouterr().err


def test_integer_regularization_refused_on_too_many_cycles(capsys, tmp_path, monkeypatch):
    world = _world(capsys, tmp_path, "--poses", "120", "--seed", "2")
    monkeypatch.setattr(lago_cvx.regularization, "MAX_INTEGER_CHORDS", 3)
    for cmd in ("solve", "certify"):
        code, _, err = run(capsys, cmd, str(world), "--regularization", "integer")
        assert code == 2 and "use --regularization chordal" in _one_error_line(err)
    code, out, _ = run(capsys, "info", str(world), "--regularization", "integer", "--json")
    info = json.loads(out)
    assert code == 0 and info["n_regularized"] is None and "use --regularization chordal" in info["note"]


def test_integer_search_limit_is_a_clear_error(capsys, tmp_path, monkeypatch):
    # a noisy world whose exact enumeration needs more nodes than allowed: exit 4 (a resource limit on
    # valid input), one line, the way out named
    from dataclasses import replace

    import lago_cvx.regularization.integer as integer

    world = _world(capsys, tmp_path, "--poses", "100", "--seed", "0", "--sigma-theta", "0.5")
    real = integer.integer_regularization
    monkeypatch.setattr(integer, "integer_regularization",
                        lambda *a, search, **kw: real(*a, search=replace(search, max_nodes=1), **kw))
    code, _, err = run(capsys, "solve", str(world), "--regularization", "integer")
    assert code == 4
    line = _one_error_line(err)
    assert "after 1 nodes" in line and "chordal regularization" in line
    assert "--max-nodes" in line and "--max-shift" in line and "max_nodes" not in line  # CLI terms
    # the options it names exist, and the limit they set is honoured (exit 4 again, not a usage error)
    monkeypatch.setattr(integer, "integer_regularization", real)
    code, _, err = run(capsys, "solve", str(world), "--regularization", "integer", "--max-nodes", "1")
    assert code == 4 and "after 1 nodes" in _one_error_line(err)
    code, out, _ = run(capsys, "solve", str(world), "--regularization", "integer", "--max-shift", "0", "--json")
    assert code == 0 and json.loads(out)["regularization"] == "integer"


# ----------------------------------------------------------- the comparison is opt-in; anchors
def test_certify_comparison_is_opt_in_and_labels_its_cost(capsys, tmp_path):
    """Without --compare-lago the raw LAGO estimate is not certified at all (no ``certify_lago`` time, no
    ``lago_certificate``); with it the comparison's f is LAGO's rotations with re-optimised translations,
    below ``f_lago`` (LAGO's own translations), and each number's line says which it is."""
    world = _world(capsys, tmp_path, "--poses", "150", "--seed", "3")
    code, text, _ = run(capsys, "certify", str(world), "--json")
    plain = json.loads(text)
    assert code == 0 and plain["lago_certificate"] is None and plain["compare_lago"] is False
    assert "certify_lago" not in plain["timings"]
    code, text, _ = run(capsys, "certify", str(world), "--compare-lago")
    assert code == 0
    head = "at LAGO's rotations with the translations re-optimised for them: f = "
    f_cmp = float(text.split(head)[1].split()[0])
    f_lago = float(text.split("LAGO estimate, poses as returned")[1].split("f = ")[1].split()[0])
    assert f_lago == pytest.approx(plain["f_lago"], rel=1e-9)
    # translations re-optimised for f: never above (equal here, where LAGO's re-solved positions are already
    # the optimal ones — isotropic Ω_tt makes f's translation term τ times χ²'s; CSAIL's are not, below)
    assert f_cmp <= f_lago * (1 + 1e-9)
    assert "comparison certificate" in text.split("time: ")[1]  # its time is reported apart


def test_certify_one_anchor_is_a_frame_several_are_refused(capsys, tmp_path):
    world = _world(capsys, tmp_path, "--poses", "150", "--seed", "3")
    plain_out, anch_out, part_out = tmp_path / "p.g2o", tmp_path / "a.g2o", tmp_path / "t.g2o"
    code, text, _ = run(capsys, "certify", str(world), "--json", "-o", str(plain_out))
    plain = json.loads(text)
    code_a, text, _ = run(capsys, "certify", str(world), "--json", "--anchor", "17:3.5,-2,0.25", "-o", str(anch_out))
    anch = json.loads(text)
    assert code == code_a == 0 and anch["anchor"] == 17
    assert anch["f"] == pytest.approx(plain["f"], rel=1e-9) and anch["certified"]
    g = read_graph(world)
    k = int(g.index_of(17))
    pa, pp = read_graph(anch_out).initial, read_graph(plain_out).initial
    np.testing.assert_allclose(pa[k], [3.5, -2.0, 0.25], atol=1e-9)
    # the same estimate in another frame: relative poses and f unchanged
    np.testing.assert_allclose(between(pa[k], pa)[:, :2], between(pp[k], pp)[:, :2], atol=1e-7)
    assert sesync_cost(g, pa) == pytest.approx(sesync_cost(g, pp), rel=1e-9)
    code, _, _ = run(capsys, "certify", str(world), "--anchor", "17:,,1.0", "-o", str(part_out))
    pt = read_graph(part_out).initial
    assert code == 0 and pt[k, 2] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(pt[k, :2], pp[k, :2], atol=1e-9)  # a rotation about the anchored pose
    code, out, err = run(capsys, "certify", str(world), "--anchor", "17:1,2,0", "--anchor", "3")
    assert code == 2 and out == "" and "at most one --anchor" in _one_error_line(err)
    code, out, err = run(capsys, "certify", str(world), "--anchor", "99999:1,2,0")
    assert code == 2 and "99999" in _one_error_line(err)


def test_certify_estimate_library_refuses_two_anchors():
    from lago_cvx.certification import certify_estimate
    from lago_cvx.errors import OptionError
    from lago_cvx.synthetic import manhattan_world

    g = manhattan_world(30, seed=1).graph
    with pytest.raises(OptionError, match="at most one anchor"):
        certify_estimate(g, anchors={0: (0, 0, 0), 5: (1, 1, None)})
