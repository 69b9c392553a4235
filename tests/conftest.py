"""Shared fixtures. Real datasets live in ../shared/datasets beside the project root (never copied
into the project); set LAGO_CVX_DATASETS to point elsewhere. Tests that need them are skipped,
with the reason printed, when the folder is absent; everything else runs on synthetic worlds."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DATASETS = Path(os.environ.get("LAGO_CVX_DATASETS", ROOT.parent / "shared" / "datasets"))

#: Every pose-graph file in the datasets folder (relative paths), with the counts of its README.
#: (file, n_poses, n_edges, n_odometric, n_loop_closures)
DATASET_TABLE = [
    ("se-sync/intel.g2o", 1728, 2512, 1727, 785),
    ("se-sync/CSAIL.g2o", 1045, 1172, 1044, 128),
    ("se-sync/MIT.g2o", 808, 827, 807, 20),
    ("se-sync/manhattan.g2o", 3500, 5453, 3499, 1954),
    ("se-sync/city10000.g2o", 10000, 20687, 9999, 10688),
    ("carlone/input_INTEL_g2o.g2o", 1228, 1483, 1227, 256),
    ("carlone/INTEL_P_toro.graph", 1228, 1505, 1227, 278),
    ("carlone/input_M3500_g2o.g2o", 3500, 5453, 3499, 1954),
    ("carlone/input_M3500a_g2o.g2o", 3500, 5453, 3499, 1954),
    ("carlone/M3500_P_toro.graph", 3500, 5453, 3499, 1954),
    ("carlone/CSAIL_P_toro.graph", 1045, 1172, 1044, 128),
    ("carlone/FR079_P_toro.graph", 989, 1217, 988, 229),
    ("gtsam/noisyToyGraph.txt", 4, 5, 3, 2),
    ("gtsam/orientationsNoisyToyGraph.txt", 4, 5, 3, 2),
    ("gtsam/optimizedNoisyToyGraph.txt", 4, 5, 3, 2),
]
DATASET_FILES = [row[0] for row in DATASET_TABLE]

#: χ² minima of the datasets README, section 4.2 (g2o convention).
REFERENCE_CHI2 = {
    "se-sync/intel.g2o": 44.4178, "se-sync/CSAIL.g2o": 61.143, "carlone/CSAIL_P_toro.graph": 61.143,
    "se-sync/MIT.g2o": 39.6013, "se-sync/manhattan.g2o": 3533.46, "carlone/M3500_P_toro.graph": 3533.46,
    "se-sync/city10000.g2o": 511.985, "carlone/input_INTEL_g2o.g2o": 214.171,
    "carlone/INTEL_P_toro.graph": 213.212, "carlone/input_M3500_g2o.g2o": 137.913,
    "carlone/input_M3500a_g2o.g2o": 912.115, "carlone/FR079_P_toro.graph": 36.4248,
}


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
