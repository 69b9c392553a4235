"""Shared fixtures. Real datasets live in ../shared/datasets beside the project root (never copied
into the project); set LAGO_CVX_DATASETS to point elsewhere. Tests that need them are skipped,
with the reason printed, when the folder is absent; everything else runs on synthetic worlds."""

from __future__ import annotations

from pathlib import Path

import pytest

from lago_cvx import datasets as _datasets

ROOT = Path(__file__).resolve().parents[1]
#: The datasets folder as the package finds it ($LAGO_CVX_DATASETS, then ../shared/datasets), or a
#: path that does not exist.
DATASETS = _datasets.datasets_dir() or ROOT.parent / "shared" / "datasets"


@pytest.fixture(scope="session")
def datasets_dir() -> Path:
    if not DATASETS.is_dir():
        pytest.skip(f"real datasets not found at {DATASETS} (set LAGO_CVX_DATASETS)")
    return DATASETS


def dataset_path(rel: str) -> Path:
    """Path of a dataset file, or skip the calling test when it is absent."""
    p = DATASETS / rel
    if not p.is_file():
        pytest.skip(f"dataset {rel} not found under {DATASETS}")
    return p
