"""Every lecture notebook executes top to bottom (nbclient), and its .py/.ipynb pair is in sync.

Notebooks run with lectures/ as the working directory. Real-data cells read ../shared/datasets through
``lago_cvx.datasets`` and say so clearly when it is absent.
"""

from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext", reason="the test extra (pip install -e '.[test]') runs the lectures")
nbclient = pytest.importorskip("nbclient")

LECTURES = Path(__file__).resolve().parents[1] / "lectures"
SOURCES = sorted(LECTURES.glob("[0-9][0-9]_*.py"))


def test_there_are_lectures():
    assert SOURCES, f"no lectures found in {LECTURES}"


@pytest.mark.parametrize("src", SOURCES, ids=[s.stem for s in SOURCES])
def test_pair_in_sync(src):
    ipynb = src.with_suffix(".ipynb")
    assert ipynb.exists(), f"{ipynb.name} missing: run `jupytext --sync {src}`"
    a = [(c.cell_type, c.source.strip()) for c in jupytext.read(src).cells]
    b = [(c.cell_type, c.source.strip()) for c in jupytext.read(ipynb).cells]
    assert a == b, f"{src.name} and {ipynb.name} differ: run `jupytext --sync {src}`"
    assert all(not c.get("outputs") for c in jupytext.read(ipynb).cells if c.cell_type == "code"), \
        f"{ipynb.name} carries outputs: strip them (jupyter nbconvert --clear-output)"


@pytest.mark.parametrize("src", SOURCES, ids=[s.stem for s in SOURCES])
def test_lecture_executes(src, monkeypatch, tmp_path):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")  # reproducible figure metadata (the kernel inherits it)
    monkeypatch.setenv("LAGO_CVX_FIGURES", str(tmp_path))  # running the tests changes no tracked file
    nb = jupytext.read(src)
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(LECTURES)}})
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors
