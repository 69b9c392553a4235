"""Issue 40 — 3-D files are first-class on the command line: every option of ``solve``, ``info``, ``plot``,
``certify`` and ``generate`` either acts on a 3-D file or is refused with one line naming it (exit 2); the hints of
mistyped command lines; the absolute certification threshold (``--abs-tol``, ``abs_tol=``) on nearly noise-free
graphs, planar and 3-D."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import dataset_path
from lago_cvx.certification import certify_estimate
from lago_cvx.cli import main
from lago_cvx.errors import OptionError
from lago_cvx.io import read_graph, write_graph
from lago_cvx.posegraph3d import chi2_3d
from lago_cvx.space import lago3d
from lago_cvx.space.certify import certify3d
from lago_cvx.synthetic import manhattan_world
from lago_cvx.synthetic import space as space_worlds


def _json(capsys, argv, status=0):
    assert main(argv) == status
    return json.loads(capsys.readouterr().out)


def _usage_error(capsys, argv) -> str:
    """stderr of a command line argparse refuses (SystemExit 2: the command's usage, then one error line)."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    return capsys.readouterr().err


def _error(capsys, argv) -> str:
    """The one stderr line of a command that must exit 2."""
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    return err


@pytest.fixture()
def world3d(tmp_path, capsys):
    out = tmp_path / "w.g2o"
    assert main(["generate", "--world", "torus3d", "--poses", "60", "--seed", "5", "-o", str(out)]) == 0
    capsys.readouterr()
    return str(out)


# Each option of the planar commands that a 3-D graph cannot honour, as given on the command line.
REFUSED = [
    ("solve", ["--spanning-tree", "bfs"], "--spanning-tree"),
    ("solve", ["--regularization", "chordal"], "--regularization"),
    ("solve", ["--information", "marginal"], "--information marginal"),
    ("solve", ["--positions", "resolve"], "--positions"),
    ("solve", ["--max-nodes", "10"], "--max-nodes"),
    ("solve", ["--max-shift", "1"], "--max-shift"),
    ("solve", ["--time-limit", "1"], "--time-limit"),
    ("solve", ["--edge2-order", "g2o"], "--edge2-order"),
    ("info", ["--route", "seed"], "--route seed"),
    ("info", ["--regularization", "tree"], "--regularization"),
    ("info", ["--spanning-tree", "mst"], "--spanning-tree"),
    ("certify", ["--spanning-tree", "odometry"], "--spanning-tree"),
    ("certify", ["--regularization", "integer"], "--regularization"),
    ("certify", ["--max-nodes", "10"], "--max-nodes"),
    ("plot", ["--regularization", "chordal", "-o", "{tmp}/f.png"], "--regularization"),
    ("plot", ["--spanning-tree", "bfs", "-o", "{tmp}/f.png"], "--spanning-tree"),
]


@pytest.mark.parametrize("command,options,flag", REFUSED, ids=[f"{c} {' '.join(o[:2])}" for c, o, _ in REFUSED])
def test_planar_only_options_are_refused_on_3d_files(world3d, tmp_path, capsys, command, options, flag):
    err = _error(capsys, [command, world3d, *[o.format(tmp=tmp_path) for o in options]])
    assert flag in err and "3-D" in err


def test_generate_refuses_planar_world_options_for_3d_worlds(tmp_path, capsys):
    for options, flag in ((["--laps", "2"], "--laps"),):
        err = _error(capsys, ["generate", "--world", "sphere3d", "-o", str(tmp_path / "s.g2o"), *options])
        assert flag in err and "sphere3d" in err


def test_robust_with_full_pose_anchors_is_refused_on_3d_files(tmp_path, capsys):
    """--robust holds one pose for the frame; with poses known exactly (ID:X,Y,Z,QX,QY,QZ,QW) it is refused."""
    out = tmp_path / "w.g2o"
    assert main(["generate", "--world", "grid3d", "--poses", "27", "-o", str(out)]) == 0
    err = _error(capsys, ["solve", str(out), "--robust", "--anchor", "3:0,0,0,0,0,0,1"])
    assert "--robust" in err and "ID:X,Y,Z,QX,QY,QZ,QW" in err


def test_generate_3d_sigmas_reach_the_world(tmp_path, capsys):
    """--sigma-xy and --sigma-theta are the 3-D world's translation and rotation noise: zero noise (with the
    reference information) gives zero χ² at the truth."""
    out = tmp_path / "g.g2o"
    assert main(["generate", "--world", "grid3d", "--poses", "27", "--sigma-xy", "0", "--sigma-theta", "0",
                 "-o", str(out)]) == 0
    g = read_graph(str(out).replace(".g2o", ".truth.g2o"))
    assert chi2_3d(g, *g.initial) < 1e-18


def test_solve_3d_anchor_with_a_pose_holds_it_and_moves_the_frame(world3d, tmp_path, capsys):
    """solve --anchor ID:X,Y,Z,QX,QY,QZ,QW on a 3-D file: the pose where given (exactly, also after --refine), the
    χ² of the bare-ID run (one anchor is a choice of frame); two such anchors hold both."""
    bare = _json(capsys, ["solve", world3d, "--anchor", "7", "--json"])
    out = tmp_path / "a.g2o"
    q = np.array([0.1, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1, -0.2, 0.3, 0.9])
    spec = "7:1,2,3," + ",".join(repr(float(v)) for v in q)
    one = _json(capsys, ["solve", world3d, "--anchor", spec, "--refine", "-o", str(out), "--json"])
    assert one["chi2"] == pytest.approx(bare["chi2"], rel=1e-6) and list(one["anchors"]) == ["7"]
    g = read_graph(out)
    k = list(g.ids).index(7)
    from lago_cvx.so3 import quat_to_rot

    assert np.allclose(g.initial_t[k], [1, 2, 3], atol=1e-9)
    assert np.allclose(g.initial_R[k], quat_to_rot(q[None])[0], atol=1e-9)
    assert one["chi2_refined"] <= one["chi2"]
    two = _json(capsys, ["solve", world3d, "--anchor", spec, "--anchor", "20:0,0,0,0,0,0,1", "-o", str(out),
                         "--json"])
    g = read_graph(out)
    assert np.allclose(g.initial_t[list(g.ids).index(20)], 0, atol=1e-9) and two["chi2"] > one["chi2"]
    both = _json(capsys, ["solve", world3d, "--anchor", spec, "--anchor", "20:0,0,0,0,0,0,1", "--refine", "-o",
                          str(out), "--json"])  # --refine holds both anchors
    g = read_graph(out)
    assert np.allclose(g.initial_t[list(g.ids).index(20)], 0, atol=1e-9)
    assert np.allclose(g.initial_t[k], [1, 2, 3], atol=1e-9) and both["chi2_refined"] <= both["chi2"]
    for extra, flag in ((["--check"], "--check"), (["--method", "cvxpy"], "--method")):
        err = _error(capsys, ["solve", world3d, "--anchor", spec, "--anchor", "20:0,0,0,0,0,0,1", *extra])
        assert flag in err
    assert "bare ID" in _error(capsys, ["solve", world3d, "--anchor", spec, "--anchor", "20"])
    assert "99999" in _error(capsys, ["solve", world3d, "--anchor", "99999:0,0,0,0,0,0,1"])
    assert "ID:X,Y,Z,QX,QY,QZ,QW" in _error(capsys, ["solve", world3d, "--anchor", "7:1,2,3"])


def test_certify_3d_honours_max_iterations_and_compare_lago(world3d, capsys):
    """--max-iterations 0: the certified point is LAGO's own (not refined: not certified, exit 3); --compare-lago
    certifies the raw LAGO point too; an unknown anchor id exits 2 naming it."""
    full = _json(capsys, ["certify", world3d, "--json"])
    assert full["certified"] and full["lago_certificate"] is None
    raw = _json(capsys, ["certify", world3d, "--max-iterations", "0", "--json"], status=3)
    assert raw["f"] == pytest.approx(raw["f_lago"], rel=1e-9) and raw["f"] > full["f"] * (1 + 1e-6)
    both = _json(capsys, ["certify", world3d, "--compare-lago", "--json"])
    lc = both["lago_certificate"]
    assert both["certified"] and not lc["certified"] and lc["f"] == pytest.approx(both["f_lago"], rel=1e-9)
    assert "99999" in _error(capsys, ["certify", world3d, "--anchor", "99999"])


# ------------------------------------------------------------------------ hints of mistyped command lines
def test_a_stray_output_name_hints_at_o(world3d, capsys):
    err = _usage_error(capsys, ["solve", world3d, "out.g2o"])
    assert "usage: lago-cvx solve" in err and "did you mean -o out.g2o?" in err


def test_an_option_of_another_command_is_named(world3d, capsys):
    err = _usage_error(capsys, ["info", world3d, "--refine"])
    assert "usage: lago-cvx info" in err and "--refine belongs to `solve`" in err
    assert "--abs-tol belongs to `certify`" in _usage_error(capsys, ["info", world3d, "--abs-tol=1e-3"])
    assert "info takes one FILE" in _usage_error(capsys, ["info", world3d, "other.g2o"])
    err = _usage_error(capsys, ["solve", world3d, "--refien"])  # a typo
    assert "did you mean --refine?" in err
    err = _usage_error(capsys, ["solve", world3d, "--max-iteratoins", "3"])
    assert "did you mean --max-iterations?" in err and "-o 3" not in err  # 3 is the unknown option's value
    err = _usage_error(capsys, ["solve", world3d, "--bogus", "3"])
    assert err.rstrip().endswith("unrecognized arguments: --bogus 3")  # no hint rather than a wrong one


def test_plot_over_its_input_names_the_figure_and_no_missing_option(world3d, tmp_path, capsys):
    err = _error(capsys, ["plot", world3d, "-o", world3d])
    assert "the figure" in err and "--overwrite-input" not in err
    png = tmp_path / "est.png"
    png.write_bytes(b"")
    err = _error(capsys, ["plot", world3d, str(png), "-o", str(png)])  # nor over its ESTIMATE
    assert "the figure" in err and str(png) in err


def test_a_corrupted_first_line_of_a_3d_file_names_the_3d_tags(world3d, tmp_path, capsys):
    lines = open(world3d).read().splitlines()
    bad = tmp_path / "bad.g2o"
    bad.write_text("\n".join(["VERTEX_SE3:QUA" + lines[0][len("VERTEX_SE3:QUAT"):], *lines[1:]]) + "\n")
    err = _error(capsys, ["info", str(bad)])
    assert f"{bad}:1:" in err and "VERTEX_SE3:QUAT/EDGE_SE3:QUAT" in err and "VERTEX_SE2/EDGE_SE2" in err


# ------------------------------------------------------------------------ the absolute certification threshold
def _quiet_planar():
    """A nearly noise-free planar world: noise 1e-5 m / 1e-6 rad measured with the information of 5 cm / 0.02 rad
    (f ≈ 1e-5, far below the d·n·η the relative test must absorb)."""
    return manhattan_world(300, seed=1, sigma_xy=1e-5, sigma_theta=1e-6, info_sigma_xy=0.05, info_sigma_theta=0.02)


def _quiet_3d():
    """A nearly noise-free 3-D world: noise 1e-6 measured with the information of σ = 1 cm / 0.01 rad (f ≈ 3e-5)."""
    return space_worlds.cube_grid_world(5, seed=1, sigma_t=1e-6, sigma_r=1e-6, info_sigma_t=0.01,
                                        info_sigma_r=0.01).graph


def test_abs_tol_certifies_a_nearly_noise_free_planar_graph(tmp_path, capsys):
    g = _quiet_planar().graph
    rep, cert = certify_estimate(g)
    assert not cert.certified and rep["relative_suboptimality_bound"] > 0.1 and rep["f"] < 1e-3
    rep, cert = certify_estimate(g, abs_tol=1e-3)
    assert cert.certified and cert.abs_tol == 1e-3 and "absolute tolerance" in cert.verdict
    assert cert.cost - cert.lower_bound <= 1e-3  # what it proves
    rep, cert = certify_estimate(g, abs_tol=1e-9)  # a threshold below the proven gap and below η: not certified
    assert not cert.certified
    path = tmp_path / "quiet.g2o"
    write_graph(path, g)
    assert _json(capsys, ["certify", str(path), "--json"], status=3)["abs_tol"] == 0
    out = _json(capsys, ["certify", str(path), "--abs-tol", "1e-3", "--json"])
    assert out["certified"] and out["abs_tol"] == 1e-3
    assert "--abs-tol: expected a finite number >= 0" in _usage_error(capsys, ["certify", str(path), "--abs-tol",
                                                                               "-1"])


def test_abs_tol_certifies_a_nearly_noise_free_3d_graph(tmp_path, capsys):
    g = _quiet_3d()
    res = lago3d(g)
    cert = certify3d(g, res.t, res.R, anchor_index=res.anchor_index)
    assert not cert.certified and cert.relative_suboptimality_bound > 0.1 and cert.cost < 1e-3
    cert = certify3d(g, res.t, res.R, anchor_index=res.anchor_index, abs_tol=1e-3)
    assert cert.certified and cert.cost - cert.lower_bound <= 1e-3 and "absolute tolerance" in cert.verdict
    path = tmp_path / "quiet3d.g2o"
    write_graph(path, g)
    _json(capsys, ["certify", str(path), "--json"], status=3)
    assert _json(capsys, ["certify", str(path), "--abs-tol", "1e-3", "--json"])["certified"]


@pytest.mark.parametrize("world", ["manhattan", "grid3d"])
def test_generate_a_nearly_noise_free_world_and_certify_it_with_abs_tol(tmp_path, capsys, world):
    """``generate`` with a tiny noise and a realistic information (--info-sigma-*): the relative test cannot pass
    (exit 3), --abs-tol 1e-3 certifies it (exit 0), by a proven gap below 1e-3."""
    path = tmp_path / "quiet.g2o"
    assert main(["generate", "--world", world, "--poses", "125", "--sigma-xy", "1e-6", "--sigma-theta", "1e-6",
                 "--info-sigma-xy", "0.01", "--info-sigma-theta", "0.01", "-o", str(path)]) == 0
    capsys.readouterr()
    rel = _json(capsys, ["certify", str(path), "--json"], status=3)
    assert rel["f"] < 1e-3 and rel["relative_suboptimality_bound"] > 0.1
    assert main(["certify", str(path)]) == 3 and "--abs-tol ABS certifies it" in capsys.readouterr().out
    out = _json(capsys, ["certify", str(path), "--abs-tol", "1e-3", "--json"])
    assert out["certified"] and out["f"] - out["lower_bound"] <= 1e-3


def test_abs_tol_below_the_floor_does_not_pass_by_the_eigenvalue_test(tmp_path, capsys):
    """On a graph whose information is large (η = 1e-12‖M‖ ≈ 0.1), λ_min ≥ −1e-3 cannot be proven: the absolute
    test then rests on the gap alone, which is far above 1e-3 — not certified."""
    w = manhattan_world(300, seed=1, sigma_xy=1e-5, sigma_theta=1e-5)  # information of σ = 1e-5: f ≈ 3m
    rep, cert = certify_estimate(w.graph, abs_tol=1e-3)
    assert cert.eta > 1e-3 and not cert.certified


def test_abs_tol_must_be_finite_and_nonnegative():
    g = _quiet_planar().graph
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(OptionError, match="abs_tol"):
            certify_estimate(g, abs_tol=bad)


def test_a_stray_choice_hints_at_the_option_it_belongs_to(world3d, tmp_path, capsys):
    out = str(tmp_path / "x.g2o")
    err = _usage_error(capsys, ["generate", "manhattan", "--poses", "100", "-o", out])
    assert "usage: lago-cvx generate" in err and "did you mean --world manhattan?" in err and "-o manhattan" not in err
    assert "did you mean --world sphere3d?" in _usage_error(capsys, ["generate", "--poses", "10", "-o", out, "sphere3d"])
    err = _usage_error(capsys, ["solve", world3d, "default"])
    assert "did you mean --route default?" in err and "-o default" not in err
    assert "did you mean -o out.g2o?" in _usage_error(capsys, ["solve", world3d, "out.g2o"])  # no choice: still -o


def test_every_choice_of_every_command_hints_at_its_options():
    from lago_cvx.cli.main import _subcommands, build_parser, unrecognized_hint

    parser = build_parser()
    seen = 0
    for name, command in _subcommands(parser).items():
        for action in command._actions:
            if not action.option_strings or action.choices is None:
                continue
            option = max(action.option_strings, key=len)
            for choice in action.choices:
                assert f"{option} {choice}" in unrecognized_hint(parser, name, [str(choice)]), (name, option, choice)
                seen += 1
    assert seen > 20  # generate's --world, solve's --route, … (most commands have some)
