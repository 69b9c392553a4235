"""Section ``costs`` of ``python benchmarks/run.py``: the cost a file means, checked against its owners' code.

For every file: ``lago-cvx solve F --json -o est.g2o`` and ``lago-cvx solve F --refine --json -o est.g2o`` as
whole processes; g2o's own χ² of ``est.g2o`` (g2opy: the file loaded, the first vertex fixed) and the χ² its
Levenberg–Marquardt reaches from our refined estimate (100 iterations); then the same with ``--cost gtsam``
against GTSAM's 2·error() (``gtsam.readG2o``) and GTSAM's Levenberg–Marquardt (``lago_cvx.peers``). The relative
differences are |ours − theirs| / ours; "LM gain" is (ours − LM's) / ours, ≤ 1e-6 when our refinement reached
their minimum. Needs the ``peers`` extra (``pip install "lago-cvx[peers]"``).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import _bench
from lago_cvx import peers

PLANAR = ["se-sync/MIT.g2o", "se-sync/CSAIL.g2o", "carlone/input_INTEL_g2o.g2o", "se-sync/manhattan.g2o",
          "se-sync/intel.g2o", "se-sync/city10000.g2o", "carlone/input_M3500_g2o.g2o",
          "carlone/CSAIL_P_toro.graph", "carlone/M3500_P_toro.graph", "carlone/INTEL_P_toro.graph",
          "carlone/FR079_P_toro.graph"]
SPACE = ["se-sync-3d/sphere2500.g2o", "se-sync-3d/smallGrid3D.g2o", "se-sync-3d/parking-garage.g2o",
         "se-sync-3d/torus3D.g2o"]
HEAD = ["file", "cost", "χ² LAGO (ours)", "peer's χ² at it", "rel. diff", "χ² refined (ours)", "peer's χ² at it",
        "rel. diff", "peer's LM from it", "LM gain"]


def _solve(path: Path, out: Path, *extra) -> dict:
    argv = [sys.executable, "-m", "lago_cvx", "solve", str(path), "--json", "-o", str(out), *extra]
    done = subprocess.run(argv, capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def _rel(a: float, b: float) -> float:
    return abs(a - b) / abs(a)


def _rows(rel: str, path: Path, work: Path) -> list[list]:
    rows = []
    costs = [("g2o" if not rel.endswith(".graph") else "paper", peers.g2o_chi2)]
    if not rel.endswith(".graph"):
        costs.append(("gtsam", peers.gtsam_chi2))
    for cost, peer in costs:
        extra = ["--cost", cost]
        est = work / "est.g2o"
        lago = _solve(path, est, *extra)
        at = peer(est)["chi2_at"]
        refined = _solve(path, est, *extra, "--refine")
        theirs = peer(est, iterations=100)
        mine = refined["chi2_refined"]
        rows.append([rel, cost, _bench.fmt(lago["chi2"], ".10g"), _bench.fmt(at, ".10g"),
                     f"{_rel(lago['chi2'], at):.1e}", _bench.fmt(mine, ".10g"), _bench.fmt(theirs["chi2_at"], ".10g"),
                     f"{_rel(mine, theirs['chi2_at']):.1e}", _bench.fmt(theirs["chi2_lm"], ".10g"),
                     f"{(mine - theirs['chi2_lm']) / mine:.1e}"])
    return rows


def run(args) -> str:
    skipped = _bench.datasets_skipped()
    if skipped:
        return f"# The cost a file means\n\n{skipped}"
    if not (peers.have_g2o() and peers.have_gtsam()):
        return "# The cost a file means\n\nskipped: needs g2opy and gtsam (pip install \"lago-cvx[peers]\")."
    from importlib.metadata import version

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for rel in PLANAR + SPACE:
            path = _bench.find(rel)
            if path is None:
                continue
            print(f"  {rel}", flush=True)
            rows += _rows(rel, path, Path(tmp))
    versions = f"g2o's own bindings (PyPI `g2opy`) {version('g2opy')}, GTSAM {version('gtsam')} (PyPI `gtsam`)"
    return "\n".join([
        "# The cost a file means, against g2o's and GTSAM's own code",
        "",
        f"Peers: {versions}. Costs (`lago_cvx.conventions`): `g2o` — g2o's χ² (EDGE_SE2: t2v(Z⁻¹X_i⁻¹X_j); "
        "EDGE_SE3:QUAT: translation and quaternion vector of Z⁻¹X_i⁻¹X_j), the default for g2o files; `gtsam` — "
        "GTSAM's 2·error() (Logmap(Z⁻¹X_i⁻¹X_j), information as `readG2o` reads it); `paper` — the LAGO paper's "
        "eq. (3), the default for TORO files (its χ² is g2o's of the g2o file we write, whose information is "
        "rotated into g2o's frame). Peer for `g2o` and `paper`: g2o; for `gtsam`: GTSAM.",
        "",
        _bench.table(HEAD, rows),
    ])
