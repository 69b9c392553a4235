"""The ``lago-cvx`` process defers NumPy submodules SciPy only enumerates (lago_cvx/cli/startup.py):
they are not executed on the solve path, they work when used, and the results are byte-identical."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

#: Modules that only a real import of numpy.f2py / numpy.testing executes.
_BODIES = ("numpy.f2py.crackfortran", "numpy.testing._private.utils", "numpy.ma.core")


def _run(code: str, *, env=None) -> str:
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                         env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


def _cli(*args, eager=False):
    """Run ``lago-cvx ARGS`` as the console entry point does; the deferred modules' bodies it executed."""
    env = dict(os.environ, LAGO_CVX_EAGER_IMPORTS="1" if eager else "0")
    code = f"""
        import sys
        from lago_cvx.cli import main
        sys.argv = ["lago-cvx", *{list(args)!r}]
        status = main()
        assert status == 0, status
        print("loaded:", *(m for m in {_BODIES!r} if m in sys.modules))
    """
    return _run(code, env=env).splitlines()[-1].removeprefix("loaded:").strip()


def test_solve_runs_none_of_the_deferred_modules_and_gives_the_same_file(tmp_path):
    world, lazy_out, eager_out = (str(tmp_path / n) for n in ("w.g2o", "lazy.g2o", "eager.g2o"))
    # generate draws from numpy.random: a deferred module that is used loads on demand
    assert _cli("generate", "--poses", "300", "--seed", "4", "-o", world) == ""
    assert _cli("solve", world, "-o", lazy_out) == ""
    loaded = _cli("solve", world, "-o", eager_out, eager=True)
    # the opt-out imports eagerly; should a SciPy stop cloning NumPy's namespace, the deferral is moot
    assert "numpy.f2py.crackfortran" in loaded, "import scipy.sparse no longer executes numpy.f2py"
    with open(lazy_out, "rb") as a, open(eager_out, "rb") as b:
        assert a.read() == b.read()


def test_deferred_modules_work_when_used():
    out = _run("""
        from lago_cvx.cli.startup import defer_unused_numpy_modules, DEFERRED_NUMPY_MODULES
        deferred = defer_unused_numpy_modules()
        assert set(deferred) <= set(DEFERRED_NUMPY_MODULES) and "numpy.f2py" in deferred, deferred
        import scipy.sparse
        import numpy as np
        from numpy.random import default_rng
        assert np.ma.masked_array([1.0, 2.0], mask=[0, 1]).sum() == 1.0
        assert default_rng(0).random() == np.random.default_rng(0).random()
        np.testing.assert_allclose(np.polynomial.Polynomial([1, 2])(3.0), 7.0)
        assert callable(np.f2py.run_main) and np.ctypeslib.as_array is not None
        print("ok")
    """)
    assert out.strip() == "ok"


@pytest.mark.parametrize("how", ["argv", "env"])
def test_in_process_callers_and_the_opt_out_keep_eager_imports(how, tmp_path):
    """main(argv=[...]) from a user's interpreter, or LAGO_CVX_EAGER_IMPORTS=1, defers nothing."""
    env = dict(os.environ, LAGO_CVX_EAGER_IMPORTS="1" if how == "env" else "0")
    call = "main(['--version'])" if how == "argv" else "sys.argv = ['lago-cvx', '--version']; main()"
    out = _run(f"""
        import sys
        from lago_cvx.cli import main
        try:
            {call}
        except SystemExit:
            pass
        print(sum(type(m).__name__ == "_LazyModule" for m in list(sys.modules.values())))
    """, env=env)
    assert out.strip().splitlines()[-1] == "0"
