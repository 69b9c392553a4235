"""LAGO where scientific Python users run it: results survive pickle and deepcopy (with their covariances),
forked workers after a warm parent, spawned workers and two threads at once give the serial results, and
joblib (and its Dask backend) carry results back. benchmarks/processes.py runs the same on the real graphs."""

from __future__ import annotations

import concurrent.futures as cf
import copy
import logging
import multiprocessing as mp
import pickle
import sys

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.refinement import refine

WORLDS = [(120, 0), (400, 1), (250, 2), (600, 3)]


def _graph(n, seed):
    return lc.manhattan_world(n, seed=seed).graph


def _chi2(args):
    return float(lc.lago(_graph(*args)).chi2)


@pytest.fixture(scope="module")
def serial():
    return [_chi2(w) for w in WORLDS]  # also warms this process: pools, orderings, thread state


def _results(g):
    a, b = int(g.ids[0]), int(g.ids[len(g.ids) // 2])
    return {
        "default": lc.lago(g),
        "seed": lc.lago(g, route="seed"),
        "chordal": lc.lago(g, regularization="chordal"),
        "anchored": lc.lago(g, anchors={a: (0.0, 0.0, 0.0), b: (3.0, -2.0, 0.5)}),
        "cvxpy": lc.lago(g, method="cvxpy"),
    }


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_results_survive_copies_with_their_covariances(how):
    g = _graph(80, 5)
    copier = (lambda r: pickle.loads(pickle.dumps(r))) if how == "pickle" else copy.deepcopy
    for name, res in _results(g).items():
        twin = copier(res)
        np.testing.assert_array_equal(twin.poses, res.poses, err_msg=name)
        assert twin.chi2 == res.chi2, name
        cov, cov2 = res.pose_covariances(), twin.pose_covariances()  # the copy refactors what it needs
        np.testing.assert_allclose(cov2, cov, rtol=1e-9, atol=1e-12 * np.abs(cov).max(), err_msg=name)
    ref = refine(g, lc.lago(g).poses)
    twin = copier(ref)
    np.testing.assert_array_equal(twin.poses, ref.poses)


def test_a_cvxpy_problem_travels_and_solves_again():
    res = lc.lago(_graph(60, 2), method="cvxpy")
    prob = pickle.loads(pickle.dumps(res.problems["phase1"]))
    assert "P_δ^(-1/2)" in str(prob)
    prob.solve(solver="CLARABEL")
    assert prob.value == pytest.approx(res.problems["phase1"].value, rel=1e-6)


@pytest.mark.skipif(sys.platform != "linux", reason="fork start method")
def test_forked_workers_after_a_warm_parent(serial, caplog):
    ctx = mp.get_context("fork")
    with caplog.at_level(logging.WARNING, logger="lago_cvx"):
        for _ in range(3):
            with cf.ProcessPoolExecutor(2, mp_context=ctx) as ex:
                assert list(ex.map(_chi2, WORLDS)) == serial


def test_spawned_workers(serial):
    with cf.ProcessPoolExecutor(2, mp_context=mp.get_context("spawn")) as ex:
        assert list(ex.map(_chi2, WORLDS)) == serial


def test_two_threads_at_once(serial):
    with cf.ThreadPoolExecutor(2) as ex:
        assert list(ex.map(_chi2, WORLDS * 2)) == serial * 2


def test_joblib_carries_results_back(serial):
    joblib = pytest.importorskip("joblib")
    got = joblib.Parallel(n_jobs=2)(joblib.delayed(lc.lago)(_graph(*w)) for w in WORLDS)
    assert [float(r.chi2) for r in got] == serial
    assert got[0].pose_covariances().shape == (WORLDS[0][0], 3, 3)


def test_joblib_on_a_dask_cluster(serial):
    joblib = pytest.importorskip("joblib")
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster):
        with joblib.parallel_config(backend="dask"):
            got = joblib.Parallel()(joblib.delayed(lc.lago)(_graph(*w)) for w in WORLDS)
    assert [float(r.chi2) for r in got] == serial


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_certificates_and_3d_results_survive_copies(how):
    """The certificate of the SE-Sync-refined estimate and a 3-D result travel too (data, no engine state)."""
    from lago_cvx.certification import certify_estimate
    from lago_cvx.synthetic.space import sphere_world

    copier = (lambda r: pickle.loads(pickle.dumps(r))) if how == "pickle" else copy.deepcopy
    g = _graph(60, 7)
    report, cert = certify_estimate(g)
    twin = copier(cert)
    assert type(twin) is type(cert) and twin.certified == cert.certified
    assert twin.cost == cert.cost and twin.lower_bound == cert.lower_bound
    np.testing.assert_array_equal(twin.poses, cert.poses)
    assert copier(report) == report
    w = sphere_world(4, 8, seed=2)
    res3 = lc.lago(w.graph)
    twin3 = copier(res3)
    np.testing.assert_array_equal(twin3.t, res3.t)
    assert twin3.chi2 == res3.chi2
