"""Settings are frozen dataclasses that refuse a bad value when they are made, with an ``OptionError`` naming
the field — never a ``TypeError`` later, nor a bool or a string taken as a number — and take NumPy scalars as
numbers."""

from __future__ import annotations

import numpy as np
import pytest

from lago_cvx.errors import OptionError
from lago_cvx.solvers import ClarabelSettings, IntegerSearch
from lago_cvx.variants import RobustSettings

BAD = [
    (RobustSettings, dict(confidence="0.9"), "robust confidence"), (RobustSettings, dict(threshold="2"), "threshold"),
    (RobustSettings, dict(mu_factor=None), "mu_factor"), (RobustSettings, dict(mu_factor=float("inf")), "mu_factor"),
    (RobustSettings, dict(max_iterations=True), "max_iterations"), (RobustSettings, dict(max_iterations=1.5), "max_"),
    (RobustSettings, dict(local_search=True), "local_search"), (RobustSettings, dict(calibrate=True), "calibrate"),
    (RobustSettings, dict(trust_odometry=1), "trust_odometry"), (RobustSettings, dict(trust_odometry=0), "trust_"),
    (RobustSettings, dict(drop_below="x"), "drop_below"), (RobustSettings, dict(readmit=-1), "readmit"),
    (RobustSettings, dict(weight_tolerance=0.5), "weight_tolerance"), (RobustSettings, dict(start=3), "start"),
    (ClarabelSettings, dict(max_iter=-5), "max_iter"), (ClarabelSettings, dict(max_iter="ten"), "max_iter"),
    (ClarabelSettings, dict(tol_gap_abs=float("nan")), "tol_gap_abs"), (ClarabelSettings, dict(tol_feas=-1), "tol_"),
    (ClarabelSettings, dict(verbose=1), "verbose"), (ClarabelSettings, dict(direct_solve_method=3), "direct_solve"),
    (IntegerSearch, dict(time_limit="5"), "time_limit"), (IntegerSearch, dict(max_nodes="x"), "max_nodes"),
    (IntegerSearch, dict(max_nodes=1.5), "max_nodes"), (IntegerSearch, dict(max_shift=-1), "max_shift"),
    (IntegerSearch, dict(solver=3), "solver"),
]


@pytest.mark.parametrize("cls, kw, name", BAD, ids=[f"{c.__name__}-{next(iter(k))}-{i}" for i, (c, k, _) in
                                                   enumerate(BAD)])
def test_bad_values_are_refused_when_made(cls, kw, name):
    with pytest.raises(OptionError, match=name):
        cls(**kw)


def test_numpy_scalars_are_numbers_and_settings_hash():
    r = RobustSettings(max_iterations=np.int64(5), confidence=np.float64(0.95), trust_odometry=np.True_,
                       local_search=np.int32(0))
    assert (r.max_iterations, r.confidence, r.trust_odometry, r.local_search) == (5, 0.95, True, 0)
    assert type(r.max_iterations) is int and type(r.confidence) is float and r.trust_odometry is True
    assert r == RobustSettings(max_iterations=5, confidence=0.95, trust_odometry=True, local_search=0)
    c = ClarabelSettings(max_iter=np.int64(50), verbose=np.True_, tol_feas=0)
    assert c.max_iter == 50 and type(c.max_iter) is int and c.verbose is True and c.tol_feas == 0.0
    i = IntegerSearch(max_nodes=np.int64(10), time_limit=5)
    assert i.max_nodes == 10 and i.time_limit == 5.0
    assert len({r, c, i, IntegerSearch(solver_options={"a": 1})}) == 4  # every settings object hashes
