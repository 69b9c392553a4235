"""The public benchmark graphs: where they are, what they contain, and the reference optima.

The graphs are never copied into the project (licences vary). ``dataset("se-sync/MIT.g2o")`` finds a
file by looking, in this order, in ``$LAGO_CVX_DATASETS``, in ``../shared/datasets`` beside the project
checkout (and beside, or two levels above, the working directory), and in the download cache
(``$LAGO_CVX_CACHE``, default ``~/.cache/lago_cvx/datasets``); it raises ``DatasetNotFound`` naming the
places tried. Code that can run without them (lectures, tests, benchmarks) catches it and says so.

``MANIFEST`` gives, for every file, its SHA-256 and its public source (GitHub repository, commit and
path; the bytes there are identical, checked by git blob id). ``verify()`` checks the files found against
it, and ``fetch()`` downloads missing ones into the cache with ``pooch`` (the optional extra
``pip install "lago-cvx[datasets]"``; never needed by the tests). ``lago-cvx datasets`` does the same
on the command line.

Reference values (from ``../shared/datasets/README.md``; every table in the project takes them from
here):

* ``DATASET_TABLE`` — file, poses, edges, odometric edges (consecutive ids), loop closures;
* ``REFERENCE_CHI2`` — the minimum of the cost each file means (``lago_cvx.conventions``: g2o's χ² for g2o
  files, eq. (3) for TORO files; Σ eᵀΩe, no ½): the lower of ``refine`` from LAGO and g2o's own
  Levenberg–Marquardt from there (``benchmarks/costs.md``; best found, not certified);
* ``REFERENCE_SESYNC`` — the minimum of the SE-Sync cost f (README §4.2; all certified by
  ``lago_cvx.certification.certify``, see benchmarks/);
* ``PUBLISHED_SESYNC`` — SE-Sync's Table 1 (Rosen et al., IJRR 2019), as printed (4 digits).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import NamedTuple

from .errors import DatasetNotFound

__all__ = ["datasets_dir", "dataset", "DatasetNotFound", "DATASET_TABLE", "DATASET_FILES", "REFERENCE_CHI2",
           "REFERENCE_SESYNC", "PUBLISHED_SESYNC", "MANIFEST", "Source", "cache_dir", "locate", "verify", "fetch",
           "source_url", "resolve_name"]

#: Every pose-graph file of the datasets folder with the counts of its README and the reference minima of
#: its §4.2 ("–" where there is none): the minimum of the file's own cost (``REFERENCE_CHI2``), of the SE-Sync cost f.
_TABLE_TEXT = """
file                                   poses  edges  odometric  loop_closures  chi2_min  sesync_min
se-sync/intel.g2o                       1728   2512       1727            785   45.0047     52.3482
se-sync/CSAIL.g2o                       1045   1172       1044            128    40.5551     31.7037
se-sync/MIT.g2o                          808    827        807             20   41.1633     61.1541
se-sync/manhattan.g2o                   3500   5453       3499           1954   3549.04     6431.39
se-sync/city10000.g2o                  10000  20687       9999          10688   511.985     638.625
carlone/input_INTEL_g2o.g2o             1228   1483       1227            256   215.830     393.653
carlone/INTEL_P_toro.graph              1228   1505       1227            278   214.873     391.721
carlone/input_M3500_g2o.g2o             3500   5453       3499           1954   137.913     193.862
carlone/input_M3500a_g2o.g2o            3500   5453       3499           1954   912.115     1597.64
carlone/M3500_P_toro.graph              3500   5453       3499           1954   3549.04     6431.39
carlone/CSAIL_P_toro.graph              1045   1172       1044            128    40.5551     31.7037
carlone/FR079_P_toro.graph               989   1217        988            229   38.8449     28.5858
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
#: χ² minima of each file's own cost (module docstring).
REFERENCE_CHI2 = {row[0]: row[5] for row in _TABLE if row[5] is not None}
#: Minima of the SE-Sync cost f (datasets README §4.1–4.2).
REFERENCE_SESYNC = {row[0]: row[6] for row in _TABLE if row[6] is not None}

#: SE-Sync's Table 1 (IJRR 2019), as printed.
PUBLISHED_SESYNC = {
    "se-sync/manhattan.g2o": "6.432e3", "se-sync/city10000.g2o": "6.386e2", "se-sync/CSAIL.g2o": "3.170e1",
    "se-sync/intel.g2o": "5.235e1",
}


class Source(NamedTuple):
    """Where a dataset file comes from: ``sha256`` of its bytes, GitHub ``repository``, ``commit`` and
    ``path`` there (the same bytes), and the licence the repository states."""

    file: str
    sha256: str
    repository: str
    commit: str
    path: str
    licence: str


_SE_SYNC = ("david-m-rosen/SE-Sync", "9b631b6b82d8aa7d32ab846412ae1c070412b7b6", "LGPL-3.0 (code); data as published")
_NANO_PGO = ("gisbi-kim/nano-pgo", "b85562f0acda4d3e556f5b2d27c14156336df75b", "no licence file; data from L. Carlone's page")
_ISRANI = ("israni/Submapping--Graph-SLAM", "56190e919bfffef2c20059b3c7bfd350d2f68c40",
           "no licence file; data from L. Carlone's page")
