"""Issue 30 — sweeps beyond one machine: the experiment sweeps take ``n_jobs`` and run through joblib;
serially, with ``n_jobs=2`` (loky processes) and on a ``dask.distributed.LocalCluster`` under
``joblib.parallel_config(backend="dask")`` they give identical numbers (each trial seeds its own world).
Only the wall-clock fields (``seconds``, ``time``) may differ."""

from __future__ import annotations

import time

import pytest

from lago_cvx.errors import MissingSolverError
from lago_cvx.experiments import integer_noise_sweep, rotation_noise_sweep, run_trials

SWEEP = dict(sigmas=[0.05, 0.4], seeds=range(3), n_poses=60)
INTEGER = dict(sigmas=(0.02, 0.5), seeds=range(3), n_poses=40)


def _numbers(rows, clock):
    """The rows without their wall clock, as text: ``repr`` of a float is exact (shortest round trip), and
    NaN (no case where IP and rounding differ) then equals NaN."""
    return repr([{k: v for k, v in r.items() if k != clock} for r in rows])


def _both(**kw):
    t = time.perf_counter()
    rot = rotation_noise_sweep(**SWEEP, **kw)
    ip = integer_noise_sweep(**INTEGER, **kw)
    return _numbers(rot, "seconds"), _numbers(ip, "time"), time.perf_counter() - t, rot


def test_sweeps_identical_serially_with_two_jobs_and_on_dask(capsys):
    pytest.importorskip("joblib")
    serial = _both()
    two = _both(n_jobs=2)
    assert two[:2] == serial[:2]  # exactly equal: every number, every row, in order
    assert len({r["optimal"] for r in serial[3]}) > 1  # a sweep whose numbers vary from trial to trial
    times = {"serial": serial[2], "n_jobs=2 (loky)": two[2]}
    distributed = pytest.importorskip("distributed")
    import joblib

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster):
        with joblib.parallel_config(backend="dask"):
            dask = _both(n_jobs=2)
    assert dask[:2] == serial[:2]
    times["dask LocalCluster(2 workers)"] = dask[2]
    with capsys.disabled():
        print("\nsweep times: " + ", ".join(f"{k} {v:.1f} s" for k, v in times.items()))


def test_run_trials_keeps_order_and_reports_progress():
    seen = []
    assert run_trials(pow, [(2, k) for k in range(5)], progress=lambda d, t: seen.append((d, t))) == \
        [1, 2, 4, 8, 16]
    assert seen == [(k, 5) for k in range(1, 6)]


def test_missing_joblib_names_the_extra(monkeypatch):
    import builtins

    real = builtins.__import__

    def no_joblib(name, *a, **kw):
        if name == "joblib":
            raise ImportError("no joblib")
        return real(name, *a, **kw)

    monkeypatch.setattr(builtins, "__import__", no_joblib)
    assert run_trials(pow, [(2, 3)]) == [8]  # serial: joblib not needed
    with pytest.raises(MissingSolverError, match=r"lago-cvx\[dask\]"):
        run_trials(pow, [(2, 3)], n_jobs=2)
