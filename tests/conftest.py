"""Shared fixtures. Real datasets live in ../shared/datasets beside the project root (never copied
into the project); set LAGO_CVX_DATASETS to point elsewhere. Tests that need them are skipped,
with the reason printed, when the folder is absent; everything else runs on synthetic worlds."""

from __future__ import annotations

import importlib
import sys
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


def bench_module(name: str):
    """A module of benchmarks/ (``robust3d``, ``separable``, …), imported with that folder on the path only
    while importing."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