_PYSLAM = ("memorydump85/pyslam", "cd6b3ba39efd5ad334797719ec65b3be848ea94c", "no licence file")
_GTSAM = ("borglab/gtsam", "0ffe6c930302ebd297484e65e6e8d467c91d26b0", "BSD-3-Clause")

#: file → (sha256, (repository, commit, licence), path in the repository)
_SOURCES = {
    "se-sync/intel.g2o": ("3e0724c048e0ba524be9dd268a8b78e19a2497043143584cbb61310638b15c4b", _SE_SYNC, "data/intel.g2o"),
    "se-sync/CSAIL.g2o": ("66d99ac857a9849d814d214a9ebd0d4876d5d40f0a37be9330c1ff6e6e9daaa6", _SE_SYNC, "data/CSAIL.g2o"),
    "se-sync/MIT.g2o": ("e5922be0d0689c7a5bc04c58adf3a8e697e240bdd7691cc4218470eaf92956eb", _SE_SYNC, "data/MIT.g2o"),
    "se-sync/manhattan.g2o": ("6ae8d30971720c1af24a00c4b2dd5c5ddafbbbe488bfc771145c47decbffb248", _SE_SYNC,
                              "data/manhattan.g2o"),
    "se-sync/city10000.g2o": ("df5988994339e990be198a36e7f640e31a5a1b26df3ed400363fafc49d5ca630", _SE_SYNC,
                              "data/city10000.g2o"),
    "carlone/input_INTEL_g2o.g2o": ("e648e42b1f24ab01cce76f56c8d8dad0b606f712afe2b92356bf26f195c602be", _NANO_PGO,
                                    "data/input_INTEL_g2o.g2o"),
    "carlone/INTEL_P_toro.graph": ("c715e7b5c9035080582e67bbaa1f9aca6b2bf7f166046333be0218c9923fa37c", _ISRANI,
                                   "Datasets/INTEL_P_toro.graph"),
    "carlone/input_M3500_g2o.g2o": ("1883593980e602b11bd0ba95799c969e59ee8a6892bdb2a3a48f495459efe9d8", _NANO_PGO,
                                    "data/input_M3500_g2o.g2o"),
    "carlone/input_M3500a_g2o.g2o": ("34deb00c3ff7206048d805c612c545cd8764ac3a7fd933a4ee2d3419fc3a0b8f", _PYSLAM,
                                     "datasets/M3500a.g2o"),
    "carlone/M3500_P_toro.graph": ("675a0eabfa741d4667250bacbcfe9bdfead1715dab1cd753d361bdf2f4d9d8bf", _ISRANI,
                                   "Datasets/M3500_P_toro.graph"),
    "carlone/CSAIL_P_toro.graph": ("fcf4de76b262e7f58ea64b8c5db806fec926a519d2f5d85fcc9c553f8f82fa98", _NANO_PGO,
                                   "data/CSAIL_P_toro.graph"),
    "carlone/FR079_P_toro.graph": ("ba53624ae4ed843258359c8e5713e7456943b6daf2e4a17b800a90e170d7e659", _NANO_PGO,
                                   "data/FR079_P_toro.graph"),
    "gtsam/noisyToyGraph.txt": ("9b2d2930cf50b2b2c756172f50c34503c41644e529727bd7a4960f6e785ff859", _GTSAM,
                                "examples/Data/noisyToyGraph.txt"),
    "gtsam/orientationsNoisyToyGraph.txt": ("bc2ab0aae5cd3d07d639d1725714475bcae25f42300f1d78952c0f71b1abbe40", _GTSAM,
                                            "examples/Data/orientationsNoisyToyGraph.txt"),
    "gtsam/optimizedNoisyToyGraph.txt": ("08f1962a9aff2971151b31e9535df199d83de065a5f194f794e55451f95e4767", _GTSAM,
                                         "examples/Data/optimizedNoisyToyGraph.txt"),
}

#: Every dataset file's ``Source`` (SHA-256 and public origin), in ``DATASET_FILES`` order.
MANIFEST = {f: Source(f, sha, repo, commit, path, licence)
            for f, (sha, (repo, commit, licence), path) in ((f, _SOURCES[f]) for f in DATASET_FILES)}

#: Base of the download URLs (``$LAGO_CVX_DATASETS_MIRROR`` replaces it, e.g. for a local mirror).
RAW_BASE = "https://raw.githubusercontent.com"


def source_url(file: str) -> str:
    """The download URL of a dataset file: ``<base>/<repository>/<commit>/<path>``."""
    src = _source(file)
    base = os.environ.get("LAGO_CVX_DATASETS_MIRROR", RAW_BASE).rstrip("/")
    return f"{base}/{src.repository}/{src.commit}/{src.path}"


def _source(file: str) -> Source:
    try:
        return MANIFEST[file]
    except KeyError:
        raise DatasetNotFound(f"unknown dataset {file!r}; known: {', '.join(DATASET_FILES)}") from None


