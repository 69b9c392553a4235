"""The public benchmark graphs: where they are, what they contain, and the reference optima.

The graphs are never copied into the project (licences vary). ``dataset("se-sync/MIT.g2o")`` finds a
file by looking, in this order, in ``$LAGO_CVX_DATASETS``, in ``../shared/datasets`` beside the project
checkout, and in ``../shared/datasets`` beside (or two levels above) the working directory; it raises
``DatasetNotFound`` naming the places tried. Code that can run without them (lectures, tests,
benchmarks) catches it and says so.

Reference values (from ``../shared/datasets/README.md``; every table in the project takes them from
here):

* ``DATASET_TABLE`` — file, poses, edges, odometric edges (consecutive ids), loop closures;
* ``REFERENCE_CHI2`` — the χ² minimum (g2o convention, Σ eᵀΩe) reached by Gauss–Newton from the chordal
  / SE-Sync point (README §4.2: best found, not certified);
* ``REFERENCE_SESYNC`` — the minimum of the SE-Sync cost f (README §4.2; all certified by
  ``lago_cvx.certification.certify``, see benchmarks/);
* ``PUBLISHED_SESYNC`` — SE-Sync's Table 1 (Rosen et al., IJRR 2019), as printed (4 digits).
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import DatasetNotFound

__all__ = ["datasets_dir", "dataset", "DatasetNotFound", "DATASET_TABLE", "DATASET_FILES", "REFERENCE_CHI2",
           "REFERENCE_SESYNC", "PUBLISHED_SESYNC"]

#: Every pose-graph file of the datasets folder with the counts of its README and the reference minima of
#: its §4.2 ("–" where there is none): χ² minimum in the g2o convention, minimum of the SE-Sync cost f.
_TABLE_TEXT = """
file                                   poses  edges  odometric  loop_closures  chi2_min  sesync_min
se-sync/intel.g2o                       1728   2512       1727            785   44.4178     52.3482
se-sync/CSAIL.g2o                       1045   1172       1044            128    61.143     31.7037
se-sync/MIT.g2o                          808    827        807             20   39.6013     61.1541
se-sync/manhattan.g2o                   3500   5453       3499           1954   3533.46     6431.39
se-sync/city10000.g2o                  10000  20687       9999          10688   511.985     638.625
carlone/input_INTEL_g2o.g2o             1228   1483       1227            256   214.171     393.653
carlone/INTEL_P_toro.graph              1228   1505       1227            278   213.212     391.721
carlone/input_M3500_g2o.g2o             3500   5453       3499           1954   137.913     193.862
carlone/input_M3500a_g2o.g2o            3500   5453       3499           1954   912.115     1597.64
carlone/M3500_P_toro.graph              3500   5453       3499           1954   3533.46     6431.39
carlone/CSAIL_P_toro.graph              1045   1172       1044            128    61.143     31.7037
carlone/FR079_P_toro.graph               989   1217        988            229   36.4248     28.5858
gtsam/noisyToyGraph.txt                    4      5          3              2         –           –
gtsam/orientationsNoisyToyGraph.txt        4      5          3              2         –           –
gtsam/optimizedNoisyToyGraph.txt           4      5          3              2         –           –
"""


def _row(line: str) -> tuple:
    file, *counts, chi2_min, sesync_min = line.split()
    return (file, *map(int, counts), *(None if v == "–" else float(v) for v in (chi2_min, sesync_min)))


_TABLE = tuple(_row(line) for line in _TABLE_TEXT.strip().splitlines()[1:])
#: (file, n_poses, n_edges, n_odometric, n_loop_closures) of every file.
DATASET_TABLE = tuple(row[:5] for row in _TABLE)
#: The files of ``DATASET_TABLE``.
DATASET_FILES = tuple(row[0] for row in _TABLE)
#: χ² minima, g2o convention (README §4.2).
REFERENCE_CHI2 = {row[0]: row[5] for row in _TABLE if row[5] is not None}
#: Minima of the SE-Sync cost f (README §4.2).
REFERENCE_SESYNC = {row[0]: row[6] for row in _TABLE if row[6] is not None}

#: SE-Sync's Table 1 (IJRR 2019), as printed.
PUBLISHED_SESYNC = {
    "se-sync/manhattan.g2o": "6.432e3", "se-sync/city10000.g2o": "6.386e2", "se-sync/CSAIL.g2o": "3.170e1",
    "se-sync/intel.g2o": "5.235e1",
}


def _candidates() -> list[Path]:
    out = []
    env = os.environ.get("LAGO_CVX_DATASETS")
    if env:
        out.append(Path(env))
    root = Path(__file__).resolve().parents[1]  # the project checkout (editable install)
    out.append(root.parent / "shared" / "datasets")
    cwd = Path.cwd().resolve()
    out += [cwd.parent / "shared" / "datasets", cwd.parent.parent / "shared" / "datasets"]
    return out


def datasets_dir() -> Path | None:
    """The datasets folder, or None when it is not found."""
    for c in _candidates():
        if c.is_dir():
            return c
    return None


def dataset(rel: str) -> Path:
    """Path of a dataset file (e.g. ``"se-sync/MIT.g2o"``); raises ``DatasetNotFound`` with the places tried."""
    base = datasets_dir()
    if base is None:
        tried = ", ".join(str(c) for c in _candidates())
        raise DatasetNotFound(f"real datasets not found (tried {tried}); set LAGO_CVX_DATASETS")
    p = base / rel
    if not p.is_file():
        raise DatasetNotFound(f"dataset {rel} not found under {base}")
    return p
