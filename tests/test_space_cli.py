"""The command line on 3-D graphs: ``info``, ``solve`` (``--check``, ``--refine``, ``--anchor``, ``-o``), ``certify``
and the 3-D worlds of ``generate``, with the planar commands' JSON keys."""

from __future__ import annotations

import json

import numpy as np

import pytest

from conftest import dataset_path
from lago_cvx.cli import main
from lago_cvx.io import read_graph
from lago_cvx.posegraph3d import chi2_3d


def _run(capsys, argv):
    status = main(argv)
    return status, json.loads(capsys.readouterr().out)


@pytest.fixture()
def world(tmp_path, capsys):
    out = tmp_path / "w.g2o"
    assert main(["generate", "--world", "grid3d", "--poses", "64", "--seed", "3", "-o", str(out)]) == 0
    capsys.readouterr()
    return out


def test_generate_and_info(world, capsys):
    g = read_graph(world)
    assert g.dim == 3 and g.n_poses == 64 and read_graph(str(world).replace(".g2o", ".truth.g2o")).dim == 3
    status, info = _run(capsys, ["info", str(world), "--json"])
    assert status == 0 and info["dim"] == 3 and info["n_poses"] == 64 and info["n_components"] == 1
    assert {"n_edges", "n_loop_closures", "cyclomatic_number", "has_initial_guess"} <= set(info)


def test_solve_check_refine_output(world, tmp_path, capsys):
    out = tmp_path / "out.g2o"
    status, res = _run(capsys, ["solve", str(world), "--check", "--refine", "-o", str(out), "--json"])
    assert status == 0 and res["dim"] == 3 and max(res["max_rel_diff"].values()) < 1e-6
    assert res["chi2_refined"] <= res["chi2"] <= res["chi2_seed"]
    g = read_graph(out)
    assert chi2_3d(g, *g.initial) == pytest.approx(res["chi2_refined"], rel=1e-9)  # the refined poses were written
    status, seed = _run(capsys, ["solve", str(world), "--route", "seed", "--anchor", "5", "--json"])
    # another anchor: the chordal relaxation's projected solution is not gauge-equivariant (the relaxed anchor block
    # of one gauge is no rotation in the other), so the seed χ² moves by ~1e-6 relative (0.9e-6 in GTSAM's cost,
    # 1.2e-6 in g2o's on this world)
    assert seed["route"] == "seed" and seed["chi2"] == pytest.approx(res["chi2_seed"], rel=1e-5)
    assert main(["solve", str(world), "--anchor", "5:1,2,3"]) == 2  # a 3-D pose is ID:X,Y,Z,QX,QY,QZ,QW


def test_certify_exit_status(world, capsys):
    status, cert = _run(capsys, ["certify", str(world), "--json"])
    assert status == 0 and cert["certified"] and cert["exit_status"] == 0
    assert cert["lower_bound"] <= cert["f"] <= cert["f_lago"]


def test_solve_gtsam_offdiagonal_example(capsys):
    p = dataset_path("gtsam/pose3example-offdiagonal.txt")
    status, res = _run(capsys, ["solve", str(p), "--refine", "--json"])
    assert status == 0 and res["chi2_refined"] < 1e-12


def test_plot_projections(world, tmp_path, capsys):
    fig = tmp_path / "w.svg"
    status, res = _run(capsys, ["plot", str(world), "-o", str(fig), "--json"])
    assert status == 0 and res["dim"] == 3 and fig.read_bytes().startswith(b"<?xml")
    status, res = _run(capsys, ["plot", str(world), "-o", str(fig), "--covariances", "--every", "8", "--json"])
    assert status == 0 and res["n_ellipses"] == 8  # the ellipsoids' projections, one every 8 of 64 poses


def test_certify_3d_honours_the_anchor(capsys, tmp_path):
    """certify on a 3-D file: an unknown --anchor id exits 2 naming it; ID moves the frame; ID:X,Y,Z,QX,QY,QZ,QW puts
    that pose where given (f unchanged); a malformed spec exits 2 with one line."""
    path = str(dataset_path("se-sync-3d/smallGrid3D.g2o"))
    assert main(["certify", path, "--anchor", "99999"]) == 2
    assert "no pose with id 99999" in capsys.readouterr().err
    assert main(["certify", path, "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    out = tmp_path / "c.g2o"
    assert main(["certify", path, "--anchor", "5:1,2,3,0,0,0,1", "--json", "-o", str(out)]) == 0
    moved = json.loads(capsys.readouterr().out)
    assert moved["f"] == pytest.approx(plain["f"], rel=1e-9) and moved["certified"]
    t, R = read_graph(out).initial
    k = list(read_graph(out).ids).index(5)
    assert np.allclose(t[k], [1, 2, 3], atol=1e-12) and np.allclose(R[k], np.eye(3), atol=1e-12)
    assert main(["certify", path, "--anchor", "5:1,2"]) == 2
    assert capsys.readouterr().err.count("\n") == 1