def cache_dir() -> Path:
    """Where ``fetch`` puts downloads: ``$LAGO_CVX_CACHE`` or ``~/.cache/lago_cvx/datasets``
    (``$XDG_CACHE_HOME`` respected)."""
    env = os.environ.get("LAGO_CVX_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "lago_cvx" / "datasets"


def _project_candidates() -> list[Path]:
    """``../shared/datasets`` beside the project checkout (editable install) and beside, or two levels
    above, the working directory."""
    root = Path(__file__).resolve().parents[1]
    cwd = Path.cwd().resolve()
    return [root.parent / "shared" / "datasets", cwd.parent / "shared" / "datasets",
            cwd.parent.parent / "shared" / "datasets"]


def _candidates() -> list[Path]:
    out = []
    env = os.environ.get("LAGO_CVX_DATASETS")
    if env:
        out.append(Path(env))
    out += _project_candidates()
    out.append(cache_dir())
    seen, unique = set(), []
    for c in out:
        if c not in seen:
            seen.add(c)
            unique.append(c)
    return unique


def datasets_dir() -> Path | None:
    """The first datasets folder that exists (``$LAGO_CVX_DATASETS``, ``../shared/datasets``, the cache),
    or None."""
    for c in _candidates():
        if c.is_dir():
            return c
    return None


def locate(rel: str) -> Path | None:
    """The first place (in the lookup order) that holds ``rel``, or None."""
    for c in _candidates():
        p = c / rel
        if p.is_file():
            return p
    return None


def resolve_name(name: str) -> str:
    """The ``DATASET_FILES`` entry ``name`` means: the entry itself, else the one entry whose basename
    (``CSAIL.g2o``) or stem (``CSAIL``) is ``name`` — exactly, else ignoring case. Raises
    ``DatasetNotFound`` for a name that matches no entry or several, listing the candidates."""
    if name in DATASET_FILES:
        return name
    base = {f: f.rsplit("/", 1)[-1] for f in DATASET_FILES}
    keys = {f: (b, b.rsplit(".", 1)[0]) for f, b in base.items()}
    for fold in (str, str.lower):  # exact, then ignoring case
        hits = [f for f, k in keys.items() if fold(name) in map(fold, k)]
        if len(hits) == 1:
            return hits[0]
        if hits:
            raise DatasetNotFound(f"dataset name {name!r} is ambiguous: it names {', '.join(hits)}; give one of them")
    near = [f for f in DATASET_FILES if name.lower() in f.lower()]
    if not near:
        import difflib

        near = difflib.get_close_matches(name, DATASET_FILES, n=5, cutoff=0.5) or difflib.get_close_matches(
            name.lower(), {k[1].lower(): f for f, k in keys.items()}, n=5, cutoff=0.5)
        near = [f for f in DATASET_FILES if f in near or keys[f][1].lower() in near]
    hint = f"; did you mean {', '.join(near)}?" if near else f"; the names are {', '.join(DATASET_FILES)}"
    raise DatasetNotFound(f"unknown dataset {name!r}{hint}")


def dataset(rel: str) -> Path:
    """Path of a dataset file (e.g. ``"se-sync/MIT.g2o"``); raises ``DatasetNotFound`` with the places tried."""
    p = locate(rel)
    if p is None:
        tried = ", ".join(str(c) for c in _candidates())
        raise DatasetNotFound(f"dataset {rel} not found (tried {tried}); set LAGO_CVX_DATASETS or run "
                              f"`lago-cvx datasets fetch {rel}`")
    return p


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def verify(files=None) -> list[tuple[str, Path | None, str]]:
    """Check the dataset files found against ``MANIFEST``: ``[(file, path or None, status)]`` with status
    ``"ok"``, ``"missing"`` or ``"mismatch"`` (the bytes differ from the public source's)."""
    out = []
    for f in (DATASET_FILES if files is None else files):
        src = _source(f)
        p = locate(f)
        if p is None:
            out.append((f, None, "missing"))
        else:
            out.append((f, p, "ok" if _sha256(p) == src.sha256 else "mismatch"))
    return out


def fetch(files=None, *, progress: bool = False) -> list[Path]:
    """Download the dataset files that are not found anywhere into ``cache_dir()`` (with ``pooch``, which
    checks each download's SHA-256), and return their paths. Files already present are not downloaded.
    Needs network access and ``pip install "lago-cvx[datasets]"``."""
    try:
        import pooch
    except ImportError:
        from .errors import MissingSolverError

        raise MissingSolverError('fetching datasets needs pooch: pip install "lago-cvx[datasets]"') from None
    paths = []
    for f in (DATASET_FILES if files is None else files):
        src = _source(f)
        have = locate(f)
        if have is not None:
            paths.append(have)
            continue
        target = cache_dir() / f
        try:
            got = pooch.retrieve(source_url(f), known_hash=f"sha256:{src.sha256}", fname=target.name,
                                 path=target.parent, progressbar=progress)
        except Exception as exc:  # network errors, hash mismatch: one clear line
            raise DatasetNotFound(f"cannot fetch {f} from {source_url(f)}: {exc}") from None
        paths.append(Path(got))
    return paths
