"""docs/cookbook.md runs: its python blocks, in order, in one namespace; each checks itself with asserts."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

COOKBOOK = Path(__file__).resolve().parents[1] / "docs" / "cookbook.md"
BLOCKS = re.findall(r"```python\n(.*?)```", COOKBOOK.read_text(encoding="utf-8"), re.DOTALL)
#: The recipes' titles, (a) … (h), in order (the first block is the shared world).
TITLES = ["world"] + re.findall(r"^## \(([a-z])\)", COOKBOOK.read_text(encoding="utf-8"), re.MULTILINE)


def test_every_recipe_has_a_block_of_at_most_ten_lines_with_a_check():
    assert len(BLOCKS) == len(TITLES) == 9
    for title, block in zip(TITLES[1:], BLOCKS[1:]):
        assert len(block.strip().splitlines()) <= 10, f"recipe ({title}) has more than 10 lines"
        assert "assert" in block, f"recipe ({title}) checks nothing"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """The recipes may write files (recipe (f) hands GTSAM a g2o file): they run in a fresh folder."""
    return tmp_path_factory.mktemp("cookbook")


@pytest.fixture(scope="module")
def namespace():
    ns: dict = {}
    exec(compile(BLOCKS[0], f"{COOKBOOK}:world", "exec"), ns)
    return ns


@pytest.mark.parametrize("k", range(1, 9), ids=lambda k: f"recipe-{'abcdefgh'[k - 1]}")
def test_recipe_runs_and_checks_itself(namespace, workdir, monkeypatch, k):
    from lago_cvx.datasets import locate

    monkeypatch.chdir(workdir)
    if "import gtsam" in BLOCKS[k]:
        pytest.importorskip("gtsam")
    for rel in re.findall(r'datasets\.dataset\("([^"]+)"\)', BLOCKS[k]):
        if locate(rel) is None:
            pytest.skip(f"dataset {rel} not found")
    exec(compile(BLOCKS[k], f"{COOKBOOK}:({TITLES[k]})", "exec"), namespace)
